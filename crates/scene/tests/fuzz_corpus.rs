//! The scene fuzz targets' corpus as a stable test: every seed, crash reproducer and local crash
//! artifact of `fuzz/` goes through the very code the targets run (`fuzz/src/scene_files.rs`), so
//! a loader that panics on one fails `cargo test` without a fuzzer. The seeds are the built-in
//! scenes (DESIGN.md §11) exported to OBJ, MTL and TOML, the OBJ cut into small pieces, and a
//! few malformed files; `cargo test -p scene --test fuzz_corpus -- --ignored` writes them again.

#[path = "../../../fuzz/src/corpus.rs"]
mod corpus;
#[path = "../../../fuzz/src/scene_files.rs"]
mod scene_files;

use std::collections::BTreeMap;
use std::fmt::Write as _;

const TARGETS: [(&str, corpus::Target); 3] = [
    ("scene_obj", scene_files::obj),
    ("scene_mtl", scene_files::mtl),
    ("scene_toml", scene_files::toml),
];

/// Faces in each piece cut from an exported OBJ, and pieces per scene: small inputs keep the
/// fuzzer fast, several pieces reach several materials.
const FACES_PER_PIECE: usize = 24;
const PIECES: usize = 5;

#[test]
fn the_scene_fuzz_corpus_loads_without_panicking() {
    corpus::replay_targets(env!("CARGO_MANIFEST_DIR"), &TARGETS, 5);
}

#[test]
#[ignore = "writes fuzz/corpus: run with --ignored after changing a built-in scene"]
fn write_seed_corpus() {
    let exported = tempfile::tempdir().expect("temp dir");
    let mut obj = Vec::new();
    let mut mtl = Vec::new();
    let mut toml = Vec::new();
    for name in scene::BUILTIN_NAMES {
        let scene = scene::load(name).expect("built-in scene");
        scene::export::write_obj_mtl_toml(&scene, exported.path()).expect("export");
        let read = |ext: &str| {
            std::fs::read_to_string(exported.path().join(format!("{name}.{ext}")))
                .expect("exported file")
        };
        for (i, piece) in obj_pieces(&read("obj")).into_iter().enumerate() {
            obj.push((format!("{name}-piece-{i}.obj"), piece.into_bytes()));
        }
        mtl.push((format!("{name}.mtl"), read("mtl").into_bytes()));
        // The TOML target's OBJ is `scene.obj`.
        let settings = read("toml").replace(&format!("\"{name}.obj\""), "\"scene.obj\"");
        toml.push((format!("{name}.toml"), settings.into_bytes()));
    }
    let malformed = |cases: &[(&str, &str)]| -> Vec<(String, Vec<u8>)> {
        cases
            .iter()
            .map(|(name, text)| (format!("malformed-{name}"), text.as_bytes().to_vec()))
            .collect()
    };
    obj.extend(malformed(&[
        ("nan-vertex.obj", "v 0 0 0\nv nan 1 0\nv 0 1 0\nf 1 2 3\n"),
        (
            "index-out-of-range.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
        ),
        ("two-corners.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n"),
    ]));
    let valid = [
        (
            "relative-indices.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n",
        ),
        (
            "texcoord-and-normal.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3//1\n",
        ),
        (
            "weighted-vertex.obj",
            "v 0 0 0 2\nv 1 0 0 1\nv 0 1 0\nf 1 2 3\n",
        ),
    ];
    obj.extend(valid.map(|(name, text)| (name.to_owned(), text.as_bytes().to_vec())));
    mtl.extend(malformed(&[
        ("one-number-colour.mtl", "newmtl white\nKd 0.5\n"),
        ("negative-colour.mtl", "newmtl light\nKe 1 -1 1\n"),
        ("illum-word.mtl", "newmtl marble\nillum x\n"),
        ("unnamed.mtl", "newmtl\nKd 1 1 1\n"),
    ]));
    toml.extend(malformed(&[
        ("unknown-field.toml", "name = \"t\"\nobj = \"scene.obj\"\ncolour = 1\n"),
        ("zero-sun.toml", "name = \"t\"\nobj = \"scene.obj\"\n[sun]\ndirection = [0, 0, 0]\nradiance = [1, 1, 1]\nangular_diameter_deg = 0.5\n"),
        ("no-obj.toml", "name = \"t\"\n"),
        ("other-obj.toml", "name = \"t\"\nobj = \"../elsewhere.obj\"\n"),
        ("viewpoint-up-along-view.toml", "name = \"t\"\nobj = \"scene.obj\"\n[[viewpoint]]\nname = \"v\"\neye = [0, 0, 0]\ntarget = [0, 1, 0]\n"),
    ]));
    let dir = corpus::fuzz_dir(env!("CARGO_MANIFEST_DIR"));
    corpus::write_seeds(&dir, "scene_obj", &obj);
    corpus::write_seeds(&dir, "scene_mtl", &mtl);
    corpus::write_seeds(&dir, "scene_toml", &toml);
}

/// Up to `PIECES` runs of `FACES_PER_PIECE` faces, spread over the file, each a valid OBJ on its
/// own: the `mtllib`, the vertices its faces use (renumbered from 1) and its `usemtl` lines.
fn obj_pieces(text: &str) -> Vec<String> {
    let mut header = String::new();
    let mut positions = Vec::new();
    let mut faces = Vec::new();
    let mut material = String::new();
    for line in text.lines() {
        match line.split_whitespace().next() {
            Some("mtllib") => writeln!(header, "{line}").expect("write to a string"),
            Some("v") => positions.push(line),
            Some("usemtl") => material = line.to_owned(),
            Some("f") => faces.push((material.clone(), line)),
            _ => {}
        }
    }
    let step = (faces.len() / PIECES).max(FACES_PER_PIECE);
    faces
        .chunks(step)
        .map(|chunk| {
            let chunk = &chunk[..chunk.len().min(FACES_PER_PIECE)];
            let mut renumbered: BTreeMap<usize, usize> = BTreeMap::new();
            let mut vertices = String::new();
            let mut body = String::new();
            let mut current = "";
            for (material, face) in chunk {
                if material != current {
                    writeln!(body, "{material}").expect("write to a string");
                    current = material;
                }
                body.push('f');
                for corner in face.split_whitespace().skip(1) {
                    let old: usize = corner.parse().expect("exported faces are plain indices");
                    let next = renumbered.len() + 1;
                    let new = *renumbered.entry(old).or_insert_with(|| {
                        writeln!(vertices, "{}", positions[old - 1]).expect("write to a string");
                        next
                    });
                    write!(body, " {new}").expect("write to a string");
                }
                body.push('\n');
            }
            format!("{header}{vertices}{body}")
        })
        .collect()
}
