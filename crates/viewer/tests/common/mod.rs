//! A scripted SMA stand-in over loopback: it accepts viewers, shakes hands as the SMA does, sends
//! `SceneInfo` first, then sends whatever the test queues and reports what the viewer sends.
#![allow(dead_code)] // each test binary uses its own part of this helper

use std::sync::mpsc;
use std::time::Duration;

use protocol::connection::{SceneCheck, accept_handshake};
use protocol::frame::DEFAULT_MAX_FRAME;
use protocol::types::{Bounds, Viewpoint};
use protocol::viewer_link::{SceneInfo, ShownTriangle, SmaToViewer, ViewerToSma};
use protocol::{Role, split_tcp};
use tokio::sync::mpsc as tokio_mpsc;

pub const WAIT: Duration = Duration::from_secs(30);

/// What the stand-in saw.
#[derive(Debug)]
pub enum Seen {
    /// A viewer connected (session number, from 1).
    Session(u32),
    Message(ViewerToSma),
    /// The viewer's session ended.
    Ended,
}

/// What the test tells the stand-in.
pub enum Command {
    Send(SmaToViewer),
    /// Close the current session (the viewer should reconnect).
    Drop,
}

pub struct StandIn {
    pub addr: String,
    pub seen: mpsc::Receiver<Seen>,
    commands: tokio_mpsc::UnboundedSender<Command>,
}

impl StandIn {
    pub fn start(scene: SceneInfo) -> StandIn {
        let (seen_tx, seen) = mpsc::channel();
        let (commands, commands_rx) = tokio_mpsc::unbounded_channel();
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let listener = runtime
            .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
            .expect("binding a loopback port");
        let addr = listener.local_addr().unwrap().to_string();
        std::thread::spawn(move || runtime.block_on(serve(listener, scene, seen_tx, commands_rx)));
        StandIn {
            addr,
            seen,
            commands,
        }
    }

    pub fn send(&self, msg: SmaToViewer) {
        self.commands
            .send(Command::Send(msg))
            .expect("stand-in gone");
    }

    pub fn drop_session(&self) {
        self.commands.send(Command::Drop).expect("stand-in gone");
    }

    /// The next thing seen that `pick` accepts, skipping others; panics after `WAIT`.
    pub fn expect<T>(&self, what: &str, mut pick: impl FnMut(Seen) -> Option<T>) -> T {
        let deadline = std::time::Instant::now() + WAIT;
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match self.seen.recv_timeout(left) {
                Ok(seen) => {
                    if let Some(t) = pick(seen) {
                        return t;
                    }
                }
                Err(_) => panic!("stand-in SMA: no {what} within {WAIT:?}"),
            }
        }
    }

    pub fn expect_camera(&self) -> protocol::viewer_link::Camera {
        self.expect("camera", |s| match s {
            Seen::Message(ViewerToSma::Camera(c)) => Some(c),
            _ => None,
        })
    }
}

async fn serve(
    listener: tokio::net::TcpListener,
    scene: SceneInfo,
    seen: mpsc::Sender<Seen>,
    mut commands: tokio_mpsc::UnboundedReceiver<Command>,
) {
    let mut session = 0;
    while let Ok((stream, _)) = listener.accept().await {
        session += 1;
        let (mut reader, mut writer) =
            split_tcp::<ViewerToSma, SmaToViewer>(stream, DEFAULT_MAX_FRAME);
        if accept_handshake(
            &mut reader,
            &mut writer,
            Role::Sma,
            Role::Viewer,
            SceneCheck::Tell(scene.fingerprint),
        )
        .await
        .is_err()
        {
            continue;
        }
        if writer
            .send(&SmaToViewer::SceneInfo(scene.clone()))
            .await
            .is_err()
        {
            continue;
        }
        let _ = seen.send(Seen::Session(session));
        loop {
            tokio::select! {
                msg = reader.recv() => match msg {
                    Ok(msg) => { let _ = seen.send(Seen::Message(msg)); }
                    Err(_) => break,
                },
                cmd = commands.recv() => match cmd {
                    Some(Command::Send(msg)) => {
                        if writer.send(&msg).await.is_err() { break; }
                    }
                    Some(Command::Drop) | None => break,
                },
            }
        }
        let _ = seen.send(Seen::Ended);
    }
}

/// A scene with two viewpoints looking at the origin from +Z.
pub fn scene() -> SceneInfo {
    let vp = |name: &str, eye: [f32; 3]| Viewpoint {
        name: name.into(),
        eye,
        target: [0.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 60.0,
    };
    SceneInfo {
        name: "stand-in".into(),
        fingerprint: [7; 32],
        bounds: Bounds {
            min: [-2.0, -2.0, -2.0],
            max: [2.0, 2.0, 2.0],
        },
        viewpoints: vec![vp("front", [0.0, 0.0, 3.0]), vp("side", [3.0, 0.0, 0.0])],
        criteria: vec!["nld_os".into(), "nld_is".into(), "rnd".into()],
    }
}

/// Known triangles for image checks, seen from the "front" viewpoint: a red-orange square on the
/// left (two triangles, one radiance), a square on the right whose radiance varies along x, and a
/// green triangle in front of part of the left square (it must hide it: depth test).
pub fn known_triangles() -> Vec<ShownTriangle> {
    let quad = |id: u64, x0: f32, x1: f32, z: f32, left: [f32; 3], right: [f32; 3]| {
        let (a, b, c, d) = ([x0, -0.6, z], [x1, -0.6, z], [x1, 0.6, z], [x0, 0.6, z]);
        vec![
            ShownTriangle {
                id,
                positions: [a, b, c],
                radiance: [left, right, right],
            },
            ShownTriangle {
                id: id + 1,
                positions: [a, c, d],
                radiance: [left, right, left],
            },
        ]
    };
    // The occluder comes first, so only the depth test can keep it in front.
    let mut t = vec![ShownTriangle {
        id: 30,
        positions: [[-1.3, 0.1, 0.5], [-0.9, 0.1, 0.5], [-1.1, 0.5, 0.5]],
        radiance: [[0.1, 0.9, 0.1]; 3],
    }];
    t.extend(quad(10, -1.4, -0.2, 0.0, [2.0, 0.8, 0.3], [2.0, 0.8, 0.3]));
    t.extend(quad(20, 0.2, 1.4, 0.0, [0.2, 0.2, 0.2], [4.0, 4.0, 4.0]));
    t
}

/// The camera of the "front" viewpoint at a given size.
pub fn front_camera(seq: u64, width: u32, height: u32) -> protocol::viewer_link::Camera {
    protocol::viewer_link::Camera::from_viewpoint(&scene().viewpoints[0], seq, width, height)
}
