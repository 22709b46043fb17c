//! The `renderer serve` binary as a separate process: it announces its address, serves a batch,
//! and shuts down cleanly on Ctrl-C (SIGINT).

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{connect_as_sma, identity, recv};
use protocol::Side;
use protocol::renderer_link::{
    FromRenderer, Quality, SampleKey, ShadeBatch, ShadePoint, ToRenderer,
};

#[tokio::test]
async fn serve_answers_and_stops_on_ctrl_c() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_renderer"))
        .args([
            "serve",
            "--scene",
            "cornell",
            "--listen",
            "127.0.0.1:0",
            "--threads",
            "2",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start renderer");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = conventions::listening::parse(&line)
        .expect("address line")
        .to_string();

    let cornell = identity(&scene::load("cornell").unwrap());
    let (mut r, mut w) = connect_as_sma(&addr, cornell).await.unwrap();
    let point = ShadePoint {
        key: SampleKey {
            vertex: 0,
            side: Side::Front,
        },
        base_triangle: 0,
        bary: [0.3, 0.3],
        side: Side::Front,
        eye: None,
    };
    let batch = ShadeBatch {
        batch_id: 9,
        quality: Quality::DIRECT,
        seed: 1,
        points: vec![point; 4],
    };
    w.send(&ToRenderer::ShadeBatch(batch)).await.unwrap();
    let reply = recv(&mut r).await.unwrap();
    assert!(
        matches!(reply, FromRenderer::Radiance(ref rad) if rad.batch_id == 9 && rad.parts.len() == 4)
    );

    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let start = Instant::now();
    let exit = loop {
        if let Some(exit) = child.try_wait().unwrap() {
            break exit;
        }
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "renderer did not stop on SIGINT"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(exit.success(), "clean exit, got {exit:?}");
}
