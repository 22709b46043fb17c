//! The first frame on every link: magic, protocol version, role and, on the renderer link, the
//! scene's identity: its fingerprint and whether its textures are on (DESIGN.md §5, §8). A viewer
//! has no scene: it learns it from `SceneInfo`.

use serde::{Deserialize, Serialize};

use crate::error::{ProtocolError, short_hex};
use crate::types::SceneIdentity;

/// "WKTH": walkthrough.
pub const MAGIC: [u8; 4] = *b"WKTH";
/// Bumped on any incompatible change of a message.
pub const PROTOCOL_VERSION: u16 = 11;

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
    pub scene: Option<SceneIdentity>,
}

/// Sent back by the accepting side.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum HelloReply {
    Welcome {
        role: Role,
        version: u16,
        scene: Option<SceneIdentity>,
    },
    Refused {
        reason: String,
    },
}

impl Hello {
    pub fn new(role: Role, scene: Option<SceneIdentity>) -> Hello {
        Hello {
            magic: MAGIC,
            version: PROTOCOL_VERSION,
            role,
            scene,
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

/// Both sides must have loaded the same scene when one of them expects it: textures on or off
/// alike (said first, as the likelier slip), then the same fingerprint.
pub fn check_scene(
    ours: Option<&SceneIdentity>,
    theirs: Option<&SceneIdentity>,
) -> Result<(), ProtocolError> {
    match (ours, theirs) {
        (Some(a), Some(b)) if a.textures != b.textures => Err(ProtocolError::TexturesMismatch {
            ours: a.textures,
            theirs: b.textures,
        }),
        (Some(a), Some(b)) if a.fingerprint != b.fingerprint => {
            Err(ProtocolError::FingerprintMismatch {
                ours: short_hex(&a.fingerprint),
                theirs: short_hex(&b.fingerprint),
            })
        }
        (Some(a), None) => Err(ProtocolError::FingerprintMismatch {
            ours: short_hex(&a.fingerprint),
            theirs: "none".into(),
        }),
        _ => Ok(()),
    }
}
