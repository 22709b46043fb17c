//! The viewer listener: one task per accepted connection (tokio mini-redis style), ended
//! gracefully when the shutdown signal flips.

use tokio::net::TcpListener;
use tokio::sync::{mpsc, watch};

use crate::viewer_link::{self, ViewerEvent, ViewerId, ViewerLinkConfig};

/// Accepts viewers until shutdown. Accept errors (e.g. out of file descriptors) are logged and
/// retried after a pause rather than ending the server.
pub async fn accept_viewers(
    listener: TcpListener,
    config: ViewerLinkConfig,
    events: mpsc::UnboundedSender<ViewerEvent>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut next_id: ViewerId = 1;
    loop {
        let accepted = tokio::select! {
            a = listener.accept() => a,
            _ = shutdown.changed() => return,
        };
        match accepted {
            Ok((stream, _)) => {
                let task =
                    viewer_link::serve(stream, next_id, config.clone(), events.clone(), shutdown.clone());
                tokio::spawn(task);
                next_id += 1;
            }
            Err(e) => {
                tracing::warn!(error = %e, "accepting a viewer failed");
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
        }
    }
}
