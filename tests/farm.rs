//! A renderer farm that survives (DESIGN.md §2, §8), with real processes over loopback: renderers
//! stopped with SIGSTOP (a hung host: its sockets open, nothing answered) before they are sent
//! batches and while they hold some, the only renderer stopped, a renderer joining a running SMA,
//! a viewer that stops reading, frames stalled halfway, and a renderer offered more batches than
//! it holds. Nothing here asserts a time: waits are generous guards, and the detection delay is
//! printed, not judged. Needs a wgpu adapter for the SMA's visibility (Mesa without a GPU):
//! without one each test says so and returns, unless `WALKTHROUGH_REQUIRE_GPU` is set.

use std::path::Path;
use std::time::{Duration, Instant};

use protocol::connection::{TcpReader, TcpWriter, connect_handshake};
use protocol::frame::DEFAULT_MAX_FRAME;
use protocol::handshake::HelloReply;
use protocol::renderer_link::{
    FromRenderer, Quality, SampleKey, ShadeBatch, ShadePoint, ToRenderer,
};
use protocol::viewer_link::{Camera, SmaToViewer, ViewerToSma};
use protocol::{Hello, Role, SceneIdentity, Side, split_tcp};
use protocol::{MessageReader, WireMessage};
use sma::visibility::Gpu;
use testkit::child::{Process, Server, start_renderer_with, start_sma, strings};
use testkit::gpu::gpu_or_skip;
use testkit::liar::hello_frame;
use testkit::probe::Probe;
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;
use tokio::net::tcp::OwnedWriteHalf;

const SCENE: &str = "bracara";
const W: u32 = 256;
const H: u32 = 192;
const WAIT: Duration = Duration::from_secs(150);
/// Liveness flags for the SMA: a stopped renderer is lost after a second of silence.
const FAST_LIVENESS: [&str; 4] = ["--heartbeat-ms", "200", "--silence-ms", "1000"];

fn exe() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_walkthrough"))
}

fn have_gpu() -> bool {
    gpu_or_skip(Gpu::new()).is_some()
}

/// A renderer on one thread with more `flags`, its log in `dir`.
fn renderer(dir: &Path, name: &str, flags: &[&str]) -> Server {
    let log = dir.join(format!("{name}.log"));
    start_renderer_with(exe(), SCENE, Some(1), &strings(flags), Some(&log))
        .unwrap_or_else(|e| panic!("{name}: {e:#}"))
}

/// An SMA on `renderers` with fast liveness and more `flags`, its log in `dir`.
fn sma(dir: &Path, renderers: &[&Server], flags: &[&str]) -> Server {
    let addrs: Vec<_> = renderers.iter().map(|r| r.addr).collect();
    let mut all = strings(&FAST_LIVENESS);
    all.extend(strings(&["--stats-secs", "0.3"]));
    all.extend(strings(flags));
    start_sma(exe(), SCENE, &addrs, &all, Some(&dir.join("sma.log")))
        .unwrap_or_else(|e| panic!("sma: {e:#}"))
}

fn workdir() -> tempfile::TempDir {
    tempfile::tempdir().expect("a temporary folder")
}

/// Lines of `process`'s log holding every one of `parts`.
fn count_lines(process: &Process, parts: &[&str]) -> usize {
    let text = process.log_text();
    text.lines()
        .filter(|l| parts.iter().all(|p| l.contains(p)))
        .count()
}

/// Waits until `process`'s log has at least `n` lines holding `parts`; returns how long it took.
fn wait_for_lines(process: &Process, parts: &[&str], n: usize) -> Duration {
    let start = Instant::now();
    while count_lines(process, parts) < n {
        assert!(
            start.elapsed() < WAIT,
            "{}",
            process.failure(&format!("logged no {n} lines with {parts:?}"))
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    start.elapsed()
}

/// The first epoch answering `camera` with nothing outstanding; every visible leaf is shown then.
async fn completes(probe: &mut Probe, camera: &Camera) {
    let done = probe.complete(camera.seq, WAIT).await.unwrap();
    assert_eq!(
        done.shown, done.visible_leaves,
        "complete yet not all shown: {done:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn renderers_stopped_before_and_while_holding_batches_do_not_stall_the_view() {
    if !have_gpu() {
        return;
    }
    let dir = workdir();
    let a = renderer(dir.path(), "a", &[]);
    let b = renderer(dir.path(), "b", &[]);
    let s = sma(
        dir.path(),
        &[&a, &b],
        &["--no-refine", "--batch-points", "8"],
    );
    let (a_name, b_name) = (a.addr.to_string(), b.addr.to_string());
    wait_for_lines(&s.process, &["renderer connected", &a_name], 1);
    wait_for_lines(&s.process, &["renderer connected", &b_name], 1);

    // Stopped before it is sent any batch.
    a.process.pause();
    let mut probe = Probe::connect(&s.addr.to_string()).await.unwrap();
    let first = probe.view("VT", W, H).await.unwrap();
    completes(&mut probe, &first).await;
    let detected = wait_for_lines(&s.process, &["renderer lost", &a_name], 1);
    eprintln!("renderer a lost, {detected:?} after the view completed");

    // Back again: it is connected anew.
    a.process.resume();
    wait_for_lines(&s.process, &["renderer connected", &a_name], 2);

    // The other one stopped while it holds batches: a's work completes the view.
    let second = probe.view("VR", W, H).await.unwrap();
    probe
        .until(WAIT, |e| e.camera_seq == second.seq && e.samples > 0)
        .await
        .unwrap();
    b.process.pause();
    let paused_at = Instant::now();
    completes(&mut probe, &second).await;
    let lost = wait_for_lines(&s.process, &["renderer lost", &b_name], 1);
    eprintln!(
        "renderer b stopped holding batches: view completed and b reported lost {:?} after the stop",
        paused_at.elapsed().max(lost)
    );
    let log = s.process.log_text();
    let held = log
        .lines()
        .find(|l| l.contains("renderer lost") && l.contains(&b_name))
        .unwrap_or_default()
        .to_string();
    eprintln!("{held}");
    b.process.resume();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_only_renderer_stopped_is_reported_and_its_work_resumes_after_sigcont() {
    if !have_gpu() {
        return;
    }
    let dir = workdir();
    let r = renderer(dir.path(), "only", &[]);
    let s = sma(dir.path(), &[&r], &["--no-refine", "--batch-points", "8"]);
    let mut probe = Probe::connect(&s.addr.to_string()).await.unwrap();
    let camera = probe.view("VT", W, H).await.unwrap();
    probe
        .until(WAIT, |e| e.camera_seq == camera.seq && e.samples > 0)
        .await
        .unwrap();
    r.process.pause();
    let paused_at = Instant::now();
    probe.until_stats(WAIT, |s| s.renderers == 0).await.unwrap();
    eprintln!(
        "stats said no renderer {:?} after the stop",
        paused_at.elapsed()
    );
    wait_for_lines(&s.process, &["no renderer is answering"], 1);
    let stalled = *probe.epochs.last().expect("epochs came");
    r.process.resume();
    completes(&mut probe, &camera).await;
    wait_for_lines(&s.process, &["a renderer answers again"], 1);
    let done = *probe.epochs.last().unwrap();
    assert!(done.samples > stalled.samples, "{stalled:?} then {done:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_third_renderer_joining_a_running_sma_gets_batches() {
    if !have_gpu() {
        return;
    }
    let dir = workdir();
    let a = renderer(dir.path(), "a", &[]);
    let b = renderer(dir.path(), "b", &[]);
    let s = sma(
        dir.path(),
        &[&a, &b],
        &[
            "--no-refine",
            "--batch-points",
            "8",
            "--renderer-listen",
            "127.0.0.1:0",
        ],
    );
    let port = s
        .process
        .announced("sma renderers", WAIT)
        .unwrap()
        .to_string();
    let mut probe = Probe::connect(&s.addr.to_string()).await.unwrap();
    let first = probe.view("VT", W, H).await.unwrap();
    completes(&mut probe, &first).await;

    let _c = renderer(dir.path(), "c", &["--join", &port]);
    wait_for_lines(&s.process, &["renderer joined"], 1);
    // Only the newcomer can answer now.
    a.process.pause();
    b.process.pause();
    let second = probe.view("MC", W, H).await.unwrap();
    completes(&mut probe, &second).await;
    a.process.resume();
    b.process.resume();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_viewer_that_stops_reading_is_cut_off_while_another_goes_on() {
    if !have_gpu() {
        return;
    }
    let dir = workdir();
    let r = renderer(dir.path(), "r", &[]);
    let s = sma(
        dir.path(),
        &[&r],
        &["--no-refine", "--viewer-silence-ms", "2000"],
    );
    let addr = s.addr.to_string();
    let before = s.process.resident_bytes();

    // A viewer that reads nothing past `SceneInfo`, with a small receive buffer, and keeps
    // asking for other views, each answered with a whole new table.
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    let stream = socket.connect(addr.parse().unwrap()).await.unwrap();
    let (mut reader, mut writer): (TcpReader<SmaToViewer>, TcpWriter<ViewerToSma>) =
        split_tcp(stream, DEFAULT_MAX_FRAME);
    connect_handshake(
        &mut reader,
        &mut writer,
        Hello::new(Role::Viewer, None),
        Role::Sma,
    )
    .await
    .unwrap();
    let scene = match reader.recv().await.unwrap() {
        SmaToViewer::SceneInfo(scene) => *scene,
        other => panic!("expected SceneInfo, got {other:?}"),
    };
    let stuck = tokio::spawn(async move {
        for seq in 1..=2000u64 {
            let vp = &scene.viewpoints[seq as usize % scene.viewpoints.len()];
            let camera = ViewerToSma::Camera(Camera::from_viewpoint(vp, seq, W, H));
            let sent = tokio::time::timeout(Duration::from_secs(1), writer.send(&camera));
            if !matches!(sent.await, Ok(Ok(()))) {
                break;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        reader
    });

    let mut probe = Probe::connect(&addr).await.unwrap();
    let first = probe.view("VT", W, H).await.unwrap();
    completes(&mut probe, &first).await;
    // What waits for it is coalesced, so it holds no more than its views' triangles; it is cut
    // off when it answers no heartbeat (the byte bound behind that is tested with the outbox).
    wait_for_lines(
        &s.process,
        &["disconnecting a viewer that answers no heartbeat"],
        1,
    );
    let after = s.process.resident_bytes();
    eprintln!("SMA resident memory before the stuck viewer {before:?}, after its cut {after:?}");
    // The other viewer goes on.
    let second = probe.view("VR", W, H).await.unwrap();
    completes(&mut probe, &second).await;
    drop(stuck.await.unwrap());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_frame_stalled_halfway_is_cut_off_by_the_sma_and_by_the_renderer() {
    if !have_gpu() {
        return;
    }
    let dir = workdir();
    let r = renderer(dir.path(), "r", &["--frame-timeout-ms", "500"]);
    let s = sma(
        dir.path(),
        &[&r],
        &["--no-refine", "--frame-timeout-ms", "500"],
    );

    // A viewer that stops halfway through a frame.
    let hello = Hello::new(Role::Viewer, None);
    let (mut reader, _writer) = stalled::<SmaToViewer>(&s.addr.to_string(), &hello).await;
    let told = tokio::time::timeout(WAIT, async {
        loop {
            match reader.recv().await {
                Ok(SmaToViewer::Error { message }) => return message,
                Ok(_) => continue,
                Err(e) => panic!("closed without an error reply: {e}"),
            }
        }
    })
    .await
    .expect("the SMA held a stalled frame open");
    assert!(told.contains("stalled"), "{told}");

    // An SMA that does the same to a renderer.
    let hello = Hello::new(Role::Sma, Some(identity()));
    let (mut reader, _writer) = stalled::<FromRenderer>(&r.addr.to_string(), &hello).await;
    let told = tokio::time::timeout(WAIT, reader.recv())
        .await
        .expect("the renderer held a stalled frame open");
    match told {
        Ok(FromRenderer::Error { message }) => assert!(message.contains("stalled"), "{message}"),
        other => panic!("expected an error reply, got {other:?}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_renderer_refuses_more_batches_than_it_holds() {
    let dir = workdir();
    let log = dir.path().join("r.log");
    let flags = strings(&["--max-batches", "2"]);
    let r = start_renderer_with(exe(), SCENE, Some(1), &flags, Some(&log)).unwrap();
    let (mut reader, mut writer) = renderer_link(&r.addr.to_string(), identity()).await;
    for batch_id in 1..=6 {
        let batch = heavy_batch(batch_id);
        writer.send(&ToRenderer::ShadeBatch(batch)).await.unwrap();
    }
    let (mut answered, mut refused) = (0, Vec::new());
    while answered + refused.len() < 6 {
        match tokio::time::timeout(WAIT, reader.recv())
            .await
            .unwrap()
            .unwrap()
        {
            FromRenderer::Radiance(_) => answered += 1,
            FromRenderer::Rejected { reason, .. } => refused.push(reason),
            other => panic!("unexpected {other:?}"),
        }
    }
    assert!(answered >= 2, "{answered} answered, refused {refused:?}");
    assert!(
        !refused.is_empty(),
        "six batches taken by a renderer holding two"
    );
    assert!(
        refused.iter().all(|r| r.contains("holds at most 2")),
        "{refused:?}"
    );
}

/// The scene as an SMA that loaded `SCENE` says it in the handshake.
fn identity() -> SceneIdentity {
    let scene = scene::load(SCENE).unwrap();
    SceneIdentity {
        fingerprint: scene.fingerprint,
        textures: scene.settings.textures.enabled,
    }
}

/// A link to a renderer as an SMA, after the handshake.
async fn renderer_link(
    addr: &str,
    ours: SceneIdentity,
) -> (TcpReader<FromRenderer>, TcpWriter<ToRenderer>) {
    let stream = TcpStream::connect(addr).await.unwrap();
    let (mut reader, mut writer) = split_tcp(stream, DEFAULT_MAX_FRAME);
    let hello = Hello::new(Role::Sma, Some(ours));
    connect_handshake(&mut reader, &mut writer, hello, Role::Renderer)
        .await
        .unwrap();
    (reader, writer)
}

/// Shakes hands at `addr` with `hello`, then sends a length announcing 100 bytes and only 10 of
/// them. The write half is kept open: closing it would end the frame rather than stall it.
async fn stalled<In: WireMessage>(
    addr: &str,
    hello: &Hello,
) -> (
    MessageReader<tokio::net::tcp::OwnedReadHalf, In>,
    OwnedWriteHalf,
) {
    let stream = TcpStream::connect(addr).await.unwrap();
    let (read, mut write) = stream.into_split();
    let mut said = hello_frame(hello);
    said.extend(100u32.to_be_bytes());
    said.extend([0u8; 10]);
    write.write_all(&said).await.unwrap();
    let mut reader = MessageReader::new(read, DEFAULT_MAX_FRAME);
    match reader.recv_as::<HelloReply>().await.unwrap() {
        HelloReply::Welcome { .. } => {}
        refused => panic!("{refused:?}"),
    }
    (reader, write)
}

/// A batch that keeps one thread busy for a while: many points, many paths.
fn heavy_batch(batch_id: u64) -> ShadeBatch {
    let points = (0..256)
        .map(|i| ShadePoint {
            key: SampleKey {
                vertex: i,
                side: Side::Front,
            },
            base_triangle: i,
            bary: [0.3, 0.3],
            side: Side::Front,
            eye: None,
        })
        .collect();
    ShadeBatch {
        batch_id,
        quality: Quality {
            paths: 256,
            bounces: Some(2),
        },
        seed: batch_id,
        points,
    }
}
