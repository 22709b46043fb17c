//! Peers that lie, against a real renderer and a real SMA over loopback (DESIGN.md §8): a valid
//! `Hello` of the wrong role, of another protocol version or of another scene, a 64 MiB frame
//! announced before the handshake, and a connection that never says a word are each refused with
//! their reason and closed, while a real viewer is served all along. Past the SMA's bound on
//! viewers, a viewer is refused cleanly, never left hanging. Needs a wgpu adapter for the SMA.

use std::path::Path;
use std::time::Duration;

use protocol::{Hello, PROTOCOL_VERSION, Role, SceneIdentity};
use sma::visibility::Gpu;
use testkit::child::{Process, start_server, start_sma, strings};
use testkit::gpu::gpu_or_skip;
use testkit::liar::{hello_frame, large_frame_announcement, refusal};
use testkit::probe::Probe;

const SCENE: &str = "cornell";
const WAIT: Duration = Duration::from_secs(120);

fn exe() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_walkthrough"))
}

/// A renderer that gives a handshake 300 ms, and an SMA on it with `sma_flags`.
fn system(sma_flags: &[&str]) -> (Process, String, Process, String) {
    let mut args = strings(&[
        "renderer",
        "serve",
        "--scene",
        SCENE,
        "--listen",
        "127.0.0.1:0",
    ]);
    args.extend(strings(&[
        "--threads",
        "1",
        "--handshake-deadline-ms",
        "300",
    ]));
    let renderer = start_server(exe(), "renderer", &args, None).unwrap();
    let mut flags = strings(&["--stats-secs", "60"]);
    flags.extend(strings(sma_flags));
    let sma = start_sma(exe(), SCENE, &[renderer.addr], &flags, None).unwrap();
    let (r, s) = (renderer.addr.to_string(), sma.addr.to_string());
    (renderer.process, r, sma.process, s)
}

/// What each lie says, and what its refusal must name. An honest peer says `says` of its scene;
/// `actual` is the scene the server has loaded.
fn lies(
    honest: Role,
    wrong: Role,
    says: Option<SceneIdentity>,
    actual: SceneIdentity,
) -> Vec<(Vec<u8>, &'static str)> {
    let other_version = Hello {
        version: PROTOCOL_VERSION + 1,
        ..Hello::new(honest, says)
    };
    let other_scene = SceneIdentity {
        fingerprint: [0x5a; 32],
        ..actual
    };
    let other_textures = SceneIdentity {
        textures: !actual.textures,
        ..actual
    };
    vec![
        (hello_frame(&Hello::new(wrong, says)), "unexpected role"),
        (hello_frame(&other_version), "version mismatch"),
        (
            hello_frame(&Hello::new(honest, Some(other_scene))),
            "fingerprint mismatch",
        ),
        (
            hello_frame(&Hello::new(honest, Some(other_textures))),
            "textures mismatch",
        ),
        (
            large_frame_announcement(),
            "exceeds the maximum of 4096 bytes",
        ),
        (Vec::new(), "no handshake within"),
    ]
}

/// Tells every lie to `addr`; each must be refused with its reason.
async fn refused_with_reasons(addr: &str, lies: Vec<(Vec<u8>, &'static str)>) {
    for (said, reason) in lies {
        // Without a handshake deadline the silent peer would be held open for good: the guard
        // turns that hang into a failure.
        let got = tokio::time::timeout(WAIT, refusal(addr, &said))
            .await
            .unwrap_or_else(|_| panic!("lie expecting {reason:?} held open"))
            .unwrap_or_else(|e| panic!("lie expecting {reason:?}: {e:#}"));
        assert!(got.contains(reason), "expected {reason:?} in {got:?}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn lying_peers_are_cut_off_with_a_reason_while_a_real_viewer_is_served() {
    if gpu_or_skip(Gpu::new()).is_none() {
        return;
    }
    let (_renderer, renderer_addr, _sma, sma_addr) = system(&["--handshake-deadline-ms", "300"]);
    let mut viewer = Probe::connect(&sma_addr).await.unwrap();
    let camera = viewer.view("main", 64, 64).await.unwrap();
    let ours = SceneIdentity {
        fingerprint: viewer.scene.fingerprint,
        textures: viewer.scene.textures,
    };
    tokio::join!(
        refused_with_reasons(&sma_addr, lies(Role::Viewer, Role::Renderer, None, ours)),
        refused_with_reasons(
            &renderer_addr,
            lies(Role::Sma, Role::Viewer, Some(ours), ours)
        ),
    );
    // The SMA's own link to the renderer and the viewer went on through all of it.
    viewer.complete(camera.seq, WAIT).await.unwrap();
    let again = viewer.view("main", 48, 48).await.unwrap();
    viewer.complete(again.seq, WAIT).await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn past_the_bound_a_viewer_is_refused_cleanly_and_served_once_a_place_frees() {
    if gpu_or_skip(Gpu::new()).is_none() {
        return;
    }
    let flags = ["--max-viewers", "2", "--handshake-deadline-ms", "60000"];
    let (_renderer, _, _sma, sma_addr) = system(&flags);
    let mut first = Probe::connect(&sma_addr).await.unwrap();
    let silent = tokio::net::TcpStream::connect(&sma_addr).await.unwrap();
    let refused = Probe::connect(&sma_addr)
        .await
        .err()
        .expect("a third viewer is refused");
    assert!(
        format!("{refused:#}").contains("at most 2 connections"),
        "{refused:#}"
    );
    drop(silent);
    // The silent peer's place frees once the SMA has seen it go: until then a viewer is refused
    // the same clean way, never left waiting.
    let mut second = loop {
        match Probe::connect(&sma_addr).await {
            Ok(probe) => break probe,
            Err(e) => assert!(format!("{e:#}").contains("at most 2"), "{e:#}"),
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    for probe in [&mut first, &mut second] {
        let camera = probe.view("main", 48, 48).await.unwrap();
        probe.complete(camera.seq, WAIT).await.unwrap();
    }
}
