//! A corpus of broken scene files (OBJ, MTL, TOML), each with the exact error it must give, and
//! a property test that no corruption of a valid scene makes the loader panic.

use std::path::Path;

use proptest::prelude::*;
use scene::{SceneError, load};

const TOML: &str = "name = \"t\"\nobj = \"t.obj\"\n";
const MTL: &str = "newmtl white\nKd 0.8 0.8 0.8\nillum 1\nnewmtl lamp\nKd 0.5 0.5 0.5\nKe 4 4 4\n";
const OBJ: &str = "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl white\nf 1 2 3\nusemtl lamp\nf 1 3 4\n";

/// Writes the three files into a fresh directory (None = leave that file out) and loads the TOML.
fn load_files(
    toml: &str,
    obj: Option<&str>,
    mtl: Option<&str>,
) -> (Result<scene::Scene, SceneError>, tempfile::TempDir) {
    let dir = tempfile::tempdir().expect("temp dir");
    let write = |name: &str, text: Option<&str>| {
        if let Some(text) = text {
            std::fs::write(dir.path().join(name), text).expect("write corpus file");
        }
    };
    write("t.toml", Some(toml));
    write("t.obj", obj);
    write("t.mtl", mtl);
    let path = dir.path().join("t.toml");
    (load(path.to_str().expect("utf-8 path")), dir)
}

/// The error message with the temporary directory taken out.
fn error_of(toml: &str, obj: Option<&str>, mtl: Option<&str>) -> String {
    let (result, dir) = load_files(toml, obj, mtl);
    let e = result.expect_err("the corpus file must be rejected");
    e.to_string()
        .replace(&format!("{}/", dir.path().display()), "")
}

#[test]
fn the_valid_base_scene_loads() {
    let (s, _dir) = load_files(TOML, Some(OBJ), Some(MTL));
    let s = s.expect("valid");
    assert_eq!(s.mesh.triangles.len(), 2);
    assert!(s.effects.area_lights);
    assert!(s.report.warnings.is_empty());
}

#[test]
fn broken_obj_files_name_file_and_line() {
    let cases = [
        (
            "v 0 0 0\nv nan 1 0\nv 0 1 0\nf 1 2 3\n",
            "t.obj:2: non-finite number (NaN or infinity)",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 inf 0\nf 1 2 3\n",
            "t.obj:3: non-finite number (NaN or infinity)",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1e39 0\nf 1 2 3\n",
            "t.obj:3: non-finite number (NaN or infinity)",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
            "t.obj:4: vertex index 4 out of range (3 defined before this line)",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
            "t.obj:4: vertex index 0 out of range (3 defined before this line)",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -5\n",
            "t.obj:4: vertex index -5 out of range (3 defined before this line)",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2/1 3/1\n",
            "t.obj:4: texcoord index 1 out of range (0 defined before this line)",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n",
            "t.obj:4: needs at least 3 corners, found 2",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3x\n",
            "t.obj:4: '3x' is not a vertex index",
        ),
        ("v 0 0\n", "t.obj:1: expected 3 numbers, found 2"),
        ("v 0 zero 0\n", "t.obj:1: 'zero' is not a number"),
        ("v 1 2 3 0\n", "t.obj:1: vertex weight w is zero"),
        ("vn 0 1\n", "t.obj:1: expected 3 numbers, found 2"),
        ("usemtl\n", "t.obj:1: usemtl needs a name"),
        (
            "# no faces at all\nv 0 0 0\n",
            "the scene has no triangles left after validation",
        ),
        (
            "v 0 0 0\nv 1 1 1\nv 2 2 2\nf 1 2 3\n",
            "the scene has no triangles left after validation",
        ),
    ];
    for (obj, expected) in cases {
        assert_eq!(error_of(TOML, Some(obj), None), expected, "for OBJ {obj:?}");
    }
}

#[test]
fn broken_mtl_files_name_file_and_line() {
    let cases = [
        // tobj 4.0.5 itself would panic on this one.
        (
            "newmtl white\nKd 0.5\n",
            "t.mtl:2: expected 3 numbers, found 1",
        ),
        (
            "newmtl white\nKe 1 nan 1\n",
            "t.mtl:2: non-finite number (NaN or infinity)",
        ),
        (
            "newmtl white\nKd 0.5 -0.5 0.5\n",
            "t.mtl:2: negative colour",
        ),
        ("newmtl white\nNs\n", "t.mtl:2: expected 1 numbers, found 0"),
        (
            "newmtl white\nillum three\n",
            "t.mtl:2: illum needs an integer 0-255",
        ),
        ("newmtl\n", "t.mtl:1: newmtl needs a name"),
        ("newmtl white\nmap_Kd\n", "t.mtl:2: map_Kd needs a name"),
        (
            "newmtl white\nmap_Kd -s x t.png\n",
            "t.mtl:2: map_Kd option -s needs at least 1 number",
        ),
    ];
    for (mtl, expected) in cases {
        assert_eq!(
            error_of(TOML, Some(OBJ), Some(mtl)),
            expected,
            "for MTL {mtl:?}"
        );
    }
}

#[test]
fn broken_scene_files_are_errors() {
    let sun = "[sun]\ndirection = [0, 0, 0]\nradiance = [1, 1, 1]\nangular_diameter_deg = 0.5\n";
    let view = "[[viewpoint]]\nname = \"v\"\neye = [0, 1, 0]\ntarget = [0, 1, 0]\n";
    let cases: [(String, &str); 7] = [
        (
            "name = \"t\"\n".into(),
            "t.toml: the scene file names no OBJ (`obj = \"...\"`)",
        ),
        (
            format!("{TOML}{sun}"),
            "invalid scene settings: sun direction [0.0, 0.0, 0.0] is not a usable direction",
        ),
        (
            format!("{TOML}{view}"),
            "invalid scene settings: viewpoint v: eye equals target, or up is parallel to the view",
        ),
        (
            format!("{TOML}crease_angle_deg = 200\n"),
            "invalid scene settings: crease_angle_deg 200 is not within 0..=180",
        ),
        (
            format!("{TOML}[sky]\nkind = \"uniform\"\nradiance = [1, -1, 1]\n"),
            "invalid scene settings: sky radiance [1.0, -1.0, 1.0] must be finite and non-negative",
        ),
        (
            "name = \"t\"\nobj = \"elsewhere.obj\"\n".into(),
            "elsewhere.obj: No such file or directory (os error 2)",
        ),
        (
            format!("{TOML}[quality]\npaths = 0\n"),
            "invalid scene settings: quality.paths must be at least 1",
        ),
    ];
    for (toml, expected) in &cases {
        assert_eq!(
            error_of(toml, Some(OBJ), Some(MTL)),
            *expected,
            "for TOML {toml:?}"
        );
    }
    // TOML syntax and schema errors carry the toml crate's message, which names line and column.
    for toml in [
        "name = \n",
        "name = \"t\"\nobj = \"t.obj\"\ncolour = 3\n",
        "obj = \"t.obj\"\n",
    ] {
        let e = error_of(toml, Some(OBJ), Some(MTL));
        assert!(e.starts_with("t.toml: TOML parse error at line"), "{e}");
    }
}

#[test]
fn unknown_names_and_missing_files_are_errors() {
    assert!(matches!(load("atlantis"), Err(SceneError::UnknownScene(name)) if name == "atlantis"));
    assert!(
        matches!(load("no/such/scene.toml"), Err(SceneError::Io { path, .. }) if path == Path::new("no/such/scene.toml"))
    );
}

#[test]
fn a_missing_mtl_gives_the_default_material_and_a_warning() {
    let (s, _dir) = load_files(TOML, Some(OBJ), None);
    let s = s.expect("loads without its MTL");
    assert_eq!(s.materials.len(), 1);
    assert_eq!(s.materials[0].name, "default");
    assert_eq!(s.report.warnings.len(), 2, "{:?}", s.report.warnings);
    assert!(
        s.report.warnings[0].contains("t.mtl")
            && s.report.warnings[1].starts_with("2 faces have no known material")
    );
    assert!(!s.effects.area_lights, "the lamp is gone with its MTL");
}

#[test]
fn zero_area_triangles_are_dropped_and_counted() {
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 3 3 1\n";
    let (s, _dir) = load_files(TOML, Some(obj), None);
    let s = s.expect("loads");
    assert_eq!(s.report.dropped_triangles, 2);
    assert_eq!(s.mesh.triangles.len(), 1);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// Overwrite, insert or delete bytes anywhere in the OBJ, MTL or TOML: loading returns
    /// a scene or an error, and never panics.
    #[test]
    fn corrupt_files_never_panic(
        which in 0usize..3,
        edits in prop::collection::vec((any::<prop::sample::Index>(), 0u8..3, prop::sample::select(b" \n/-.0159aefvnlKdsmtu#\x00\xff".to_vec())), 1..6),
    ) {
        let mut files = [TOML.as_bytes().to_vec(), OBJ.as_bytes().to_vec(), MTL.as_bytes().to_vec()];
        let f = &mut files[which];
        for (at, op, byte) in edits {
            let i = at.index(f.len() + 1);
            match op {
                0 if i < f.len() => f[i] = byte,
                1 => f.insert(i, byte),
                _ if i < f.len() => { f.remove(i); }
                _ => {}
            }
        }
        let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
        let (result, _dir) = load_files(&text(&files[0]), Some(&text(&files[1])), Some(&text(&files[2])));
        drop(result);
    }
}
