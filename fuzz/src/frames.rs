//! What the frame fuzz targets do with one input: feed it, as the bytes a peer sent, to the
//! readers of both directions of a link (DESIGN.md §8), through the same `MessageReader` and
//! handshake functions the services use. A decoder must answer every input with a message or an
//! error: a panic, or an allocation sized by an announced length beyond the maximum frame, is a
//! crash. The protocol crate's `fuzz_corpus` test includes this file to replay the corpus on
//! stable Rust.

use std::fmt::Debug;

use futures::executor::block_on;
use protocol::connection::{
    MessageReader, MessageWriter, SceneCheck, accept_handshake, connect_handshake,
};
use protocol::frame::{decode, encode};
use protocol::renderer_link::{FromRenderer, ToRenderer};
use protocol::viewer_link::{SmaToViewer, ViewerToSma};
use protocol::{Hello, ProtocolError, Role, SceneIdentity, WireMessage};

/// The maximum frame of the readers here. The services' (64 MiB, DESIGN.md §8) would let every
/// input that announces a large frame reserve that much, which costs the fuzzer more than the
/// decoding; the size check is the same comparison at any maximum, and inputs stay far below both.
pub const MAX_FRAME: usize = 64 * 1024;

/// The scene the renderer side of the handshake has loaded.
pub const RENDERER_SCENE: SceneIdentity = SceneIdentity {
    fingerprint: [7; 32],
    textures: false,
};

/// The handshake as each accepting and each connecting side runs it, on the input as what the
/// peer said: the renderer accepting an SMA (scene checked), the SMA accepting a viewer,
/// the SMA connecting to a renderer and a viewer connecting to the SMA. True when one of them
/// accepted the peer.
pub fn handshake(data: &[u8]) -> bool {
    block_on(async {
        let (mut reader, mut writer) = endpoints::<ToRenderer>(data);
        let renderer_accepts = accept_handshake(
            &mut reader,
            &mut writer,
            Role::Renderer,
            Role::Sma,
            SceneCheck::Same(RENDERER_SCENE),
        )
        .await
        .is_ok();
        let (mut reader, mut writer) = endpoints::<ViewerToSma>(data);
        let sma_accepts = accept_handshake(
            &mut reader,
            &mut writer,
            Role::Sma,
            Role::Viewer,
            // The SMA's scene, only told: a viewer has none to check.
            SceneCheck::Tell(RENDERER_SCENE),
        )
        .await
        .is_ok();
        let (mut reader, mut writer) = endpoints::<FromRenderer>(data);
        let hello = Hello::new(Role::Sma, Some(RENDERER_SCENE));
        let sma_connects = connect_handshake(&mut reader, &mut writer, hello, Role::Renderer)
            .await
            .is_ok();
        let (mut reader, mut writer) = endpoints::<SmaToViewer>(data);
        let hello = Hello::new(Role::Viewer, None);
        let viewer_connects = connect_handshake(&mut reader, &mut writer, hello, Role::Sma)
            .await
            .is_ok();
        renderer_accepts || sma_accepts || sma_connects || viewer_connects
    })
}

/// The renderer link after the handshake: the renderer reading `ToRenderer`, the SMA reading
/// `FromRenderer`. True when every frame was a message of one direction.
pub fn renderer_link(data: &[u8]) -> bool {
    let to_renderer = read_all::<ToRenderer>(data);
    read_all::<FromRenderer>(data) || to_renderer
}

/// The viewer link after the handshake: the SMA reading `ViewerToSma`, the viewer reading
/// `SmaToViewer`. True when every frame was a message of one direction.
pub fn viewer_link(data: &[u8]) -> bool {
    let to_sma = read_all::<ViewerToSma>(data);
    read_all::<SmaToViewer>(data) || to_sma
}

/// A reader of `data` and a writer into nothing.
fn endpoints<M: WireMessage>(
    data: &[u8],
) -> (
    MessageReader<&[u8], M>,
    MessageWriter<tokio::io::Sink, protocol::HelloReply>,
) {
    (
        MessageReader::new(data, MAX_FRAME),
        MessageWriter::new(tokio::io::sink(), MAX_FRAME),
    )
}

/// Reads messages until the stream ends or breaks. A service closes the link at the first bad
/// frame; reading on past a malformed payload (the framing is still in step) tries every frame of
/// the input. True when the stream held only whole, valid messages.
fn read_all<M: WireMessage + Debug>(data: &[u8]) -> bool {
    let mut reader = MessageReader::<_, M>::new(data, MAX_FRAME);
    let mut all_valid = true;
    block_on(async {
        loop {
            match reader.recv().await {
                Ok(message) => check_reencodes(&message),
                Err(ProtocolError::Malformed(_) | ProtocolError::UnknownMessage) => {
                    all_valid = false;
                }
                Err(ProtocolError::Closed) => return all_valid,
                Err(_) => return false,
            }
        }
    })
}

/// Whatever was decoded encodes again, and that encoding decodes to a message that encodes the
/// same: the wire format has no message that one side can read and the other cannot write.
/// (Compared as bytes: a decoded NaN is not equal to itself.)
fn check_reencodes<M: WireMessage + Debug>(message: &M) {
    let bytes = encode(message).expect("a decoded message encodes");
    let again: M = decode(&bytes)
        .unwrap_or_else(|e| panic!("the encoding of {message:?} does not decode: {e}"));
    assert_eq!(encode(&again).expect("encodes"), bytes, "{message:?}");
}
