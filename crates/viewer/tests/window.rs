//! The real window under Xvfb: it opens, shows the SMA's triangles under the scene's sky beside
//! its panel (a screenshot of the X screen compared with the headless drawing of the same view),
//! `H` hides the panel (the whole screen is then the headless drawing), a synthesized key press
//! walks the camera, and a click on a viewpoint button of the panel jumps there; both reach the
//! SMA stand-in as a new `Camera`.

mod common;

use std::io::BufRead;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::{Seen, StandIn, front_camera, known_triangles, scene};
use protocol::viewer_link::{Epoch, SmaToViewer, ViewerToSma};
use viewer::gpu::{REQUIRE_GPU_VAR, gpu_required, headless_or_skip};
use viewer::{DrawSettings, ToneMap, render_offscreen_with};

const W: u32 = 640;
const H: u32 = 480;
/// Screen columns left of this are the panel's (it is `viewer::panel::WIDTH` points wide, one
/// pixel per point under Xvfb), with a margin for its edge line.
const PANEL_PX: u32 = viewer::panel::WIDTH as u32 + 4;

/// Kills the processes it holds when the test ends, passed or not.
struct Reaper(Vec<Child>);

impl Drop for Reaper {
    fn drop(&mut self) {
        for child in &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

fn have(program: &str) -> bool {
    Command::new("which")
        .arg(program)
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Starts `Xvfb` on a display number nobody uses; returns the display name.
fn start_xvfb(reaper: &mut Reaper) -> String {
    let n = (90..190)
        .find(|n| {
            !Path::new(&format!("/tmp/.X11-unix/X{n}")).exists()
                && !Path::new(&format!("/tmp/.X{n}-lock")).exists()
        })
        .expect("a free X display number");
    let child = Command::new("Xvfb")
        .args([
            format!(":{n}"),
            "-screen".into(),
            "0".into(),
            format!("{W}x{H}x24"),
        ])
        .args(["-nolisten", "tcp"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting Xvfb");
    reaper.0.push(child);
    let socket = format!("/tmp/.X11-unix/X{n}");
    wait_for("Xvfb's socket", || {
        Path::new(&socket).exists().then_some(())
    });
    format!(":{n}")
}

fn wait_for<T>(what: &str, mut poll: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        if let Some(t) = poll() {
            return t;
        }
        assert!(Instant::now() < deadline, "gave up waiting for {what}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn x_command(display: &str, program: &str, args: &[&str]) -> std::process::Output {
    Command::new(program)
        .env("DISPLAY", display)
        .args(args)
        .output()
        .expect(program)
}

fn screenshot(display: &str) -> Option<image::RgbImage> {
    let out = x_command(display, "import", &["-window", "root", "png:-"]);
    image::load_from_memory(&out.stdout)
        .ok()
        .map(|i| i.into_rgb8())
}

/// Mean absolute difference per channel, 0..255, over the columns `columns`.
fn mean_difference(
    a: &image::RgbImage,
    b: &image::RgbaImage,
    columns: std::ops::Range<u32>,
) -> f64 {
    let width = columns.len() as u64;
    let total: u64 = (0..H)
        .flat_map(|y| columns.clone().map(move |x| (x, y)))
        .flat_map(|(x, y)| {
            let (p, q) = (a.get_pixel(x, y).0, b.get_pixel(x, y).0);
            (0..3).map(move |c| p[c].abs_diff(q[c]) as u64)
        })
        .sum();
    total as f64 / (3 * width * H as u64) as f64
}

/// The viewer's log lines so far, read from its stderr (and passed on to the test's).
#[derive(Clone, Default)]
struct Log(Arc<Mutex<Vec<String>>>);

impl Log {
    fn follow(child: &mut Child) -> Log {
        let log = Log::default();
        let lines = log.clone();
        let stderr = child.stderr.take().expect("the viewer's stderr is piped");
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                eprintln!("{line}");
                lines.0.lock().unwrap().push(line);
            }
        });
        log
    }

    fn len(&self) -> usize {
        self.0.lock().unwrap().len()
    }

    /// The panel's state in the first line at `from` or later where the window settled, if one
    /// comes within `within`.
    fn next_settled(&self, from: usize, within: Duration) -> Option<bool> {
        let deadline = Instant::now() + within;
        loop {
            let found = self.0.lock().unwrap().iter().skip(from).find_map(|line| {
                line.contains(viewer::window::SETTLED)
                    .then(|| line.contains("panel=true"))
            });
            if found.is_some() || Instant::now() >= deadline {
                return found;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Waits until the window has settled with its panel shown ([`viewer::window::SETTLED`]) in
    /// a line at `from` or later, and after every line where it settled with the panel hidden.
    fn wait_settled_with_panel(&self, what: &str, from: usize) {
        let settled = |line: &String, panel: bool| {
            line.contains(viewer::window::SETTLED) && line.contains(&format!("panel={panel}"))
        };
        wait_for(what, || {
            let lines = self.0.lock().unwrap();
            let hidden = lines.iter().rposition(|l| settled(l, false));
            let from = hidden.map_or(from, |h| from.max(h + 1));
            lines
                .iter()
                .skip(from)
                .any(|l| settled(l, true))
                .then_some(())
        })
    }
}

/// Presses H until the window settles with its panel shown or hidden as `panel` says. Without a
/// window manager, a key pressed just after the focus moved has been seen lost under load: the
/// window settled again with its panel unchanged, or not at all. A key that arrived makes the
/// window draw and settle with the panel toggled, so another press is sent only when the window
/// settled without it or stayed quiet.
fn press_until_panel(display: &str, log: &Log, panel: bool) {
    for _ in 0..3 {
        let from = log.len();
        x_command(display, "xdotool", &["key", "h"]);
        if log.next_settled(from, Duration::from_secs(10)) == Some(panel) {
            return;
        }
    }
    panic!("H did not make the window settle with panel={panel} in three presses");
}

/// Waits until the screen shows `want` over `columns`; returns the last difference.
fn wait_for_screen(
    what: &str,
    display: &str,
    want: &image::RgbaImage,
    columns: std::ops::Range<u32>,
) -> f64 {
    let mut last = f64::NAN;
    wait_for(what, || {
        let shot = screenshot(display)?;
        last = mean_difference(&shot, want, columns.clone());
        (last < 1.0).then_some(())
    });
    last
}

#[test]
fn the_window_shows_the_triangles_and_its_panel_hides_it_on_h_walks_and_jumps_on_a_click() {
    const TEST: &str =
        "the_window_shows_the_triangles_and_its_panel_hides_it_on_h_walks_and_jumps_on_a_click";
    if !["Xvfb", "xdotool", "import"].iter().all(|p| have(p)) {
        assert!(
            !gpu_required(),
            "{REQUIRE_GPU_VAR} is set but Xvfb, xdotool or import is missing"
        );
        eprintln!("{TEST}: skipped, Xvfb/xdotool/imagemagick not installed");
        return;
    }
    let Some(gpu) = headless_or_skip(TEST).expect("a graphics adapter is required") else {
        return;
    };
    let mut reaper = Reaper(Vec::new());
    let display = start_xvfb(&mut reaper);
    let sma = StandIn::start(scene());
    let mut viewer = Command::new(env!("CARGO_BIN_EXE_viewer"))
        .env("DISPLAY", &display)
        .env_remove("WAYLAND_DISPLAY")
        // The window says at `debug` when it has settled; the rest as by default.
        .env(
            "RUST_LOG",
            "warn,viewer=info,viewer::window=debug,egui_wgpu=error",
        )
        .args(["--connect", &sma.addr, "--view", "front"])
        .args(["--width", &W.to_string(), "--height", &H.to_string()])
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting the viewer");
    let log = Log::follow(&mut viewer);
    reaper.0.push(viewer);

    let camera = sma.expect_camera();
    assert_eq!(
        camera,
        front_camera(camera.seq, W, H),
        "the window sends its view's camera"
    );
    let triangles = known_triangles();
    sma.send(SmaToViewer::Insert {
        triangles: triangles.clone(),
    });
    sma.send(SmaToViewer::ToneMap { l_white: 4.0 });
    sma.send(SmaToViewer::Epoch(Epoch {
        camera_seq: camera.seq,
        ..Epoch::default()
    }));

    let settings = DrawSettings {
        tone_map: ToneMap::Drago,
        l_white: 4.0,
        wireframe: false,
        sky: common::SKY,
    };
    let want = render_offscreen_with(&gpu, &triangles, &camera, &settings).unwrap();
    let beside = wait_for_screen(
        "the triangles beside the panel",
        &display,
        &want.display,
        PANEL_PX..W,
    );
    let shot = screenshot(&display).expect("a screenshot");
    let panel = mean_difference(&shot, &want.display, 0..PANEL_PX);
    eprintln!(
        "{TEST}: screen vs headless, mean difference {beside:.3} levels beside the panel, \
         {panel:.1} over it"
    );
    assert!(
        panel > 10.0,
        "no panel over the left of the window ({panel:.1} levels)"
    );

    // No window manager runs to hand out the keyboard focus: give it to the window.
    let found = x_command(
        &display,
        "xdotool",
        &["search", "--name", viewer::window::TITLE],
    );
    let window = String::from_utf8_lossy(&found.stdout)
        .lines()
        .next()
        .map(str::to_string);
    let window = window.expect("the viewer's window on the X display");
    x_command(&display, "xdotool", &["windowfocus", "--sync", &window]);
    press_until_panel(&display, &log, false);
    let hidden = wait_for_screen("the panel hidden", &display, &want.display, 0..W);
    eprintln!("{TEST}: after H, whole screen vs headless {hidden:.3} levels");

    x_command(&display, "xdotool", &["keydown", "w"]);
    std::thread::sleep(Duration::from_millis(300));
    x_command(&display, "xdotool", &["keyup", "w"]);
    let walked = sma.expect_camera();
    assert!(
        walked.seq > camera.seq,
        "a new camera has a new sequence number"
    );
    assert!(
        walked.eye[2] < camera.eye[2] - 1e-3,
        "W walks towards the scene: {:?}",
        walked.eye
    );
    assert_eq!(
        walked.orientation, camera.orientation,
        "walking does not turn"
    );

    // The panel back, a click on the second viewpoint's button: the camera jumps there. The
    // click comes once the panel is on the screen and the window has settled, the pointer over
    // the button, with nothing else to draw: the click alone must make the window draw the panel
    // again to see it. The window says when it has settled; the stand-in SMA sends nothing
    // that is drawn meanwhile, so the line after the pointer's move is that move's.
    let before_h = log.len();
    x_command(&display, "xdotool", &["key", "h"]);
    wait_for("the panel back", || {
        let shot = screenshot(&display)?;
        (mean_difference(&shot, &want.display, 0..PANEL_PX) > 10.0).then_some(())
    });
    log.wait_settled_with_panel("the window settled with its panel", before_h);
    let button = viewer::panel::viewpoint_button(1).center();
    let (x, y) = (button.x.round().to_string(), button.y.round().to_string());
    let before_move = log.len();
    x_command(&display, "xdotool", &["mousemove", &x, &y]);
    log.wait_settled_with_panel(
        "the window drawn for the pointer on the button (a hover is drawn) and settled",
        before_move,
    );
    x_command(&display, "xdotool", &["click", "1"]);
    let side = &scene().viewpoints[1];
    let jumped = wait_for("the camera at the clicked viewpoint", || {
        let c = sma.expect_camera();
        (c.eye == side.eye).then_some(c)
    });
    assert!(jumped.seq > walked.seq);

    x_command(&display, "xdotool", &["key", "Escape"]);
    sma.expect("goodbye", |s| {
        matches!(s, Seen::Message(ViewerToSma::Bye)).then_some(())
    });
    let status = reaper.0[1].wait().unwrap();
    assert!(status.success(), "the viewer exited with {status}");
}
