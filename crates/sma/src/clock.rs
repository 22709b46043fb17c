//! Waiting on the clock inside a `tokio::select!`, for the schedule's loop and the pool's
//! dispatcher: each wakes at the earliest of several optional instants.

/// Resolves at `at` (a `std` or a `tokio` instant); with none, never: a `select!` branch on it
/// then waits only for the other branches.
pub(crate) async fn sleep_until(at: Option<impl Into<tokio::time::Instant>>) {
    match at {
        Some(at) => tokio::time::sleep_until(at.into()).await,
        None => std::future::pending().await,
    }
}
