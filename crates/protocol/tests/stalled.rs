//! A frame begun must be finished within the reader's frame timeout (DESIGN.md §8): a peer that
//! stops halfway is cut off with `FrameStalled`, while a peer that is only quiet between frames,
//! however long, is not.

use std::time::Duration;

use protocol::frame::{DEFAULT_MAX_FRAME, encode};
use protocol::viewer_link::ViewerToSma;
use protocol::{MessageReader, ProtocolError};
use tokio::io::AsyncWriteExt;

const LIMIT: Duration = Duration::from_millis(100);

fn frame(message: &ViewerToSma) -> Vec<u8> {
    let payload = encode(message).unwrap();
    let mut out = (payload.len() as u32).to_be_bytes().to_vec();
    out.extend(payload);
    out
}

#[tokio::test]
async fn a_frame_stalled_halfway_is_cut_off_but_quiet_between_frames_is_not() {
    let (ours, mut theirs) = tokio::io::duplex(1024);
    let mut reader: MessageReader<_, ViewerToSma> = MessageReader::new(ours, DEFAULT_MAX_FRAME);
    reader.set_frame_timeout(LIMIT);

    // Quiet for three limits, then a whole frame: read as usual.
    let writer = tokio::spawn(async move {
        tokio::time::sleep(LIMIT * 3).await;
        theirs.write_all(&frame(&ViewerToSma::Pause)).await.unwrap();
        // Then half of the next frame, and nothing more (the stream stays open).
        let next = frame(&ViewerToSma::SetCriterion { name: "rnd".into() });
        theirs.write_all(&next[..next.len() / 2]).await.unwrap();
        theirs
    });
    assert_eq!(reader.recv().await.unwrap(), ViewerToSma::Pause);
    let _open = writer.await.unwrap();
    match reader.recv().await {
        Err(ProtocolError::FrameStalled { after }) => assert_eq!(after, LIMIT),
        other => panic!("expected FrameStalled, got {other:?}"),
    }
}
