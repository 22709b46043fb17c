//! Protocol throughput (DESIGN.md §8): encode + decode of triangle inserts on one core, and triangles
//! per second over loopback TCP between two processes (this one and a `loopback-sink` child).

use std::time::Instant;

use protocol::frame::{DEFAULT_MAX_FRAME, decode, encode};
use protocol::split_tcp;
use protocol::texture::Texcoords;
use protocol::viewer_link::{
    CornerShading, DirectShare, Epoch, ShownTriangle, SmaToViewer, ViewerToSma,
};

use testkit::child::{start_server, strings};

use super::stats::median;

const BATCH: usize = 10_000;

fn insert_batch(first_id: u64) -> SmaToViewer {
    let triangles = (0..BATCH as u64)
        .map(|i| {
            let f = (first_id + i) as f32;
            // A diffuse, textured triangle: no view-dependent part.
            ShownTriangle {
                id: first_id + i,
                positions: [[f, 0.5, -f], [f + 1.0, 2.0, 3.0], [0.25, f, 1.0]],
                material: (i % 40) as u16,
                texcoords: Texcoords::encode(
                    [[f * 1e-3, 0.5], [f * 1e-3 + 0.01, 0.5], [f * 1e-3, 0.51]],
                    false,
                ),
                shading: CornerShading {
                    illumination: [[0.1, 0.2, 0.3], [f * 1e-3, 0.5, 0.6], [0.7, 0.8, 0.9]],
                    direct_share: [DirectShare(100), DirectShare(255), DirectShare(0)],
                    view_dependent: None,
                },
            }
        })
        .collect();
    SmaToViewer::Insert { triangles }
}

/// Triangles per second through encode + decode on the calling thread.
fn codec_rate(batches: usize) -> anyhow::Result<f64> {
    let msgs: Vec<SmaToViewer> = (0..batches)
        .map(|b| insert_batch((b * BATCH) as u64))
        .collect();
    let t = Instant::now();
    let mut decoded = 0usize;
    for m in &msgs {
        let bytes = encode(m)?;
        if let SmaToViewer::Insert { triangles } = decode::<SmaToViewer>(&bytes)? {
            decoded += triangles.len();
        }
    }
    Ok(decoded as f64 / t.elapsed().as_secs_f64())
}

/// The child's side: decode every frame, count triangles, acknowledge at the closing `Epoch`.
pub fn loopback_sink(listen: &str) -> anyhow::Result<()> {
    tokio::runtime::Runtime::new()?.block_on(async {
        let listener = tokio::net::TcpListener::bind(listen).await?;
        conventions::listening::announce("loopback sink", listener.local_addr()?)?;
        let (stream, _) = listener.accept().await?;
        let (mut rx, mut tx) = split_tcp::<SmaToViewer, ViewerToSma>(stream, DEFAULT_MAX_FRAME);
        let mut count = 0u64;
        loop {
            match rx.recv().await? {
                SmaToViewer::Insert { triangles } => count += triangles.len() as u64,
                SmaToViewer::Epoch(e) if e.shown == count => {
                    tx.send(&ViewerToSma::Bye).await?;
                    return Ok(());
                }
                other => anyhow::bail!("unexpected {other:?} after {count} triangles"),
            }
        }
    })
}

/// Triangles per second from this process to a sink process over loopback.
fn loopback_rate(batches: usize) -> anyhow::Result<f64> {
    let exe = std::env::current_exe()?;
    let args = strings(&["loopback-sink", "--listen", "127.0.0.1:0"]);
    let sink = start_server(&exe, "loopback sink", &args, None)?;
    let msgs: Vec<SmaToViewer> = (0..batches)
        .map(|b| insert_batch((b * BATCH) as u64))
        .collect();
    let rate = tokio::runtime::Runtime::new()?.block_on(async {
        let stream = tokio::net::TcpStream::connect(sink.addr).await?;
        let (mut rx, mut tx) = split_tcp::<ViewerToSma, SmaToViewer>(stream, DEFAULT_MAX_FRAME);
        let t = Instant::now();
        for m in &msgs {
            tx.send(m).await?;
        }
        let shown = (batches * BATCH) as u64;
        tx.send(&SmaToViewer::Epoch(Epoch {
            shown,
            ..Epoch::default()
        }))
        .await?;
        rx.recv().await?;
        anyhow::Ok(shown as f64 / t.elapsed().as_secs_f64())
    });
    drop(sink);
    rate
}

pub fn section(quick: bool) -> anyhow::Result<String> {
    let (runs, batches) = if quick { (3, 5) } else { (7, 50) };
    let codec = median(
        (0..runs)
            .map(|_| codec_rate(batches))
            .collect::<anyhow::Result<Vec<_>>>()?,
    );
    let tcp = median(
        (0..runs)
            .map(|_| loopback_rate(batches))
            .collect::<anyhow::Result<Vec<_>>>()?,
    );
    let bytes = encode(&insert_batch(0))?.len() as f64 / BATCH as f64;
    Ok(format!(
        "## Protocol\n\n\
         Insert frames of {BATCH} triangles ({bytes:.1} bytes per triangle on the wire), {batches} frames per run, \
         median of {runs} runs.\n\n\
         | measure | triangles/s | target | met |\n|---|---:|---:|:-:|\n\
         | encode + decode, one core | {:.2} M | ≥ 5 M | {} |\n\
         | loopback TCP, two processes (encode, send, receive, decode) | {:.2} M | ≥ 2 M | {} |\n",
        codec / 1e6,
        if codec >= 5e6 { "yes" } else { "no" },
        tcp / 1e6,
        if tcp >= 2e6 { "yes" } else { "no" },
    ))
}
