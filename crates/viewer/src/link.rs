//! The connection to the SMA (DESIGN.md §2, §8): a task on its own thread and tokio runtime that
//! connects, shakes hands, receives `SceneInfo`, then stages incoming changes until their epoch
//! and forwards what the viewer may draw. When the link drops it reconnects with exponential
//! backoff; every new session starts from an empty table (the SMA forgets what a viewer held).
//!
//! The viewer's front end (window or headless) gets [`LinkEvent`]s through a callback; both front
//! ends make it a bounded queue ([`event_queue`]) that wakes a winit event loop through its proxy
//! and that a headless loop polls.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use protocol::connection::{TcpReader, TcpWriter, connect_handshake};
use protocol::direct_tile::ViewerTile;
use protocol::frame::DEFAULT_MAX_FRAME;
use protocol::liveness::Liveness;
use protocol::texture::TextureImage;
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
    /// Per-pixel direct light of a resting camera (not part of an update: a tile is drawn as it
    /// comes, for the camera it names).
    DirectTile(ViewerTile),
    /// One of the scene's textures (`SceneInfo::texture_table`), before any triangle uses it.
    Texture(TextureImage),
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

/// Messages the front end may have queued for the SMA. The link's task takes them as they come
/// (between sessions it drops them); they wait only while a write to the SMA waits for room in
/// the socket, or while the link waits for a front end [`EVENT_QUEUE`] events behind, which is
/// then not sending either. The front end sends at most 20 cameras a second (`camera_sender`)
/// and a command per key or click, so a full outbox means the SMA has read nothing for seconds
/// past the socket's own buffer: what comes then is dropped (see [`Link::send`]) rather than
/// make the front end wait for the SMA.
const OUTBOX: usize = 64;

/// Link events a front end may be behind by (see [`event_queue`]). The SMA closes an update at
/// most every 50 ms, plus a `Stats` a second, and the front end takes what is queued every
/// frame or tick, so 256 are some 12 s of a front end that does not look. Past that the link's
/// thread waits for it and reads nothing more: what the SMA has for this viewer then waits in
/// the SMA's own bounded outbox, coalesced per triangle, rather than here.
pub(crate) const EVENT_QUEUE: usize = 256;

/// The queue between the link and a front end that takes the events in its own loop: the
/// callback for [`Link::spawn`], which queues each event, waiting while [`EVENT_QUEUE`] are
/// queued, and calls `wake` unless a wake-up is already pending; and the receiving end. A front
/// end that `wake` wakes calls [`EventQueue::woken`] before it takes what is queued. Drop the
/// receiving end before closing the link, so a link waiting for room stops waiting.
pub(crate) fn event_queue(
    wake: impl Fn() + Send + 'static,
) -> (impl Fn(LinkEvent) + Send + 'static, EventQueue) {
    let (tx, receiver) = std::sync::mpsc::sync_channel(EVENT_QUEUE);
    let pending = Arc::new(AtomicBool::new(false));
    let notify_pending = Arc::clone(&pending);
    let notify = move |event| {
        if tx.send(event).is_ok() && !notify_pending.swap(true, Ordering::SeqCst) {
            wake();
        }
    };
    (notify, EventQueue { receiver, pending })
}

/// The front end's end of [`event_queue`].
pub(crate) struct EventQueue {
    pub receiver: std::sync::mpsc::Receiver<LinkEvent>,
    pending: Arc<AtomicBool>,
}

impl EventQueue {
    /// Marks the wake-up taken: an event queued from now on wakes the front end again, so none
    /// is left behind one it has already taken.
    pub fn woken(&self) {
        self.pending.store(false, Ordering::SeqCst);
    }
}

/// The front end's handle: messages to the SMA, and the thread to join at the end.
pub struct Link {
    /// `None` once the link is shut down: its task then ends when it has taken what is queued.
    outbox: Option<mpsc::Sender<ViewerToSma>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Link {
    /// Starts the link task. `notify` runs on the link's thread for every event.
    pub fn spawn(
        addr: String,
        notify: impl Fn(LinkEvent) + Send + 'static,
    ) -> anyhow::Result<Link> {
        let (outbox, inbox) = mpsc::channel(OUTBOX);
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        let thread = std::thread::Builder::new()
            .name("sma-link".into())
            .spawn(move || runtime.block_on(run(addr, notify, inbox)))?;
        Ok(Link {
            outbox: Some(outbox),
            thread: Some(thread),
        })
    }

    /// Queues a message without waiting; dropped while disconnected (the front end resends its
    /// state on `Connected`, so nothing stale reaches a new session), and dropped with a warning
    /// when [`OUTBOX`] messages already wait for an SMA that reads nothing.
    pub fn send(&self, msg: ViewerToSma) {
        let Some(outbox) = &self.outbox else { return };
        if let Err(mpsc::error::TrySendError::Full(msg)) = outbox.try_send(msg) {
            tracing::warn!(
                "the SMA has not read {OUTBOX} messages; dropping {}",
                outgoing_kind(&msg)
            );
        }
    }

    /// Says goodbye to the SMA and waits for the link to end.
    pub fn close(mut self) {
        self.shut_down();
    }

    /// Says `Bye` if the outbox has room, then closes it: the task ends once it has taken what
    /// is queued, `Bye` or not, so the join never waits on a full outbox.
    fn shut_down(&mut self) {
        if let Some(outbox) = self.outbox.take() {
            let _ = outbox.try_send(ViewerToSma::Bye);
        }
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

async fn run(addr: String, notify: impl Fn(LinkEvent), mut inbox: mpsc::Receiver<ViewerToSma>) {
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
    inbox: &mut mpsc::Receiver<ViewerToSma>,
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
        SmaToViewer::SceneInfo(info) => Ok((reader, writer, *info)),
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
    inbox: &mut mpsc::Receiver<ViewerToSma>,
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
                    // Not held for an epoch: a tile replaces nothing of the table (DESIGN.md §3
                    // step 8).
                    Ok(SmaToViewer::DirectTile(tile)) => notify(LinkEvent::DirectTile(tile)),
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
        SmaToViewer::SceneInfo(info) => LinkEvent::Scene(*info),
        SmaToViewer::Refinement { criterion, paused } => {
            LinkEvent::Refinement { criterion, paused }
        }
        SmaToViewer::Stats(stats) => LinkEvent::Stats(stats),
        SmaToViewer::Texture(image) => LinkEvent::Texture(image),
        SmaToViewer::Error { message } => LinkEvent::RemoteError(message),
        other => LinkEvent::RemoteError(format!("unexpected {} outside an update", kind(&other))),
    }
}

fn outgoing_kind(msg: &ViewerToSma) -> &'static str {
    match msg {
        ViewerToSma::Camera(_) => "Camera",
        ViewerToSma::SetCriterion { .. } => "SetCriterion",
        ViewerToSma::Pause => "Pause",
        ViewerToSma::Resume => "Resume",
        ViewerToSma::Bye => "Bye",
        ViewerToSma::Pong { .. } => "Pong",
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
        SmaToViewer::DirectTile(_) => "DirectTile",
        SmaToViewer::Texture(_) => "Texture",
    }
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::AtomicUsize;

    use super::*;

    fn stats() -> LinkEvent {
        LinkEvent::Stats(Stats::default())
    }

    #[test]
    fn the_event_queue_wakes_once_per_taking() {
        let wakes = Arc::new(AtomicUsize::new(0));
        let counted = Arc::clone(&wakes);
        let (notify, queue) = event_queue(move || {
            counted.fetch_add(1, Ordering::SeqCst);
        });
        notify(stats());
        notify(stats());
        assert_eq!(
            wakes.load(Ordering::SeqCst),
            1,
            "one wake-up pending at a time"
        );
        queue.woken();
        assert_eq!(queue.receiver.try_iter().count(), 2);
        notify(stats());
        assert_eq!(
            wakes.load(Ordering::SeqCst),
            2,
            "an event after the taking wakes again"
        );
    }

    #[test]
    fn a_full_event_queue_lets_go_once_its_receiver_is_dropped() {
        let (notify, queue) = event_queue(|| {});
        for _ in 0..EVENT_QUEUE {
            notify(stats());
        }
        let blocked = std::thread::spawn(move || notify(stats()));
        std::thread::sleep(Duration::from_millis(50));
        assert!(!blocked.is_finished(), "a full queue holds the link back");
        drop(queue);
        blocked.join().expect("the link goes on");
    }
}
