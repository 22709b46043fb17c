//! The first frame on every link: magic, protocol version, role and, on the renderer link, the
//! scene fingerprint (DESIGN.md §8). A viewer has no scene: it learns it from `SceneInfo`.

use serde::{Deserialize, Serialize};

use crate::error::{ProtocolError, short_hex};
use crate::types::Fingerprint;

/// "WKTH": walkthrough.
pub const MAGIC: [u8; 4] = *b"WKTH";
/// Bumped on any incompatible change of a message.
pub const PROTOCOL_VERSION: u16 = 6;

/// Who is speaking.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Role {
    Renderer,
    Sma,
    Viewer,
}

/// Sent by the connecting side.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hello {
    pub magic: [u8; 4],
    pub version: u16,
    pub role: Role,
    /// The scene the sender has loaded; `None` for a viewer.
    pub fingerprint: Option<Fingerprint>,
}

/// Sent back by the accepting side.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum HelloReply {
    Welcome {
        role: Role,
        version: u16,
        fingerprint: Option<Fingerprint>,
    },
    Refused {
        reason: String,
    },
}

impl Hello {
    pub fn new(role: Role, fingerprint: Option<Fingerprint>) -> Hello {
        Hello {
            magic: MAGIC,
            version: PROTOCOL_VERSION,
            role,
            fingerprint,
        }
    }

    /// Checks that a received hello speaks our protocol version as `expected_role`; the scene is
    /// the accepting side's `SceneCheck`.
    pub fn check_identity(&self, expected_role: Role) -> Result<(), ProtocolError> {
        if self.magic != MAGIC {
            return Err(ProtocolError::BadMagic { found: self.magic });
        }
        if self.version != PROTOCOL_VERSION {
            return Err(ProtocolError::VersionMismatch {
                ours: PROTOCOL_VERSION,
                theirs: self.version,
            });
        }
        if self.role != expected_role {
            return Err(ProtocolError::RoleMismatch {
                expected: expected_role,
                found: self.role,
            });
        }
        Ok(())
    }
}

/// Both sides must have loaded the same scene when one of them expects it.
pub fn check_fingerprint(
    ours: Option<&Fingerprint>,
    theirs: Option<&Fingerprint>,
) -> Result<(), ProtocolError> {
    match (ours, theirs) {
        (Some(a), Some(b)) if a != b => Err(ProtocolError::FingerprintMismatch {
            ours: short_hex(a),
            theirs: short_hex(b),
        }),
        (Some(a), None) => Err(ProtocolError::FingerprintMismatch {
            ours: short_hex(a),
            theirs: "none".into(),
        }),
        _ => Ok(()),
    }
}
