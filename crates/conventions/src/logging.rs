//! One log format for every process of the system: the renderer, the SMA, the viewer and the
//! launcher all print through [`init`], so their lines read alike in one terminal.

use std::io::IsTerminal;

use tracing_subscriber::EnvFilter;

/// Our crates at `info`, everyone else's (winit, wgpu, egui) only from `warn`: what a person
/// needs to follow the system, not its libraries' chatter.
const DEFAULT_FILTER: &str = "warn,conventions=info,protocol=info,scene=info,renderer=info,\
                              sma=info,viewer=info,walkthrough=info,testkit=info,egui_wgpu=error";

/// The message a headless viewer logs (at `info`) when its measured run ends, before it closes
/// its link and writes the snapshots left: a harness that reads its log takes the processes'
/// CPU times and the run's wall time there, not at its exit.
pub const HEADLESS_RUN_OVER: &str = "headless run over";

/// Logs to stderr at [`DEFAULT_FILTER`] unless `RUST_LOG` says otherwise, without the module
/// path, in colour only when stderr is a terminal. A second call (a test that runs two front
/// ends) keeps the first.
pub fn init() {
    let filter =
        EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(DEFAULT_FILTER));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_target(false)
        .try_init();
}
