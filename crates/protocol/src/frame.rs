//! Framing: a 4-byte big-endian length, then a postcard payload (DESIGN.md §8). postcard has a
//! stable, documented wire format (varint integers, little-endian floats), so bulk data such as
//! triangles and radiance stays compact without a hand-written encoding.

use std::io;
use std::time::Instant;

use bytes::BytesMut;
use serde::{Serialize, de::DeserializeOwned};
use tokio_util::codec::{Decoder, LengthDelimitedCodec};

use crate::error::ProtocolError;
use crate::variant_count::variant_count;

/// Default maximum frame: 64 MiB, room for ~800k triangles in one `Insert`.
pub const DEFAULT_MAX_FRAME: usize = 64 * 1024 * 1024;

/// The codec of every link, with a maximum frame length.
pub fn codec(max_frame: usize) -> LengthDelimitedCodec {
    LengthDelimitedCodec::builder()
        .length_field_length(4)
        .max_frame_length(max_frame)
        .new_codec()
}

/// The decoder of every link: the frames of [`codec`], except that a stream ending inside a frame
/// is an error (`UnexpectedEof`) even right after the length. `LengthDelimitedCodec` consumes the
/// length before the body comes, so at that end its buffer is empty and the stream would read as
/// a clean close (DESIGN.md §8: a malformed frame is an error, then the connection closes).
pub struct FrameDecoder {
    codec: LengthDelimitedCodec,
    /// A length was read and its body has not been returned yet.
    inside_frame: bool,
    /// When the first byte of the frame not yet returned came, if one has.
    started: Option<Instant>,
}

impl FrameDecoder {
    pub fn new(max_frame: usize) -> FrameDecoder {
        FrameDecoder {
            codec: codec(max_frame),
            inside_frame: false,
            started: None,
        }
    }

    /// When the first byte of a frame not yet complete came; `None` between frames.
    pub fn frame_started(&self) -> Option<Instant> {
        self.started
    }

    pub fn max_frame_length(&self) -> usize {
        self.codec.max_frame_length()
    }

    pub fn set_max_frame_length(&mut self, max_frame: usize) {
        self.codec.set_max_frame_length(max_frame);
    }
}

impl Decoder for FrameDecoder {
    type Item = BytesMut;
    type Error = io::Error;

    fn decode(&mut self, src: &mut BytesMut) -> io::Result<Option<BytesMut>> {
        let buffered = src.len();
        if buffered > 0 && self.started.is_none() {
            self.started = Some(Instant::now());
        }
        let frame = self.codec.decode(src)?;
        if frame.is_some() {
            self.inside_frame = false;
            // What follows a complete frame came with it: the next frame starts now.
            self.started = (!src.is_empty()).then(Instant::now);
        } else if src.len() < buffered {
            self.inside_frame = true;
        }
        Ok(frame)
    }

    fn decode_eof(&mut self, src: &mut BytesMut) -> io::Result<Option<BytesMut>> {
        match self.decode(src)? {
            None if self.inside_frame || !src.is_empty() => Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "the stream ended inside a frame",
            )),
            frame => Ok(frame),
        }
    }
}

/// Encodes one message into a payload (without the length prefix).
pub fn encode<M: Serialize>(msg: &M) -> Result<Vec<u8>, ProtocolError> {
    postcard::to_stdvec(msg).map_err(|e| ProtocolError::Malformed(e.to_string()))
}

/// Decodes one payload. Trailing bytes are an error: a frame holds exactly one message.
pub fn decode<M: DeserializeOwned>(payload: &[u8]) -> Result<M, ProtocolError> {
    match postcard::take_from_bytes::<M>(payload) {
        Ok((msg, [])) => Ok(msg),
        Ok((_, rest)) => Err(ProtocolError::Malformed(format!(
            "{} trailing bytes after the message",
            rest.len()
        ))),
        Err(postcard::Error::DeserializeBadEnum) => Err(ProtocolError::UnknownMessage),
        Err(e) => Err(ProtocolError::Malformed(e.to_string())),
    }
}

/// A message enum of one link direction. postcard writes the variant index as the first varint,
/// so a tag beyond the last variant is an unknown message, not garbage.
pub trait WireMessage: Serialize + DeserializeOwned {
    /// The number of message kinds, from the enum's serde derive.
    fn kinds() -> u32 {
        variant_count::<Self>()
    }
}

/// Decodes one message, telling an unknown message kind apart from a malformed payload.
pub fn decode_message<M: WireMessage>(payload: &[u8]) -> Result<M, ProtocolError> {
    match postcard::take_from_bytes::<u32>(payload) {
        Ok((tag, _)) if tag >= M::kinds() => Err(ProtocolError::UnknownMessage),
        _ => decode(payload),
    }
}
