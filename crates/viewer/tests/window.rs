//! The real window under Xvfb: it opens, shows the SMA's triangles (a screenshot of the X screen
//! compared with the headless drawing of the same view), and a synthesized key press walks the
//! camera, which reaches the SMA stand-in as a new `Camera`.

mod common;

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{Seen, StandIn, front_camera, known_triangles, scene};
use protocol::viewer_link::{Epoch, SmaToViewer, ViewerToSma};
use viewer::gpu::{REQUIRE_GPU_VAR, gpu_required, headless_or_skip};
use viewer::{DrawSettings, ToneMap, render_offscreen_with};

const W: u32 = 320;
const H: u32 = 240;

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
    let deadline = Instant::now() + Duration::from_secs(30);
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

/// Mean absolute difference per channel, 0..255.
fn mean_difference(a: &image::RgbImage, b: &image::RgbaImage) -> f64 {
    let total: u64 = a
        .pixels()
        .zip(b.pixels())
        .flat_map(|(p, q)| (0..3).map(move |c| p.0[c].abs_diff(q.0[c]) as u64))
        .sum();
    total as f64 / (3 * W * H) as f64
}

#[test]
fn the_window_shows_the_triangles_and_walks_on_a_key_press() {
    const TEST: &str = "the_window_shows_the_triangles_and_walks_on_a_key_press";
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
    let viewer = Command::new(env!("CARGO_BIN_EXE_viewer"))
        .env("DISPLAY", &display)
        .env_remove("WAYLAND_DISPLAY")
        .args(["--connect", &sma.addr, "--view", "front"])
        .args(["--width", &W.to_string(), "--height", &H.to_string()])
        .spawn()
        .expect("starting the viewer");
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
    };
    let want = render_offscreen_with(&gpu, &triangles, &camera, &settings).unwrap();
    let mut last = f64::NAN;
    wait_for("the triangles on screen", || {
        let shot = screenshot(&display)?;
        last = mean_difference(&shot, &want.display);
        (last < 1.0).then_some(())
    });
    eprintln!("{TEST}: screen vs headless, mean difference {last:.3} levels");

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

    x_command(&display, "xdotool", &["key", "Escape"]);
    sma.expect("goodbye", |s| {
        matches!(s, Seen::Message(ViewerToSma::Bye)).then_some(())
    });
    let status = reaper.0[1].wait().unwrap();
    assert!(status.success(), "the viewer exited with {status}");
}
