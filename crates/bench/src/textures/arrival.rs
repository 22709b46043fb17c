//! A scene's textures reaching a viewer (DESIGN.md §5, "Parts, and textures"): a real SMA
//! process, started from the `walkthrough` binary with a renderer port that none joins (it
//! sends `SceneInfo` and the textures without a renderer), and the scripted viewer of
//! `testkit::probe`, timed from holding `SceneInfo` to holding the last `Texture`. Sponza is
//! measured with its textures on, from a copy of its scene file in a temporary folder.

use std::path::{Path, PathBuf};
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

/// Sponza's scene file, a copy of it with textures on written into `dir`, or why not: its OBJ
/// is absent (the scene is not redistributed with the project).
pub(super) fn sponza_textured(toml: &Path, dir: &Path) -> anyhow::Result<PathBuf> {
    let text = std::fs::read_to_string(toml)
        .with_context(|| format!("Sponza's scene file {} is absent", toml.display()))?;
    let folder = toml.parent().context("a scene file in a folder")?;
    let (textured, obj) = with_textures_on(&text, &std::path::absolute(folder)?)?;
    anyhow::ensure!(
        obj.is_file(),
        "Sponza's files are absent ({} not found)",
        obj.display()
    );
    let copy = dir.join("sponza-textured.toml");
    std::fs::write(&copy, textured)?;
    Ok(copy)
}

/// A scene file's text with `[textures] enabled = true` and its `obj` path made absolute
/// (relative paths are read from the file's folder, `folder`), so that a copy reads the same
/// files from anywhere; with that path.
fn with_textures_on(text: &str, folder: &Path) -> anyhow::Result<(String, PathBuf)> {
    let mut table: toml::Table = toml::from_str(text).context("parsing the scene file")?;
    let obj = table
        .get("obj")
        .and_then(toml::Value::as_str)
        .context("the scene file names no `obj`")?;
    let obj = folder.join(obj);
    let obj_text = obj.to_str().context("a path in UTF-8")?.to_string();
    table.insert("obj".into(), toml::Value::String(obj_text));
    let textures = table
        .entry("textures")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    textures
        .as_table_mut()
        .context("`textures` is not a table")?
        .insert("enabled".into(), toml::Value::Boolean(true));
    Ok((toml::to_string(&table)?, obj))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The copy turns textures on, keeps the table's other settings and every other key, and
    /// names the OBJ by its path from the original's folder.
    #[test]
    fn the_copy_turns_textures_on_and_names_the_obj_absolutely() {
        let text = "name = \"s\"\nobj = \"../models/s.obj\"\n\n[textures]\nenabled = false\n\
                    albedo = \"texture\"\n\n[[viewpoint]]\nname = \"V\"\nfov_y_deg = 60.0\n";
        let (copy, obj) = with_textures_on(text, Path::new("/data/scenes")).unwrap();
        assert_eq!(obj, Path::new("/data/scenes/../models/s.obj"));
        let table: toml::Table = toml::from_str(&copy).unwrap();
        assert_eq!(table["obj"].as_str(), Some("/data/scenes/../models/s.obj"));
        assert_eq!(table["name"].as_str(), Some("s"));
        assert_eq!(table["textures"]["enabled"].as_bool(), Some(true));
        assert_eq!(table["textures"]["albedo"].as_str(), Some("texture"));
        assert_eq!(table["viewpoint"][0]["fov_y_deg"].as_float(), Some(60.0));
    }

    /// The copy is written where asked and names an OBJ that is there; an OBJ that is not
    /// there is said to be absent, and no copy is written.
    #[test]
    fn sponza_s_copy_is_written_only_where_its_obj_is_there() {
        let dir = tempfile::tempdir().unwrap();
        let (scenes, copies) = (dir.path().join("scenes"), dir.path().join("copies"));
        std::fs::create_dir_all(&scenes).unwrap();
        std::fs::create_dir_all(&copies).unwrap();
        let toml = scenes.join("s.toml");
        std::fs::write(&toml, "obj = \"../models/s.obj\"\n").unwrap();
        let absent = sponza_textured(&toml, &copies).unwrap_err();
        assert!(format!("{absent:#}").contains("absent"), "{absent:#}");
        assert!(!copies.join("sponza-textured.toml").exists());
        std::fs::create_dir_all(dir.path().join("models")).unwrap();
        std::fs::write(dir.path().join("models/s.obj"), "v 0 0 0\n").unwrap();
        let copy = sponza_textured(&toml, &copies).unwrap();
        let table: toml::Table = toml::from_str(&std::fs::read_to_string(copy).unwrap()).unwrap();
        let obj = Path::new(table["obj"].as_str().unwrap());
        assert!(obj.is_absolute() && obj.is_file(), "{obj:?}");
        assert_eq!(table["textures"]["enabled"].as_bool(), Some(true));
    }

    /// A scene file without a `[textures]` table gets one; one without `obj` is refused.
    #[test]
    fn a_missing_textures_table_is_added_and_a_missing_obj_refused() {
        let (copy, _) = with_textures_on("obj = \"a.obj\"\n", Path::new("/s")).unwrap();
        let table: toml::Table = toml::from_str(&copy).unwrap();
        assert_eq!(table["textures"]["enabled"].as_bool(), Some(true));
        assert!(with_textures_on("name = \"x\"\n", Path::new("/s")).is_err());
    }
}
