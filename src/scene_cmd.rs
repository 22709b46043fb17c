//! `walkthrough scene info <scene>` and `walkthrough scene export <builtin> <dir>`.

use std::path::PathBuf;

use clap::Subcommand;

#[derive(Subcommand, Debug)]
pub enum SceneCommand {
    /// Triangles, vertices, materials, bounds, dropped triangles, effects, fingerprint, and the
    /// visible base triangles per viewpoint.
    Info {
        /// A scene TOML file or a built-in name (bracara, cornell).
        scene: String,
        /// Image size for the per-viewpoint visibility estimate.
        #[arg(long, default_value_t = 1024)]
        width: u32,
        #[arg(long, default_value_t = 768)]
        height: u32,
    },
    /// Writes a built-in scene as OBJ + MTL + TOML.
    Export { builtin: String, dir: PathBuf },
}

pub fn run(cmd: SceneCommand) -> anyhow::Result<()> {
    match cmd {
        SceneCommand::Info {
            scene,
            width,
            height,
        } => {
            let loaded = scene::load(&scene)?;
            print!("{}", scene::info::describe(&loaded));
            for vp in &loaded.settings.viewpoints {
                let n = scene::visible_base_triangles(&loaded, vp, width, height);
                println!(
                    "viewpoint {:<6} visible base triangles at {width}x{height}: {n}",
                    vp.name
                );
            }
            Ok(())
        }
        SceneCommand::Export { builtin, dir } => {
            let loaded = scene::load(&builtin)?;
            std::fs::create_dir_all(&dir)?;
            let written = scene::export::write_obj_mtl_toml(&loaded, &dir)?;
            println!("wrote {}", written.display());
            Ok(())
        }
    }
}
