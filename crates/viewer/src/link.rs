//! The connection to the SMA (DESIGN.md §2, §8): a task on its own thread and tokio runtime that
//! connects, shakes hands, receives `SceneInfo`, then stages incoming changes until their epoch
//! and forwards what the viewer may draw. When the link drops it reconnects with exponential
//! backoff; every new session starts from an empty table (the SMA forgets what a viewer held).
//!
//! The viewer's front end (window or headless) gets [`LinkEvent`]s through a callback, so a winit
//! event loop can be woken by its proxy and a headless loop by a channel.

use std::time::Duration;

use protocol::connection::{TcpReader, TcpWriter, connect_handshake};
use protocol::frame::DEFAULT_MAX_FRAME;
use protocol::liveness::Liveness;
use protocol::viewer_link::{SceneInfo, SmaToViewer, Stats, ViewerToSma};
use protocol::{Hello, ProtocolError, Role, split_tcp};
use tokio::sync::mpsc;

use crate::update::{EpochUpdate, Staged, Staging};

/// What the link tells the front end.
#[derive(Debug)]
pub enum LinkEvent {
    /// A new session: the table must be emptied, and the front end must send its camera again.
    Connected(SceneInfo),
    /// A later `SceneInfo` within the same session.
    Scene(SceneInfo),
    /// Changes closed by an epoch: apply them all before the next frame.
    Update(EpochUpdate),
    Refinement {
        criterion: String,
        paused: bool,
    },
    Stats(Stats),
    /// The SMA reported an error; the session goes on.
    RemoteError(String),
    /// The session ended; reconnecting.
    Disconnected(String),
}

pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);
/// An SMA pings its viewers every heartbeat (half a second by default); one that has sent
/// nothing at all for this long is lost, and the link reconnects (DESIGN.md §8). The SMA's own
/// limit for a viewer is the same by default.
pub const SMA_SILENCE: Duration = Duration::from_secs(10);
const FIRST_RETRY: Duration = Duration::from_millis(100);
const MAX_RETRY: Duration = Duration::from_secs(5);

/// The front end's handle: messages to the SMA, and the thread to join at the end.
pub struct Link {
    outbox: mpsc::UnboundedSender<ViewerToSma>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Link {
    /// Starts the link task. `notify` runs on the link's thread for every event.
    pub fn spawn(
        addr: String,
        notify: impl Fn(LinkEvent) + Send + 'static,
    ) -> anyhow::Result<Link> {
        let (outbox, inbox) = mpsc::unbounded_channel();
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        let thread = std::thread::Builder::new()
            .name("sma-link".into())
            .spawn(move || runtime.block_on(run(addr, notify, inbox)))?;
        Ok(Link {
            outbox,
            thread: Some(thread),
        })
    }

    /// Queues a message; dropped while disconnected (the front end resends its state on
    /// `Connected`, so nothing stale reaches a new session).
    pub fn send(&self, msg: ViewerToSma) {
        let _ = self.outbox.send(msg);
    }

    /// Says goodbye to the SMA and waits for the link to end.
    pub fn close(mut self) {
        self.shut_down();
    }

    fn shut_down(&mut self) {
        let _ = self.outbox.send(ViewerToSma::Bye);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        self.shut_down();
    }
}

/// Why a session ended.
enum SessionEnd {
    /// The front end is done (Bye sent, or the handle dropped).
    Finished,
    Lost(String),
}

async fn run(
    addr: String,
    notify: impl Fn(LinkEvent),
    mut inbox: mpsc::UnboundedReceiver<ViewerToSma>,
) {
    let mut retry = FIRST_RETRY;
    loop {
        let attempt = tokio::time::timeout(CONNECT_TIMEOUT, connect(&addr));
        let Some(attempt) = unless_finished(attempt, &mut inbox).await else {
            return;
        };
        match attempt {
            Ok(Ok((reader, writer, info))) => {
                retry = FIRST_RETRY;
                tracing::info!(%addr, scene = %info.name, "connected to the SMA");
                notify(LinkEvent::Connected(info));
                match session(reader, writer, &notify, &mut inbox).await {
                    SessionEnd::Finished => return,
                    SessionEnd::Lost(why) => {
                        tracing::warn!(%why, "lost the SMA; reconnecting");
                        notify(LinkEvent::Disconnected(why));
                    }
                }
            }
            Ok(Err(e)) => tracing::debug!(%addr, "connecting to the SMA: {e}"),
            Err(_) => tracing::debug!(%addr, "connecting to the SMA timed out"),
        }
        if unless_finished(tokio::time::sleep(retry), &mut inbox)
            .await
            .is_none()
        {
            return;
        }
        retry = (retry * 2).min(MAX_RETRY);
    }
}

type Connected = (TcpReader<SmaToViewer>, TcpWriter<ViewerToSma>, SceneInfo);

/// `work`'s outcome, or `None` when the front end finished first (its `Bye`, or its handle
/// dropped). Between sessions nothing waits on an SMA once the front end quits: an SMA that is
/// shutting down may take the TCP connection and never answer. Other messages queued meanwhile
/// were meant for no session: the front end restates its state on `Connected`.
async fn unless_finished<T>(
    work: impl Future<Output = T>,
    inbox: &mut mpsc::UnboundedReceiver<ViewerToSma>,
) -> Option<T> {
    tokio::pin!(work);
    loop {
        tokio::select! {
            outcome = &mut work => return Some(outcome),
            msg = inbox.recv() => match msg {
                None | Some(ViewerToSma::Bye) => return None,
                Some(_) => {}
            },
        }
    }
}

async fn connect(addr: &str) -> Result<Connected, ProtocolError> {
    let stream = tokio::net::TcpStream::connect(addr).await?;
    let (mut reader, mut writer) = split_tcp(stream, DEFAULT_MAX_FRAME);
    connect_handshake(
        &mut reader,
        &mut writer,
        Hello::new(Role::Viewer, None),
        Role::Sma,
    )
    .await?;
    // An SMA stalled halfway through a frame is lost like one gone (DESIGN.md §8).
    reader.set_frame_timeout(Liveness::default().frame_timeout);
    match reader.recv().await? {
        SmaToViewer::SceneInfo(info) => Ok((reader, writer, info)),
        SmaToViewer::Error { message } => Err(ProtocolError::Remote(message)),
        other => Err(ProtocolError::Malformed(format!(
            "expected SceneInfo first, got {}",
            kind(&other)
        ))),
    }
}

async fn session(
    mut reader: TcpReader<SmaToViewer>,
    mut writer: TcpWriter<ViewerToSma>,
    notify: &impl Fn(LinkEvent),
    inbox: &mut mpsc::UnboundedReceiver<ViewerToSma>,
) -> SessionEnd {
    let mut staging = Staging::default();
    let silence = tokio::time::sleep(SMA_SILENCE);
    tokio::pin!(silence);
    loop {
        tokio::select! {
            msg = reader.recv() => {
                silence.as_mut().reset(tokio::time::Instant::now() + SMA_SILENCE);
                match msg {
                    // Answered here, on the link's own thread, whatever the front end is doing.
                    Ok(SmaToViewer::Ping { nonce }) => {
                        if let Err(e) = writer.send(&ViewerToSma::Pong { nonce }).await {
                            return SessionEnd::Lost(e.to_string());
                        }
                    }
                    Ok(msg) => match staging.stage(msg) {
                        Staged::Held => {}
                        Staged::Closed(update) => notify(LinkEvent::Update(update)),
                        Staged::Other(other) => notify(other_event(other)),
                    },
                    Err(e) => return SessionEnd::Lost(e.to_string()),
                }
            }
            _ = &mut silence => {
                return SessionEnd::Lost(format!("the SMA sent nothing for {SMA_SILENCE:?}"));
            }
            out = inbox.recv() => match out {
                None => return SessionEnd::Finished,
                Some(msg) => {
                    let bye = msg == ViewerToSma::Bye;
                    if let Err(e) = writer.send(&msg).await {
                        return if bye { SessionEnd::Finished } else { SessionEnd::Lost(e.to_string()) };
                    }
                    if bye {
                        return SessionEnd::Finished;
                    }
                }
            },
        }
    }
}

/// Messages that are not part of an update. Update messages never reach here (staging holds
/// them); should one, it is reported rather than trusted.
fn other_event(msg: SmaToViewer) -> LinkEvent {
    match msg {
        SmaToViewer::SceneInfo(info) => LinkEvent::Scene(info),
        SmaToViewer::Refinement { criterion, paused } => {
            LinkEvent::Refinement { criterion, paused }
        }
        SmaToViewer::Stats(stats) => LinkEvent::Stats(stats),
        SmaToViewer::Error { message } => LinkEvent::RemoteError(message),
        other => LinkEvent::RemoteError(format!("unexpected {} outside an update", kind(&other))),
    }
}

fn kind(msg: &SmaToViewer) -> &'static str {
    match msg {
        SmaToViewer::SceneInfo(_) => "SceneInfo",
        SmaToViewer::Insert { .. } => "Insert",
        SmaToViewer::Remove { .. } => "Remove",
        SmaToViewer::Update { .. } => "Update",
        SmaToViewer::ToneMap { .. } => "ToneMap",
        SmaToViewer::Epoch(_) => "Epoch",
        SmaToViewer::Stats(_) => "Stats",
        SmaToViewer::Refinement { .. } => "Refinement",
        SmaToViewer::Error { .. } => "Error",
        SmaToViewer::Ping { .. } => "Ping",
    }
}
