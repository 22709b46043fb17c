//! Everything that can go wrong on a link, as a typed value. A server answers a peer's bad frame
//! with an error reply and closes that connection; it never panics.

use thiserror::Error;

use crate::handshake::Role;

#[derive(Debug, Error)]
pub enum ProtocolError {
    #[error("i/o error: {0}")]
    Io(#[from] std::io::Error),
    #[error("incoming frame exceeds the maximum of {max} bytes")]
    FrameTooLarge { max: usize },
    #[error("message of {len} bytes exceeds the maximum frame of {max} bytes")]
    MessageTooLarge { len: usize, max: usize },
    #[error("connection closed in the middle of a frame")]
    Truncated,
    #[error("a frame begun was not complete within {after:?}: the peer stalled halfway")]
    FrameStalled { after: std::time::Duration },
    #[error("the peer took no part of a frame for {after:?}: it stopped reading")]
    WriteStalled { after: std::time::Duration },
    #[error("connection closed by peer")]
    Closed,
    #[error("unknown message kind (tag not known to this protocol version)")]
    UnknownMessage,
    #[error("malformed frame: {0}")]
    Malformed(String),
    #[error("bad magic {found:?}: peer does not speak the walkthrough protocol")]
    BadMagic { found: [u8; 4] },
    #[error("protocol version mismatch: ours {ours}, peer's {theirs}")]
    VersionMismatch { ours: u16, theirs: u16 },
    #[error("unexpected role: expected {expected:?}, peer says {found:?}")]
    RoleMismatch { expected: Role, found: Role },
    #[error("scene fingerprint mismatch: ours {ours}, peer's {theirs}")]
    FingerprintMismatch { ours: String, theirs: String },
    #[error(
        "scene textures mismatch: ours {}, peer's {}",
        on_off(*ours),
        on_off(*theirs)
    )]
    TexturesMismatch { ours: bool, theirs: bool },
    #[error("no handshake within {deadline:?}")]
    HandshakeTimeout { deadline: std::time::Duration },
    #[error("peer refused: {0}")]
    Refused(String),
    #[error("peer reported an error: {0}")]
    Remote(String),
}

impl ProtocolError {
    /// True when the peer simply went away (not a protocol violation).
    pub fn is_disconnect(&self) -> bool {
        matches!(self, ProtocolError::Closed | ProtocolError::Truncated)
            || matches!(self, ProtocolError::Io(e) if matches!(
                e.kind(),
                std::io::ErrorKind::ConnectionReset
                    | std::io::ErrorKind::BrokenPipe
                    | std::io::ErrorKind::UnexpectedEof
                    | std::io::ErrorKind::ConnectionAborted
            ))
    }
}

fn on_off(on: bool) -> &'static str {
    if on { "on" } else { "off" }
}

/// Short hex form of a fingerprint for messages.
pub fn short_hex(fp: &[u8]) -> String {
    fp.iter().take(8).map(|b| format!("{b:02x}")).collect()
}
