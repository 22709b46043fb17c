//! A scripted SMA stand-in over loopback: it accepts viewers, shakes hands as the SMA does, sends
//! `SceneInfo` first, pings every half second as the SMA does, then sends whatever the test
//! queues and reports what the viewer sends.

use std::sync::mpsc;
use std::time::Duration;

use protocol::connection::{SceneCheck, accept_handshake};
use protocol::frame::DEFAULT_MAX_FRAME;
use protocol::viewer_link::{SceneInfo, SmaToViewer, ViewerToSma};
use protocol::{Role, SceneIdentity, split_tcp};
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
    /// Send nothing more in this session, pings included: an SMA that hangs.
    Mute,
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

    pub fn mute(&self) {
        self.commands.send(Command::Mute).expect("stand-in gone");
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
            SceneCheck::Tell(SceneIdentity {
                fingerprint: scene.fingerprint,
                textures: scene.textures,
            }),
        )
        .await
        .is_err()
        {
            continue;
        }
        if writer
            .send(&SmaToViewer::SceneInfo(Box::new(scene.clone())))
            .await
            .is_err()
        {
            continue;
        }
        let _ = seen.send(Seen::Session(session));
        let mut heartbeat = tokio::time::interval(Duration::from_millis(500));
        let mut muted = false;
        loop {
            tokio::select! {
                msg = reader.recv() => match msg {
                    Ok(msg) => { let _ = seen.send(Seen::Message(msg)); }
                    Err(_) => break,
                },
                _ = heartbeat.tick(), if !muted => {
                    if writer.send(&SmaToViewer::Ping { nonce: 1 }).await.is_err() { break; }
                }
                cmd = commands.recv() => match cmd {
                    Some(Command::Send(msg)) => {
                        if !muted && writer.send(&msg).await.is_err() { break; }
                    }
                    Some(Command::Mute) => muted = true,
                    Some(Command::Drop) | None => break,
                },
            }
        }
        let _ = seen.send(Seen::Ended);
    }
}
