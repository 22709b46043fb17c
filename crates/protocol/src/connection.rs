//! Typed message reader and writer over a byte stream, and the handshake on top of them.
//! Reading and writing are separate halves so a process can receive and send at the same time.

use std::io;
use std::marker::PhantomData;
use std::time::{Duration, Instant};

use bytes::Bytes;
use futures::{SinkExt, StreamExt};
use serde::{Serialize, de::DeserializeOwned};
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::TcpStream;
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio_util::codec::{FramedRead, FramedWrite, LengthDelimitedCodec};

use crate::admission::HANDSHAKE_MAX_FRAME;
use crate::error::ProtocolError;
use crate::frame::{FrameDecoder, WireMessage, codec, decode, decode_message, encode};
use crate::handshake::{Hello, HelloReply, PROTOCOL_VERSION, Role, check_scene};
use crate::types::SceneIdentity;

/// Reads typed messages `M`, one per frame.
pub struct MessageReader<R, M> {
    inner: FramedRead<R, FrameDecoder>,
    /// A frame begun must be complete this long after its first byte (DESIGN.md §8).
    frame_timeout: Option<Duration>,
    _msg: PhantomData<fn() -> M>,
}

/// Writes typed messages `M`, one per frame.
pub struct MessageWriter<W, M> {
    inner: FramedWrite<W, LengthDelimitedCodec>,
    max_frame: usize,
    _msg: PhantomData<fn(M)>,
}

impl<R: AsyncRead + Unpin, M: WireMessage> MessageReader<R, M> {
    pub fn new(io: R, max_frame: usize) -> Self {
        MessageReader {
            inner: FramedRead::new(io, FrameDecoder::new(max_frame)),
            frame_timeout: None,
            _msg: PhantomData,
        }
    }

    /// The largest frame accepted from the next frame on.
    pub fn max_frame(&self) -> usize {
        self.inner.decoder().max_frame_length()
    }

    pub fn set_max_frame(&mut self, max_frame: usize) {
        self.inner.decoder_mut().set_max_frame_length(max_frame);
    }

    /// From now on a frame that has begun must be complete within `limit`, or the read fails
    /// with `FrameStalled`: a peer that stops halfway through a frame is cut off rather than
    /// held open for good. Waiting for a frame to begin is not limited.
    pub fn set_frame_timeout(&mut self, limit: Duration) {
        self.frame_timeout = Some(limit);
    }

    /// The next message; `Err(Closed)` at a clean end of stream.
    pub async fn recv(&mut self) -> Result<M, ProtocolError> {
        let frame = self.recv_frame().await?;
        decode_message(&frame)
    }

    /// The next message decoded as another type (used for the handshake frame).
    pub async fn recv_as<T: DeserializeOwned>(&mut self) -> Result<T, ProtocolError> {
        let frame = self.recv_frame().await?;
        decode(&frame)
    }

    /// Cancel-safe: the bytes of a frame in progress stay in the decoder's buffer.
    async fn recv_frame(&mut self) -> Result<bytes::BytesMut, ProtocolError> {
        let next = loop {
            let Some(limit) = self.frame_timeout else {
                break self.inner.next().await;
            };
            // Until a frame begins, look again after one limit; once begun, at its deadline.
            let started = self.inner.decoder().frame_started();
            let check_at = started.unwrap_or_else(Instant::now) + limit;
            match tokio::time::timeout_at(check_at.into(), self.inner.next()).await {
                Ok(next) => break next,
                Err(_) => {
                    let begun = self.inner.decoder().frame_started();
                    if begun.is_some_and(|t| t.elapsed() >= limit) {
                        return Err(ProtocolError::FrameStalled { after: limit });
                    }
                }
            }
        };
        match next {
            Some(Ok(frame)) => Ok(frame),
            Some(Err(e)) => Err(map_codec_error(e, self.inner.decoder().max_frame_length())),
            None if self.inner.read_buffer().is_empty() => Err(ProtocolError::Closed),
            None => Err(ProtocolError::Truncated),
        }
    }
}

impl<W: AsyncWrite + Unpin, M: Serialize> MessageWriter<W, M> {
    pub fn new(io: W, max_frame: usize) -> Self {
        MessageWriter {
            inner: FramedWrite::new(io, codec(max_frame)),
            max_frame,
            _msg: PhantomData,
        }
    }

    pub async fn send(&mut self, msg: &M) -> Result<(), ProtocolError> {
        self.send_as(msg).await
    }

    /// Sends a payload encoded beforehand (`frame::encode`), e.g. by a task that counts the
    /// bytes it queues for a peer.
    pub async fn send_payload(&mut self, payload: Vec<u8>) -> Result<(), ProtocolError> {
        if payload.len() > self.max_frame {
            return Err(ProtocolError::MessageTooLarge {
                len: payload.len(),
                max: self.max_frame,
            });
        }
        self.inner
            .send(Bytes::from(payload))
            .await
            .map_err(ProtocolError::Io)
    }

    /// Sends a message of another type on the same stream (the handshake frame).
    pub async fn send_as<T: Serialize>(&mut self, msg: &T) -> Result<(), ProtocolError> {
        self.send_payload(encode(msg)?).await
    }
}

fn map_codec_error(e: io::Error, max: usize) -> ProtocolError {
    // LengthDelimitedCodec reports an oversized frame as InvalidData before reading its body.
    if e.kind() == io::ErrorKind::InvalidData {
        ProtocolError::FrameTooLarge { max }
    } else if e.kind() == io::ErrorKind::UnexpectedEof {
        // FrameDecoder's report of a stream that ends inside a frame.
        ProtocolError::Truncated
    } else {
        ProtocolError::Io(e)
    }
}

/// The two halves of a TCP link.
pub type TcpReader<M> = MessageReader<OwnedReadHalf, M>;
pub type TcpWriter<M> = MessageWriter<OwnedWriteHalf, M>;

/// Splits a TCP stream into a typed reader of `In` and writer of `Out`.
pub fn split_tcp<In: WireMessage, Out: Serialize>(
    stream: TcpStream,
    max_frame: usize,
) -> (TcpReader<In>, TcpWriter<Out>) {
    let _ = stream.set_nodelay(true);
    let (r, w) = stream.into_split();
    (
        MessageReader::new(r, max_frame),
        MessageWriter::new(w, max_frame),
    )
}

/// Connecting side: sends `Hello`, waits for the reply. Returns the peer's scene.
pub async fn connect_handshake<R, W, In, Out>(
    reader: &mut MessageReader<R, In>,
    writer: &mut MessageWriter<W, Out>,
    hello: Hello,
    expected_peer: Role,
) -> Result<Option<SceneIdentity>, ProtocolError>
where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
    In: WireMessage,
    Out: Serialize,
{
    let ours = hello.scene;
    writer.send_as(&hello).await?;
    match recv_handshake_frame::<_, _, HelloReply>(reader).await? {
        HelloReply::Welcome {
            role,
            version,
            scene,
        } => {
            if version != PROTOCOL_VERSION {
                return Err(ProtocolError::VersionMismatch {
                    ours: PROTOCOL_VERSION,
                    theirs: version,
                });
            }
            if role != expected_peer {
                return Err(ProtocolError::RoleMismatch {
                    expected: expected_peer,
                    found: role,
                });
            }
            check_scene(ours.as_ref(), scene.as_ref())?;
            Ok(scene)
        }
        HelloReply::Refused { reason } => Err(ProtocolError::Refused(reason)),
    }
}

/// What the accepting side of a handshake does with the scenes' identities (DESIGN.md §8).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneCheck {
    /// The peer must have loaded this same scene, textures on or off alike (the renderer link).
    Same(SceneIdentity),
    /// The peer has no scene of its own (a viewer): this one is only told, in the reply.
    Tell(SceneIdentity),
}

impl SceneCheck {
    fn ours(self) -> SceneIdentity {
        match self {
            SceneCheck::Same(scene) | SceneCheck::Tell(scene) => scene,
        }
    }

    /// A viewer need not name a scene, but one that names another scene than ours is lying.
    fn check(&self, theirs: Option<&SceneIdentity>) -> Result<(), ProtocolError> {
        match (self, theirs) {
            (SceneCheck::Same(ours), theirs) => check_scene(Some(ours), theirs),
            (SceneCheck::Tell(ours), Some(theirs)) => check_scene(Some(ours), Some(theirs)),
            (SceneCheck::Tell(_), None) => Ok(()),
        }
    }
}

/// Accepting side: reads `Hello` (one frame of at most [`HANDSHAKE_MAX_FRAME`] bytes), checks
/// it, replies `Welcome` or `Refused` (then the caller closes). No deadline: a server uses
/// [`accept_handshake_within`].
pub async fn accept_handshake<R, W, In, Out>(
    reader: &mut MessageReader<R, In>,
    writer: &mut MessageWriter<W, Out>,
    our_role: Role,
    expected_peer: Role,
    scene: SceneCheck,
) -> Result<Hello, ProtocolError>
where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
    In: WireMessage,
    Out: Serialize,
{
    let hello = recv_handshake_frame(reader).await;
    answer_hello(hello, writer, our_role, expected_peer, scene).await
}

/// [`accept_handshake`] that fails with `HandshakeTimeout` (and tells the peer so) unless the
/// peer's `Hello` has come within `deadline`: a peer that never says a word is not held open.
pub async fn accept_handshake_within<R, W, In, Out>(
    reader: &mut MessageReader<R, In>,
    writer: &mut MessageWriter<W, Out>,
    our_role: Role,
    expected_peer: Role,
    scene: SceneCheck,
    deadline: Duration,
) -> Result<Hello, ProtocolError>
where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
    In: WireMessage,
    Out: Serialize,
{
    let hello = tokio::time::timeout(deadline, recv_handshake_frame(reader))
        .await
        .unwrap_or(Err(ProtocolError::HandshakeTimeout { deadline }));
    answer_hello(hello, writer, our_role, expected_peer, scene).await
}

/// Accepting side of a port that is full: reads the peer's `Hello` within `deadline` (so the
/// refusal is read as a reply, not lost to a reset), then replies `Refused { reason }`.
pub async fn refuse_handshake<R, W, In, Out>(
    reader: &mut MessageReader<R, In>,
    writer: &mut MessageWriter<W, Out>,
    reason: String,
    deadline: Duration,
) where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
    In: WireMessage,
    Out: Serialize,
{
    let _ = tokio::time::timeout(deadline, recv_handshake_frame::<_, _, Hello>(reader)).await;
    let _ = writer.send_as(&HelloReply::Refused { reason }).await;
}

/// The one frame of a handshake, read with the frame limit lowered to [`HANDSHAKE_MAX_FRAME`]
/// (DESIGN.md §8): a peer that has not said who it is cannot announce a large frame.
async fn recv_handshake_frame<R, In, T>(
    reader: &mut MessageReader<R, In>,
) -> Result<T, ProtocolError>
where
    R: AsyncRead + Unpin,
    In: WireMessage,
    T: DeserializeOwned,
{
    let after = reader.max_frame();
    reader.set_max_frame(after.min(HANDSHAKE_MAX_FRAME));
    let received = reader.recv_as::<T>().await;
    reader.set_max_frame(after);
    received
}

/// Checks a received `Hello` and answers it: `Welcome` when it passes, else `Refused` with why.
async fn answer_hello<W, Out>(
    hello: Result<Hello, ProtocolError>,
    writer: &mut MessageWriter<W, Out>,
    our_role: Role,
    expected_peer: Role,
    scene: SceneCheck,
) -> Result<Hello, ProtocolError>
where
    W: AsyncWrite + Unpin,
    Out: Serialize,
{
    let checked = hello.and_then(|hello| {
        hello.check_identity(expected_peer)?;
        scene.check(hello.scene.as_ref())?;
        Ok(hello)
    });
    let hello = match checked {
        Ok(hello) => hello,
        Err(e) => {
            let _ = writer
                .send_as(&HelloReply::Refused {
                    reason: e.to_string(),
                })
                .await;
            return Err(e);
        }
    };
    writer
        .send_as(&HelloReply::Welcome {
            role: our_role,
            version: PROTOCOL_VERSION,
            scene: Some(scene.ours()),
        })
        .await?;
    Ok(hello)
}
