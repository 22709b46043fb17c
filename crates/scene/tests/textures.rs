//! Diffuse textures in the scene (DESIGN.md §5): `map_Kd` and texture coordinates read from
//! files held in memory, the fallback to `Kd` with one warning, options honoured or warned about
//! once, and the fingerprint, which covers textures when they are on and only then.

use std::collections::HashMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use scene::{AlbedoRule, Scene, Wrap, load, load_scene_file_from};

const ON: &str = "[textures]\nenabled = true\n";

/// A unit quad in the y = 0 plane, its two triangles textured (u = x, v = z), with one material
/// `mat`, and a second quad beside it of material `plain`.
const OBJ: &str = "mtllib lib/m.mtl
v 0 0 0
v 1 0 0
v 1 0 1
v 0 0 1
v 2 0 0
v 2 0 1
vt 0 0
vt 1 0
vt 1 1
vt 0 1
usemtl mat
f 1/1 4/4 3/3
f 1/1 3/3 2/2
usemtl plain
f 2/1 3/4 6/3
f 2/1 6/3 5/2
";

fn png(texels: &[[u8; 3]], width: u32, height: u32) -> Vec<u8> {
    let image = image::RgbImage::from_raw(width, height, texels.concat()).expect("sizes");
    let mut bytes = Cursor::new(Vec::new());
    image
        .write_to(&mut bytes, image::ImageFormat::Png)
        .expect("encodes");
    bytes.into_inner()
}

/// 2 × 2: red, green above; blue, white below.
fn checker() -> Vec<u8> {
    png(
        &[[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255]],
        2,
        2,
    )
}

/// The scene `t.toml` (with `toml_extra` appended), `t.obj` = `obj`, `lib/m.mtl` = `mtl`, and
/// further files, all in memory.
fn load_with(toml_extra: &str, obj: &str, mtl: &str, files: &[(&str, Vec<u8>)]) -> Scene {
    let mut all: HashMap<PathBuf, Vec<u8>> = files
        .iter()
        .map(|(name, bytes)| (Path::new("s").join(name), bytes.clone()))
        .collect();
    let toml = format!("name = \"t\"\nobj = \"t.obj\"\n{toml_extra}");
    for (name, text) in [
        ("t.toml", toml.as_str()),
        ("t.obj", obj),
        ("lib/m.mtl", mtl),
    ] {
        all.insert(Path::new("s").join(name), text.as_bytes().to_vec());
    }
    load_scene_file_from(&all, Path::new("s/t.toml")).expect("the scene loads")
}

const MTL: &str = "newmtl mat\nKd 0.5 0.5 0.5\nmap_Kd -clamp on tex dir/check er.png\n\
                   newmtl plain\nKd 0.25 0.5 0.75\n";

fn textured(toml_extra: &str) -> Scene {
    load_with(
        toml_extra,
        OBJ,
        MTL,
        &[("lib/tex dir/check er.png", checker())],
    )
}

#[test]
fn map_kd_and_texture_coordinates_are_read() {
    let s = textured(ON);
    assert!(s.report.warnings.is_empty(), "{:?}", s.report.warnings);
    let map = s.materials[0]
        .diffuse_map
        .as_ref()
        .expect("mat is textured");
    assert_eq!(map.file, "tex dir/check er.png");
    assert_eq!(map.wrap, Wrap::Clamp);
    assert_eq!(map.rule, AlbedoRule::KdTimesTexture);
    assert_eq!((map.texture.width(), map.texture.height()), (2, 2));
    assert!(s.materials[1].diffuse_map.is_none());
    assert_eq!(s.texcoords.len(), s.mesh.triangles.len());
    // Corner (0, 0, 1) of the first triangle has vt (0, 1).
    let t0 = s.mesh.triangles[0].vertices;
    assert_eq!(s.mesh.positions[t0[1] as usize], Vec3::new(0.0, 0.0, 1.0));
    assert_eq!(s.texcoords[0][1], Vec2::new(0.0, 1.0));
    // Kd × texel, and Kd alone where there is no texture: the quad's corner near u = 0, v = 1
    // is the top-left texel, red; near (1, 0) the bottom-right one, white.
    let near = |b: [f32; 2]| s.albedo_at(0, b);
    assert!(near([0.98, 0.01]).abs_diff_eq(Vec3::new(0.5, 0.0, 0.0), 1e-6));
    assert_eq!(s.albedo_at(2, [0.3, 0.3]), Vec3::new(0.25, 0.5, 0.75));
    let texture_only = textured("[textures]\nenabled = true\nalbedo = \"texture\"\n");
    assert!(
        texture_only
            .albedo_at(0, [0.98, 0.01])
            .abs_diff_eq(Vec3::X, 1e-6)
    );
}

#[test]
fn texture_seams_split_no_vertex() {
    // The two quads meet at x = 1 with other texture coordinates on each side; materials
    // differ there, so compare one material's quad with and without its texture coordinates.
    let plain = OBJ
        .lines()
        .filter(|l| !l.starts_with("vt "))
        .map(|l| match l.strip_prefix("f ") {
            Some(corners) => {
                let positions: Vec<&str> = corners
                    .split(' ')
                    .map(|c| c.split('/').next().expect("index"))
                    .collect();
                format!("f {}", positions.join(" "))
            }
            None => l.to_owned(),
        })
        .collect::<Vec<_>>()
        .join("\n");
    let with = textured(ON);
    let without = load_with(ON, &plain, MTL, &[("lib/tex dir/check er.png", checker())]);
    assert_eq!(with.mesh.positions.len(), without.mesh.positions.len());
    assert_eq!(with.mesh.triangles, without.mesh.triangles);
    assert!(without.texcoords.is_empty());
}

#[test]
fn textures_off_read_no_texture_and_leave_the_fingerprint_as_without_them() {
    let off = textured("");
    assert!(off.materials.iter().all(|m| m.diffuse_map.is_none()));
    assert_eq!(off.texcoords.len(), off.mesh.triangles.len());
    assert!(off.report.warnings.is_empty());
    assert!(
        off.report
            .notes
            .iter()
            .any(|n| n.contains("textures are off")),
        "{:?}",
        off.report.notes
    );
    // Off, other texture bytes or texture coordinates are the same scene.
    let other = load_with(
        "",
        &OBJ.replace("vt 1 1", "vt 0.5 0.5"),
        MTL,
        &[("lib/tex dir/check er.png", png(&[[9, 9, 9]], 1, 1))],
    );
    assert_eq!(off.fingerprint, other.fingerprint);
    // On, they are not: the textures' bytes, the texture coordinates and the rule all count.
    let on = textured(ON);
    assert_ne!(on.fingerprint, off.fingerprint);
    let other_bytes = load_with(
        ON,
        OBJ,
        MTL,
        &[("lib/tex dir/check er.png", png(&[[9, 9, 9]], 1, 1))],
    );
    let other_uv = load_with(
        ON,
        &OBJ.replace("vt 1 1", "vt 0.5 0.5"),
        MTL,
        &[("lib/tex dir/check er.png", checker())],
    );
    let other_rule = textured("[textures]\nenabled = true\nalbedo = \"texture\"\n");
    let prints = [
        on.fingerprint,
        other_bytes.fingerprint,
        other_uv.fingerprint,
        other_rule.fingerprint,
    ];
    for (i, a) in prints.iter().enumerate() {
        for b in &prints[i + 1..] {
            assert_ne!(a, b);
        }
    }
}

/// An untextured scene keeps the fingerprint it had before textures existed, so ground truths
/// cached under it stay valid (values from the commit before textures).
#[test]
fn untextured_scenes_keep_their_fingerprints() {
    for (name, hex) in [
        (
            "cornell",
            "ffffe8b8cb1508d7af09586615511f32ea332ddfefe5605118249c24f0e5b0e9",
        ),
        (
            "bracara",
            "db2550dfcda115b67aa111a6c8443b93e02382dfe81181d705c7b068e6470d2a",
        ),
    ] {
        let s = load(name).expect("built in");
        assert_eq!(scene::fingerprint_hex(&s.fingerprint), hex, "{name}");
    }
}

#[test]
fn a_missing_texture_warns_once_naming_it_and_its_materials_keep_kd() {
    let mtl = "newmtl a\nKd 0.5 0.5 0.5\nmap_Kd gone.png\n\
               newmtl b\nKd 0.1 0.2 0.3\nmap_Kd gone.png\n";
    let obj = OBJ
        .replace("usemtl mat", "usemtl a")
        .replace("usemtl plain", "usemtl b");
    let s = load_with(ON, &obj, mtl, &[]);
    let warnings = &s.report.warnings;
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(
        warnings[0].contains("s/lib/gone.png") && warnings[0].contains("keep their Kd"),
        "{warnings:?}"
    );
    assert!(s.materials.iter().all(|m| m.diffuse_map.is_none()));
    assert_eq!(s.albedo_at(0, [0.2, 0.2]), Vec3::splat(0.5));
    assert_eq!(s.albedo_at(2, [0.2, 0.2]), Vec3::new(0.1, 0.2, 0.3));
}

#[test]
fn an_undecodable_texture_warns_and_falls_back() {
    let s = load_with(
        ON,
        OBJ,
        "newmtl mat\nKd 0.5 0.5 0.5\nmap_Kd bad.jpg\n",
        &[("lib/bad.jpg", b"\xff\xd8\xff not really a JPEG".to_vec())],
    );
    // One for the texture, one for the faces of `plain`, which this MTL does not define.
    assert_eq!(s.report.warnings.len(), 2, "{:?}", s.report.warnings);
    assert!(
        s.report
            .warnings
            .iter()
            .any(|w| w.contains("bad.jpg") && w.contains("cannot be decoded")),
        "{:?}",
        s.report.warnings
    );
    assert!(s.materials[0].diffuse_map.is_none());
}

#[test]
fn options_not_honoured_are_warned_about_once() {
    let mtl = "newmtl mat\nKd 1 1 1\nmap_Kd -bm 2 -s 2 2 -o 0.5 0.5 c.png\n\
               newmtl plain\nKd 1 1 1\nmap_Kd -bm 3 -imfchan r c.png\n";
    let s = load_with(ON, OBJ, mtl, &[("lib/c.png", checker())]);
    assert_eq!(
        s.report.warnings,
        [
            "map_Kd option -bm is not supported and is ignored (first met in material mat)",
            "map_Kd option -imfchan is not supported and is ignored (first met in material plain)",
        ]
    );
    let map = s.materials[0].diffuse_map.as_ref().expect("textured");
    assert_eq!(
        (map.scale, map.offset),
        (Vec2::splat(2.0), Vec2::splat(0.5))
    );
    // Both materials share one decoded texture.
    let other = s.materials[1].diffuse_map.as_ref().expect("textured");
    assert!(std::sync::Arc::ptr_eq(&map.texture, &other.texture));
}

#[test]
fn a_texture_over_the_cap_is_downscaled_with_a_note() {
    let wide = scene::texture::MAX_TEXTURE_SIDE + 4;
    let s = load_with(
        ON,
        OBJ,
        "newmtl mat\nKd 1 1 1\nmap_Kd wide.png\nnewmtl plain\nKd 1 1 1\n",
        &[(
            "lib/wide.png",
            png(&vec![[7, 7, 7]; wide as usize], wide, 1),
        )],
    );
    let map = s.materials[0].diffuse_map.as_ref().expect("textured");
    assert_eq!(map.texture.width(), scene::texture::MAX_TEXTURE_SIDE);
    assert!(
        s.report
            .notes
            .iter()
            .any(|n| n.contains("wide.png") && n.contains("downscaled")),
        "{:?}",
        s.report.notes
    );
    assert!(s.report.warnings.is_empty());
}

#[test]
fn a_black_kd_with_its_texture_alone_still_reflects() {
    let mtl = "newmtl mat\nKd 0 0 0\nmap_Kd c.png\nnewmtl plain\nKd 0 0 0\n";
    let toml = "[sun]\ndirection = [0, 1, 0]\nradiance = [1, 1, 1]\nangular_diameter_deg = 0.5\n\
                [textures]\nenabled = true\nalbedo = \"texture\"\n";
    let s = load_with(toml, OBJ, mtl, &[("lib/c.png", checker())]);
    assert!(s.effects.interreflection);
}
