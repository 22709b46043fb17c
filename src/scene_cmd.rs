//! `walkthrough scene info <scene>` and `walkthrough scene export <builtin> <dir>`.

use std::path::Path;

/// Prints the counts, bounds, effects and fingerprint of `spec`, and the base triangles each
/// viewpoint sees at `width` × `height`.
pub fn info(spec: &str, width: u32, height: u32) -> anyhow::Result<()> {
    let loaded = scene::load(spec)?;
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

/// Writes the built-in scene `builtin` as OBJ + MTL + TOML into `dir`.
pub fn export(builtin: &str, dir: &Path) -> anyhow::Result<()> {
    let loaded = scene::load(builtin)?;
    std::fs::create_dir_all(dir)?;
    let written = scene::export::write_obj_mtl_toml(&loaded, dir)?;
    println!("wrote {}", written.display());
    Ok(())
}
