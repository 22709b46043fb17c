mod evict;

use std::collections::BTreeMap;

use protocol::renderer_link::{Quality, SampleKey};
use protocol::{PartEstimate, SampleParts, Side};
use redb::{Database, TableDefinition};

use super::*;
use crate::cache::CachedSample;
use crate::mesh::MeshParams;
use crate::mesh::test_meshes::grid;

fn key() -> StoreKey {
    StoreKey::of_test_scene(3)
}

fn fresh() -> (SubdivisionMesh, ShadingCache) {
    (
        SubdivisionMesh::new(&grid(6), MeshParams::default()),
        ShadingCache::new(1 << 30),
    )
}

/// Refines a few leaves three levels deep, so the subtrees cross base triangles (greens).
fn refine(mesh: &mut SubdivisionMesh, picks: &[usize]) {
    for &pick in picks {
        let leaves: Vec<_> = mesh.leaves().collect();
        mesh.refine(&[leaves[pick % leaves.len()]], &|_| false);
    }
}

/// A sample for every vertex of every leaf, front side, and back where the vertex id is odd;
/// its value and paths say which vertex it is.
fn shade(mesh: &SubdivisionMesh, cache: &mut ShadingCache) {
    let leaves: Vec<_> = mesh.leaves().collect();
    for leaf in leaves {
        for vertex in mesh.node(leaf).vertices {
            let p = mesh.vertex(vertex).position;
            let sides: &[Side] = if vertex % 2 == 1 {
                &[Side::Front, Side::Back]
            } else {
                &[Side::Front]
            };
            for &side in sides {
                let key = SampleKey { vertex, side };
                if cache.get(key).is_none() {
                    cache.insert(key, sample(p.x + 10.0 * p.y, 16 + vertex % 7));
                }
            }
        }
    }
}

fn sample(value: f32, paths: u32) -> CachedSample {
    CachedSample {
        // Every part, so a round trip shows that none is lost nor merged into another.
        parts: SampleParts {
            direct: PartEstimate {
                rgb: [value, 0.5 * value, 1.0],
                luminance_variance: 0.25,
            },
            indirect: PartEstimate {
                rgb: [0.1 * value, 0.2, 0.3],
                luminance_variance: 0.05,
            },
            view_dependent: PartEstimate {
                rgb: [0.4, 0.01 * value, 0.6],
                luminance_variance: 0.125,
            },
        },
        quality: Quality {
            paths,
            bounces: Some(2),
        },
        view_dependent: false,
        eye: None,
        last_seen: 0,
    }
}

/// The leaves as their corner positions, each with its corners' samples (front, back): what a
/// viewer would be shown, independent of node and vertex ids.
type Shown = BTreeMap<Vec<[u32; 3]>, Vec<Option<([[u32; 3]; 2], u32)>>>;

fn shown(mesh: &SubdivisionMesh, cache: &ShadingCache) -> Shown {
    mesh.leaves()
        .map(|leaf| {
            let vertices = mesh.node(leaf).vertices;
            let corners = vertices
                .iter()
                .map(|&v| mesh.vertex(v).position.to_array().map(f32::to_bits))
                .collect();
            let samples = vertices
                .iter()
                .flat_map(|&vertex| [Side::Front, Side::Back].map(|side| (vertex, side)))
                .map(|(vertex, side)| {
                    cache.get(SampleKey { vertex, side }).map(|s| {
                        let bits = |p: PartEstimate| p.rgb.map(f32::to_bits);
                        let parts = [bits(s.parts.direct), bits(s.parts.indirect)];
                        (parts, s.quality.paths)
                    })
                })
                .collect();
            (corners, samples)
        })
        .collect()
}

/// Where a test's file is, and how often it is saved.
struct Config {
    path: PathBuf,
    save_every: Duration,
}

fn config(dir: &tempfile::TempDir) -> Config {
    Config {
        path: dir.path().join("site.redb"),
        save_every: CacheFileConfig::SAVE_EVERY,
    }
}

/// Opens the file and loads every record, as a camera that sees the whole site would.
fn open_all(
    config: &Config,
    key: &StoreKey,
    mesh: &mut SubdivisionMesh,
    cache: &mut ShadingCache,
) -> Option<CacheFile> {
    let mut file = CacheFile::open(&config.path, config.save_every, key, mesh)?;
    file.load_all(mesh, cache);
    Some(file)
}

/// Saves a refined and shaded mesh, closes the file, and returns what it showed.
fn save_one(config: &Config) -> Shown {
    let (mut mesh, mut cache) = fresh();
    let mut file = open_all(config, &key(), &mut mesh, &mut cache).expect("opens");
    assert_eq!(file.restored().bases, 0, "a new file holds nothing");
    refine(&mut mesh, &[5, 17, 17, 40, 3, 90, 91]);
    shade(&mesh, &mut cache);
    file.samples_changed(0..mesh.vertex_count() as u32);
    let before = shown(&mesh, &cache);
    file.close(&mut mesh, &cache);
    before
}

#[test]
fn a_saved_mesh_and_its_samples_come_back_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    let before = save_one(&config);
    let (mut mesh, mut cache) = fresh();
    let file = open_all(&config, &key(), &mut mesh, &mut cache).expect("opens");
    assert!(file.restored().bases > 0);
    assert_eq!(file.restored().unmatched_vertices, 0);
    assert_eq!(shown(&mesh, &cache), before);
    assert!(!file_refused(&config));
}

#[test]
fn a_dropped_file_keeps_its_last_commit() {
    // Dropped without `close`, as a killed SMA would leave it: what was saved comes back.
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    let (mut mesh, mut cache) = fresh();
    let mut file = open_all(&config, &key(), &mut mesh, &mut cache).unwrap();
    refine(&mut mesh, &[1, 2, 30]);
    shade(&mesh, &mut cache);
    file.samples_changed(0..mesh.vertex_count() as u32);
    file.save_now(&mut mesh, &cache);
    let saved = shown(&mesh, &cache);
    refine(&mut mesh, &[7]);
    drop(file);
    let (mut mesh, mut cache) = fresh();
    let _file = open_all(&config, &key(), &mut mesh, &mut cache).unwrap();
    assert_eq!(shown(&mesh, &cache), saved);
}

#[test]
fn a_save_rewrites_only_the_base_triangles_that_changed() {
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    let (mut mesh, mut cache) = fresh();
    let mut file = open_all(&config, &key(), &mut mesh, &mut cache).unwrap();
    refine(&mut mesh, &[4, 50, 51, 52]);
    shade(&mesh, &mut cache);
    file.save_now(&mut mesh, &cache);
    let first = file.writer_stats().records;
    assert!(first > 4);
    file.save_now(&mut mesh, &cache);
    assert_eq!(
        file.writer_stats().records,
        first,
        "nothing changed, nothing written"
    );
    // One new sample: one record.
    let vertex = mesh.node(mesh.leaves().next().unwrap()).vertices[0];
    let key = SampleKey {
        vertex,
        side: Side::Back,
    };
    cache.insert(key, sample(1.0, 8));
    file.samples_changed([vertex]);
    file.save_now(&mut mesh, &cache);
    assert_eq!(file.writer_stats().records, first + 1);
}

fn file_refused(config: &Config) -> bool {
    store::rejected_path(&config.path).exists()
}

/// Opens a fresh SMA's mesh and cache on a file that must be refused: it is renamed, and the
/// SMA starts empty with a new file that works.
fn assert_refused(config: &Config) {
    let (mut mesh, mut cache) = fresh();
    let leaves = mesh.leaf_count();
    let file = open_all(config, &key(), &mut mesh, &mut cache).expect("a fresh file");
    assert!(file_refused(config), "renamed to .rejected");
    assert_eq!(mesh.leaf_count(), leaves);
    assert!(cache.is_empty());
    refine(&mut mesh, &[3]);
    file.close(&mut mesh, &cache);
    let (mut mesh, mut cache) = fresh();
    open_all(config, &key(), &mut mesh, &mut cache).unwrap();
    assert!(mesh.leaf_count() > leaves, "the new file works");
}

#[test]
fn a_truncated_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    save_one(&config);
    let len = std::fs::metadata(&config.path).unwrap().len();
    let file = std::fs::OpenOptions::new()
        .write(true)
        .open(&config.path)
        .unwrap();
    file.set_len(len / 2).unwrap();
    assert_refused(&config);
}

#[test]
fn a_file_with_bytes_overwritten_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    save_one(&config);
    let mut bytes = std::fs::read(&config.path).unwrap();
    let n = bytes.len();
    bytes[4096..n].fill(0xA5);
    std::fs::write(&config.path, bytes).unwrap();
    assert_refused(&config);
}

#[test]
fn a_file_of_another_scene_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    save_one(&config);
    let mut other = key();
    other.scene[0] ^= 1;
    let (mut mesh, mut cache) = fresh();
    open_all(&config, &other, &mut mesh, &mut cache).expect("a fresh file");
    assert!(file_refused(&config));
    assert!(cache.is_empty());
}

#[test]
fn a_file_of_another_format_version_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    save_one(&config);
    {
        const META: TableDefinition<&str, &[u8]> = TableDefinition::new("meta");
        let db = Database::create(&config.path).unwrap();
        let txn = db.begin_write().unwrap();
        txn.open_table(META)
            .unwrap()
            .insert("format", (FORMAT_VERSION + 1).to_le_bytes().as_slice())
            .unwrap();
        txn.commit().unwrap();
    }
    assert_refused(&config);
}

#[test]
fn a_file_another_handle_holds_is_left_alone_and_the_sma_carries_on() {
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    save_one(&config);
    let _other_sma = Database::create(&config.path).unwrap();
    let (mut mesh, mut cache) = fresh();
    assert!(open_all(&config, &key(), &mut mesh, &mut cache).is_none());
    assert!(!file_refused(&config), "a locked file is not refused");
    assert!(cache.is_empty());
}

#[test]
fn an_unwritable_directory_leaves_the_sma_without_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let not_a_dir = dir.path().join("plain");
    std::fs::write(&not_a_dir, b"x").unwrap();
    let config = Config {
        path: not_a_dir.join("site.redb"),
        save_every: CacheFileConfig::SAVE_EVERY,
    };
    let (mut mesh, mut cache) = fresh();
    assert!(open_all(&config, &key(), &mut mesh, &mut cache).is_none());
}

#[test]
fn periodic_saves_pause_for_a_slice_at_most_and_catch_up() {
    let dir = tempfile::tempdir().unwrap();
    let config = Config {
        save_every: Duration::ZERO,
        ..config(&dir)
    };
    let (mut mesh, mut cache) = fresh();
    let mut file = open_all(&config, &key(), &mut mesh, &mut cache).unwrap();
    refine(&mut mesh, &[1, 2, 3, 60, 61]);
    shade(&mesh, &mut cache);
    let saved = shown(&mesh, &cache);
    for _ in 0..100 {
        file.save_if_due(&mut mesh, &cache);
    }
    assert!(file.pauses().count >= 1);
    file.writer.commit_and_wait(Vec::new());
    drop(file);
    let (mut mesh, mut cache) = fresh();
    open_all(&config, &key(), &mut mesh, &mut cache).unwrap();
    let restored = shown(&mesh, &cache);
    assert_eq!(
        restored.keys().collect::<Vec<_>>(),
        saved.keys().collect::<Vec<_>>()
    );
}

#[test]
fn new_samples_between_periodic_saves_wait_for_the_period() {
    let dir = tempfile::tempdir().unwrap();
    let config = Config {
        save_every: Duration::from_secs(3600),
        ..config(&dir)
    };
    let (mut mesh, mut cache) = fresh();
    let mut file = open_all(&config, &key(), &mut mesh, &mut cache).unwrap();
    refine(&mut mesh, &[1, 2, 3]);
    shade(&mesh, &mut cache);
    file.samples_changed(0..mesh.vertex_count() as VertexId);
    for _ in 0..10 {
        file.save_if_due(&mut mesh, &cache);
    }
    assert_eq!(file.pauses().count, 0, "no save before the period is over");
    assert!(file.save_due_at() > Instant::now() + Duration::from_secs(3000));
    file.save_now(&mut mesh, &cache);
    assert_eq!(file.writer_stats().commits, 1);
}

#[test]
fn a_per_scene_file_is_named_by_scene_and_fingerprint() {
    let config = CacheFileConfig {
        location: Location::PerScene(PathBuf::from("/cache/walkthrough")),
        save_every: CacheFileConfig::SAVE_EVERY,
    };
    let path = config.path("my scene/../x", &[0xab; 32]);
    assert_eq!(
        path,
        PathBuf::from("/cache/walkthrough/my_scene____x-abababababab.redb")
    );
    assert_eq!(
        CacheFileConfig::at("/a.redb").path("s", &[0; 32]),
        PathBuf::from("/a.redb")
    );
}

/// The base triangles whose centroid is in the square [lo, hi)² of the 6×6 grid.
fn bases_in(mesh: &SubdivisionMesh, lo: f32, hi: f32) -> Vec<u32> {
    (0..mesh.base_count() as u32)
        .filter(|&b| {
            let c = mesh.leaf_positions(b).iter().sum::<glam::Vec3>() / 3.0;
            (lo..hi).contains(&c.x) && (lo..hi).contains(&c.y)
        })
        .collect()
}

/// Refines, three levels deep, the leaves of the base triangles in [lo, hi)².
fn refine_area(mesh: &mut SubdivisionMesh, lo: f32, hi: f32) {
    for _ in 0..3 {
        let leaves: Vec<_> = bases_in(mesh, lo, hi)
            .into_iter()
            .flat_map(|b| mesh.leaves_of_base(b))
            .collect();
        mesh.refine(&leaves, &|_| false);
    }
}

#[test]
fn a_camera_on_one_area_loads_only_its_records_and_the_others_stay_in_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    let (mut mesh, mut cache) = fresh();
    let mut file = CacheFile::open(&config.path, config.save_every, &key(), &mesh).unwrap();
    refine_area(&mut mesh, 0.0, 1.5);
    refine_area(&mut mesh, 4.5, 6.0);
    shade(&mesh, &mut cache);
    file.samples_changed(0..mesh.vertex_count() as u32);
    let saved = shown(&mesh, &cache);
    file.close(&mut mesh, &cache);

    // Opening reads no record; a camera on the first area loads only its base triangles'.
    let (mut mesh, mut cache) = fresh();
    let mut file = CacheFile::open(&config.path, config.save_every, &key(), &mesh).unwrap();
    let stored = file.unloaded_count;
    assert_eq!(file.restored().bases, 0);
    let near = bases_in(&mesh, 0.0, 1.5);
    let far = bases_in(&mesh, 4.5, 6.0);
    let steps = file.load(near.iter().copied(), &mut mesh, &mut cache);
    assert!(!steps.is_empty(), "the loaded leaves come as steps");
    assert_eq!(
        file.restored().bases,
        near.len(),
        "one record per base of the area"
    );
    assert!(stored >= near.len() + far.len());
    assert!(
        far.iter().all(|&b| mesh.leaves_of_base(b).len() == 1),
        "the far area is not loaded"
    );
    assert!(near.iter().all(|&b| mesh.leaves_of_base(b).len() > 1));
    assert_eq!(
        file.load(near.iter().copied(), &mut mesh, &mut cache),
        Vec::new()
    );

    // Work in the near area is saved; the far area's records, never loaded, stay as they were,
    // though samples of its vertices changed meanwhile.
    refine(&mut mesh, &[0]);
    shade(&mesh, &mut cache);
    file.samples_changed(0..mesh.vertex_count() as u32);
    file.close(&mut mesh, &cache);
    let (mut mesh, mut cache) = fresh();
    let _file = open_all(&config, &key(), &mut mesh, &mut cache).unwrap();
    let far_leaves = |shown: &Shown| {
        shown
            .iter()
            .filter(|(corners, _)| corners.iter().all(|c| f32::from_bits(c[0]) >= 4.5))
            .map(|(c, s)| (c.clone(), s.clone()))
            .collect::<Vec<_>>()
    };
    let after = shown(&mesh, &cache);
    assert!(!far_leaves(&saved).is_empty());
    assert_eq!(far_leaves(&after), far_leaves(&saved));
}

#[test]
fn a_record_that_does_not_decode_is_left_out_and_the_others_load() {
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    save_one(&config);
    {
        const BASES: TableDefinition<u32, &[u8]> = TableDefinition::new("bases");
        let db = Database::create(&config.path).unwrap();
        let txn = db.begin_write().unwrap();
        txn.open_table(BASES)
            .unwrap()
            .insert(0, [0xFF_u8; 3].as_slice())
            .unwrap();
        txn.commit().unwrap();
    }
    let (mut mesh, mut cache) = fresh();
    let file = open_all(&config, &key(), &mut mesh, &mut cache).expect("opens");
    assert!(
        !file_refused(&config),
        "one bad record does not refuse the file"
    );
    assert!(file.warned_unreadable);
    assert!(file.restored().bases > 0);
    assert!(!cache.is_empty());
}

/// A view that had converged comes back converged (DESIGN.md §5, persistence): restored into
/// an SMA that judges radiance, each vertex's albedo times its illumination ("Parts, and
/// textures"), a subtree of uniform light on a coloured wall, whose samples had settled and
/// which the criterion left alone before the save, is left alone after the load too: the
/// restored midpoints are judged with their material's albedo, like the corners beside them,
/// not split again on arrival.
#[test]
fn a_restored_converged_subtree_is_not_split_again_on_arrival() {
    use std::sync::Arc;

    use crate::criteria::{Criterion, CriterionInput, CriterionSettings, NldPx};
    use crate::mesh::NodeId;
    use crate::visible_set::{VisibleLeaf, VisibleSet};

    let scene = Arc::new(scene::load("cornell").expect("built-in"));
    // As the schedule makes them: every vertex of the base mesh has its albedo from the start.
    let sma = || {
        let mesh = SubdivisionMesh::new(&scene.mesh, MeshParams::default());
        let mut cache = ShadingCache::new(1 << 30).with_albedos_of(Arc::clone(&scene));
        cache.cover_albedos(&mesh);
        (mesh, cache)
    };
    let dir = tempfile::tempdir().unwrap();
    let config = config(&dir);
    let (mut mesh, mut cache) = sma();
    let mut file = CacheFile::open(&config.path, config.save_every, &key(), &mesh).unwrap();
    let coloured = (0..mesh.base_count() as NodeId)
        .find(|&t| scene.material_of(t as usize).kd.max_element() < 0.9)
        .expect("a wall of albedo below 0.9");
    // Two levels of splits, their greens across the neighbours.
    mesh.refine(&[coloured], &|_| false);
    let children = mesh.leaves_of_base(coloured);
    mesh.refine(&children[..1], &|_| false);
    // Answers cover the new vertices' albedos before their samples arrive.
    cache.cover_albedos(&mesh);
    let leaves: Vec<NodeId> = mesh.leaves().collect();
    for &leaf in &leaves {
        for vertex in mesh.node(leaf).vertices {
            let key = SampleKey {
                vertex,
                side: Side::Front,
            };
            let settled = CachedSample {
                parts: SampleParts::direct_only([0.6; 3], 0.0),
                quality: Quality {
                    paths: 64,
                    bounces: Some(2),
                },
                view_dependent: false,
                eye: None,
                last_seen: 0,
            };
            cache.insert(key, settled);
        }
    }
    // The coloured base's leaves on a large image: small, none large by §4.3.5.
    let view = |mesh: &SubdivisionMesh| VisibleSet {
        leaves: mesh
            .leaves_of_base(coloured)
            .into_iter()
            .map(|leaf| VisibleLeaf {
                leaf,
                side: Side::Front,
                pixels: 40,
            })
            .collect(),
        width: 1024,
        height: 768,
    };
    let selected = |mesh: &SubdivisionMesh, cache: &ShadingCache| {
        let visible = view(mesh);
        assert!(visible.leaves.len() >= 7, "the subtree is visible");
        let input = CriterionInput {
            mesh,
            cache,
            visible: &visible,
            l_white: cache.l_white(mesh, &visible),
            image: None,
        };
        NldPx::new(&CriterionSettings::default()).select(&input, 64)
    };
    assert_eq!(
        selected(&mesh, &cache),
        Vec::new(),
        "converged before the save"
    );

    let saved_leaves = mesh.leaves_of_base(coloured).len();
    file.samples_changed(0..mesh.vertex_count() as u32);
    file.close(&mut mesh, &cache);

    let (mut mesh, mut cache) = sma();
    let mut file = CacheFile::open(&config.path, config.save_every, &key(), &mesh).unwrap();
    file.load([coloured], &mut mesh, &mut cache);
    assert_eq!(file.restored().unmatched_vertices, 0);
    assert_eq!(mesh.leaves_of_base(coloured).len(), saved_leaves);
    assert_eq!(
        selected(&mesh, &cache),
        Vec::new(),
        "converged after the load"
    );
}
