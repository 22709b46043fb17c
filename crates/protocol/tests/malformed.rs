//! A malformed, truncated, oversized or unknown frame, and a wrong handshake, are error values with
//! the exact variant asserted: never a panic.

use protocol::connection::{
    MessageReader, MessageWriter, SceneCheck, accept_handshake, connect_handshake,
};
use protocol::frame::decode;
use protocol::handshake::{Hello, MAGIC, PROTOCOL_VERSION, Role};
use protocol::renderer_link::{FromRenderer, ToRenderer};
use protocol::viewer_link::{SmaToViewer, ViewerToSma};
use protocol::{ProtocolError, SceneIdentity};
use tokio::io::{AsyncWriteExt, duplex};

const MAX: usize = 1024;

/// A reader over raw bytes written by hand.
async fn read_raw(bytes: Vec<u8>) -> Result<ViewerToSma, ProtocolError> {
    let (mut tx, rx) = duplex(1 << 16);
    tx.write_all(&bytes).await.unwrap();
    drop(tx);
    MessageReader::<_, ViewerToSma>::new(rx, MAX).recv().await
}

fn framed(payload: &[u8]) -> Vec<u8> {
    let mut v = (payload.len() as u32).to_be_bytes().to_vec();
    v.extend_from_slice(payload);
    v
}

#[tokio::test]
async fn truncated_frame() {
    let mut bytes = framed(&[2, 1, 2, 3]);
    bytes.truncate(6);
    let r = read_raw(bytes).await;
    assert!(matches!(r, Err(ProtocolError::Truncated)), "{r:?}");
}

/// The codec has consumed the length when the stream ends: still a truncated frame, not a close.
#[tokio::test]
async fn a_stream_ending_right_after_a_length_is_truncated() {
    let r = read_raw(vec![0, 0, 0, 9]).await;
    assert!(matches!(r, Err(ProtocolError::Truncated)), "{r:?}");
}

#[tokio::test]
async fn clean_close_is_closed() {
    assert!(matches!(read_raw(vec![]).await, Err(ProtocolError::Closed)));
}

#[tokio::test]
async fn oversized_frame_is_refused_before_reading_it() {
    let mut bytes = ((MAX + 1) as u32).to_be_bytes().to_vec();
    bytes.extend(std::iter::repeat_n(0u8, 16));
    assert!(matches!(
        read_raw(bytes).await,
        Err(ProtocolError::FrameTooLarge { max: MAX })
    ));
}

#[tokio::test]
async fn unknown_message_tag() {
    // ViewerToSma has 5 variants: tag 77 is unknown to this version.
    let r = read_raw(framed(&[77])).await;
    assert!(matches!(r, Err(ProtocolError::UnknownMessage)), "{r:?}");
}

#[tokio::test]
async fn garbage_payload_is_malformed() {
    // Camera (tag 0) cut short after its sequence number.
    assert!(matches!(
        read_raw(framed(&[0, 5, 1])).await,
        Err(ProtocolError::Malformed(_))
    ));
    // Trailing bytes after a complete Pause.
    assert!(matches!(
        read_raw(framed(&[2, 9, 9])).await,
        Err(ProtocolError::Malformed(_))
    ));
}

#[test]
fn decode_never_panics_on_random_bytes() {
    let mut state = 0x9e3779b97f4a7c15u64;
    for len in 0..400 {
        let bytes: Vec<u8> = (0..len)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                state as u8
            })
            .collect();
        let _ = decode::<SmaToViewer>(&bytes);
        let _ = decode::<ToRenderer>(&bytes);
        let _ = decode::<FromRenderer>(&bytes);
    }
}

#[tokio::test]
async fn writer_refuses_a_message_larger_than_the_maximum() {
    let (tx, _rx) = duplex(1 << 16);
    let mut w = MessageWriter::<_, SmaToViewer>::new(tx, MAX);
    let msg = SmaToViewer::Remove {
        ids: (0..1000).map(|i| u64::MAX - i).collect(),
    };
    assert!(matches!(
        w.send(&msg).await,
        Err(ProtocolError::MessageTooLarge { max: MAX, .. })
    ));
}

/// The untextured scene whose fingerprint is 32 × `byte`.
fn scene(byte: u8) -> SceneIdentity {
    SceneIdentity {
        fingerprint: [byte; 32],
        textures: false,
    }
}

/// Runs a handshake between a connecting `hello` and an accepting renderer of scene `ours`.
async fn handshake(
    hello: Hello,
    ours: SceneIdentity,
) -> (Result<(), ProtocolError>, Result<(), ProtocolError>) {
    let (a, b) = duplex(1 << 16);
    let (ar, aw) = tokio::io::split(a);
    let (br, bw) = tokio::io::split(b);
    let mut cr = MessageReader::<_, FromRenderer>::new(ar, MAX);
    let mut cw = MessageWriter::<_, ToRenderer>::new(aw, MAX);
    let mut sr = MessageReader::<_, ToRenderer>::new(br, MAX);
    let mut sw = MessageWriter::<_, FromRenderer>::new(bw, MAX);
    let server = accept_handshake(
        &mut sr,
        &mut sw,
        Role::Renderer,
        Role::Sma,
        SceneCheck::Same(ours),
    );
    let client = connect_handshake(&mut cr, &mut cw, hello, Role::Renderer);
    let (s, c) = tokio::join!(server, client);
    (s.map(|_| ()), c.map(|_| ()))
}

#[tokio::test]
async fn matching_handshake_succeeds() {
    let (s, c) = handshake(Hello::new(Role::Sma, Some(scene(1))), scene(1)).await;
    assert!(s.is_ok() && c.is_ok(), "{s:?} {c:?}");
}

#[tokio::test]
async fn wrong_fingerprint_is_refused_on_both_sides() {
    let (s, c) = handshake(Hello::new(Role::Sma, Some(scene(2))), scene(1)).await;
    assert!(
        matches!(s, Err(ProtocolError::FingerprintMismatch { .. })),
        "{s:?}"
    );
    assert!(
        matches!(c, Err(ProtocolError::Refused(ref r)) if r.contains("fingerprint")),
        "{c:?}"
    );
}

/// A peer with the same scene but its textures on where ours are off (or the reverse) is refused,
/// saying so: the fingerprints differ as well, the textures are named first.
#[tokio::test]
async fn other_textures_are_refused_on_both_sides() {
    let textured = SceneIdentity {
        textures: true,
        ..scene(3)
    };
    for (theirs, ours) in [(textured, scene(1)), (scene(1), textured)] {
        let (s, c) = handshake(Hello::new(Role::Sma, Some(theirs)), ours).await;
        assert!(
            matches!(
                s,
                Err(ProtocolError::TexturesMismatch {
                    ours: a,
                    theirs: b
                }) if a == ours.textures && b == theirs.textures
            ),
            "{s:?}"
        );
        assert!(
            matches!(c, Err(ProtocolError::Refused(ref r)) if r.contains("textures mismatch")),
            "{c:?}"
        );
    }
    // Both textured, other textures: another fingerprint.
    let other = SceneIdentity {
        textures: true,
        ..scene(4)
    };
    let (s, _) = handshake(Hello::new(Role::Sma, Some(other)), textured).await;
    assert!(
        matches!(s, Err(ProtocolError::FingerprintMismatch { .. })),
        "{s:?}"
    );
}

#[tokio::test]
async fn wrong_magic_is_refused() {
    let hello = Hello {
        magic: *b"HTTP",
        version: PROTOCOL_VERSION,
        role: Role::Sma,
        scene: Some(scene(1)),
    };
    let (s, c) = handshake(hello, scene(1)).await;
    assert!(
        matches!(s, Err(ProtocolError::BadMagic { found }) if &found == b"HTTP"),
        "{s:?}"
    );
    assert!(matches!(c, Err(ProtocolError::Refused(_))));
}

#[tokio::test]
async fn wrong_version_is_refused() {
    let hello = Hello {
        magic: MAGIC,
        version: PROTOCOL_VERSION + 1,
        role: Role::Sma,
        scene: Some(scene(1)),
    };
    let (s, _) = handshake(hello, scene(1)).await;
    assert!(
        matches!(
            s,
            Err(ProtocolError::VersionMismatch {
                ours: PROTOCOL_VERSION,
                ..
            })
        ),
        "{s:?}"
    );
}

#[tokio::test]
async fn wrong_role_is_refused() {
    let (s, _) = handshake(Hello::new(Role::Viewer, Some(scene(1))), scene(1)).await;
    assert!(
        matches!(
            s,
            Err(ProtocolError::RoleMismatch {
                expected: Role::Sma,
                found: Role::Viewer
            })
        ),
        "{s:?}"
    );
}
