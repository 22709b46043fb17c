//! The system-test harness (not part of the product): what the sma, viewer and root tests and the
//! launcher's benchmarks need to drive real processes and check what travels between them.
//!
//! - [`child`]: a server started as a child process, with the address it reports;
//! - [`loopback`]: renderer(s) and SMA as child processes, and a headless viewer run against them;
//! - [`liar`]: peers that lie before their handshake, and the refusal they get;
//! - [`probe`]: a scripted viewer that checks every update the SMA sends;
//! - [`fake_renderer`]: a renderer stand-in that shades a known function and logs requests;
//! - [`fake_sma`]: an SMA stand-in that sends what a viewer test queues and reports what it hears;
//! - [`ground_truth`]: a view's per-pixel reference image, rendered once and kept on disk;
//! - [`gpu`]: the `WALKTHROUGH_REQUIRE_GPU` rule for tests that need an adapter;
//! - [`moved_scene`]: a scene moved far from the origin, geometry and viewpoints;
//! - [`views`]: a scene's viewpoint as a viewer's camera.

pub mod child;
pub mod fake_renderer;
pub mod fake_sma;
pub mod gpu;
pub mod ground_truth;
pub mod liar;
pub mod loopback;
pub mod moved_scene;
pub mod probe;
pub mod views;
