//! Peers that lie to a server's port (DESIGN.md §8): each says one thing an honest peer never
//! would before its handshake is done, and expects to be refused with a reason and closed.

use anyhow::{Context, bail};
use protocol::connection::TcpReader;
use protocol::frame::{DEFAULT_MAX_FRAME, encode};
use protocol::viewer_link::SmaToViewer;
use protocol::{Hello, HelloReply, MessageReader, ProtocolError};
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;

/// A `Hello` as a whole frame: its length, then the message.
pub fn hello_frame(hello: &Hello) -> Vec<u8> {
    let payload = encode(hello).expect("a Hello encodes");
    let mut frame = (payload.len() as u32).to_be_bytes().to_vec();
    frame.extend(payload);
    frame
}

/// The length of a 64 MiB frame, announced as the first thing said, with no body.
pub fn large_frame_announcement() -> Vec<u8> {
    (DEFAULT_MAX_FRAME as u32).to_be_bytes().to_vec()
}

/// Connects to `addr`, says `said` (nothing at all when empty), and returns the reason of the
/// server's `Refused`, once the server has also closed the connection.
pub async fn refusal(addr: &str, said: &[u8]) -> anyhow::Result<String> {
    let stream = TcpStream::connect(addr)
        .await
        .with_context(|| format!("connecting to {addr}"))?;
    let (read, mut write) = stream.into_split();
    write.write_all(said).await?;
    let mut reader: TcpReader<SmaToViewer> = MessageReader::new(read, DEFAULT_MAX_FRAME);
    let reason = match reader.recv_as::<HelloReply>().await? {
        HelloReply::Refused { reason } => reason,
        welcome => bail!("a lying peer was welcomed: {welcome:?}"),
    };
    match reader.recv_as::<HelloReply>().await {
        Err(ProtocolError::Closed) => Ok(reason),
        Err(e) if e.is_disconnect() => Ok(reason),
        other => bail!("the connection stayed open after the refusal ({reason}): {other:?}"),
    }
}
