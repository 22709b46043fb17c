//! A scene's textures reaching a viewer (DESIGN.md §5, "Parts, and textures"): a real SMA
//! process, started from the `walkthrough` binary with a renderer port that none joins (it
//! sends `SceneInfo` and the textures without a renderer), and the scripted viewer of
//! `testkit::probe`, timed from holding `SceneInfo` to holding the last `Texture`. Sponza is
//! measured with its textures on, from `scenes/sponza-textured.toml`.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context;
use protocol::texture::TextureImage;
use protocol::viewer_link::SceneInfo;
use testkit::child::{start_sma, strings};
use testkit::probe::Probe;

/// How long one viewer may wait for the textures before the run fails.
const WAIT: Duration = Duration::from_secs(60);

/// One scene's textures as a viewer received them, and how long they took.
pub(super) struct Arrival {
    pub info: SceneInfo,
    pub images: Vec<TextureImage>,
    /// Seconds from holding `SceneInfo` to holding the last `Texture`, one per viewer
    /// connection.
    pub seconds: Vec<f64>,
    /// Seconds from connecting (the handshake) to holding the last `Texture`, likewise.
    pub from_connect: Vec<f64>,
}

impl Arrival {
    pub fn png_bytes(&self) -> usize {
        self.images.iter().map(|t| t.png.len()).sum()
    }
}

/// Starts an SMA on `scene` (a built-in name or a TOML file), connects `runs` viewers one
/// after the other, each waiting for every texture; the SMA's log goes into `logs`.
pub(super) fn measure(scene: &str, runs: usize, logs: &Path) -> anyhow::Result<Arrival> {
    let exe = crate::product::walkthrough_exe()?;
    let log = logs.join(format!(
        "sma-{}.log",
        Path::new(scene)
            .file_stem()
            .map_or(scene.into(), |s| s.to_string_lossy())
    ));
    let flags = strings(&["--renderer-listen", "127.0.0.1:0"]);
    let sma = start_sma(&exe, scene, &[], &flags, Some(&log))?;
    let addr = sma.addr.to_string();
    tokio::runtime::Runtime::new()?.block_on(async {
        let (mut seconds, mut from_connect) = (Vec::new(), Vec::new());
        let mut last = None;
        for _ in 0..runs.max(1) {
            let connecting = Instant::now();
            let mut probe = Probe::connect(&addr).await?;
            let scene_info = Instant::now();
            probe.until_textures(WAIT).await?;
            seconds.push(scene_info.elapsed().as_secs_f64());
            from_connect.push(connecting.elapsed().as_secs_f64());
            last = Some(probe);
        }
        let probe = last.expect("at least one run");
        Ok(Arrival {
            info: probe.scene.clone(),
            images: probe.textures.iter().flatten().cloned().collect(),
            seconds,
            from_connect,
        })
    })
}

/// Sponza's scene file with its textures on (`scenes/sponza-textured.toml`, which extends
/// `sponza.toml`), or why it cannot be measured: its OBJ is absent (the scene is not
/// redistributed with the project).
pub(super) fn sponza_textured() -> anyhow::Result<&'static str> {
    let scene = crate::scene::SPONZA_TEXTURED;
    scene::load(scene)
        .with_context(|| format!("Sponza's files are absent or unreadable ({scene})"))?;
    Ok(scene)
}
