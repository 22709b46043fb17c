//! The SMA's cache file (DESIGN.md §5, persistence) for BENCHMARKS.md: saving a 1 M-leaf mesh
//! with its samples (writer time, target <= 1 s), loading it (<= 1 s), what an incremental save
//! writes after refining one view, and the pause a periodic save costs the schedule's thread
//! (target <= 20 ms). The mesh is a flat grid refined uniformly, every vertex shaded: the
//! record layout's worst case for size (every base triangle changed, every vertex sampled).

use std::fmt::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use protocol::renderer_link::{Quality, SampleKey};
use protocol::{PartEstimate, SampleParts, Side};
use sma::cache::{CachedSample, ShadingCache};
use sma::cache_file::{CacheFile, StoreKey, encoded_records, restore_encoded};
use sma::mesh::{MeshParams, SubdivisionMesh, grid_mesh};

use super::stats::median;

mod monolithic;

/// 2 × 45² base triangles, split red four levels deep: 4,050 × 256 = 1,036,800 leaves.
const GRID: u32 = 45;
const LEVELS: usize = 4;
/// The quick run: one level less (259,200 leaves).
const QUICK_LEVELS: usize = 3;

fn key() -> StoreKey {
    StoreKey::of_test_scene(90)
}

fn fresh() -> (SubdivisionMesh, ShadingCache) {
    (
        SubdivisionMesh::new(&grid_mesh(GRID), MeshParams::default()),
        ShadingCache::new(usize::MAX),
    )
}

/// Splits every leaf red, `levels` times.
fn refine_uniformly(mesh: &mut SubdivisionMesh, levels: usize) {
    for _ in 0..levels {
        let leaves: Vec<_> = mesh.leaves().collect();
        mesh.refine(&leaves, &|_| false);
    }
}

/// Refines the leaves within `radius` of `centre` once more: "one view" of a walk.
fn refine_one_view(mesh: &mut SubdivisionMesh, centre: glam::Vec3, radius: f32) {
    let near: Vec<_> = mesh
        .leaves()
        .filter(|&l| mesh.leaf_positions(l)[0].distance(centre) < radius)
        .collect();
    mesh.refine(&near, &|_| false);
}

/// A front sample for every vertex of every leaf that has none; returns the vertices shaded.
fn shade(mesh: &SubdivisionMesh, cache: &mut ShadingCache) -> Vec<u32> {
    let mut shaded = Vec::new();
    let leaves: Vec<_> = mesh.leaves().collect();
    for leaf in leaves {
        for vertex in mesh.node(leaf).vertices {
            let key = SampleKey {
                vertex,
                side: Side::Front,
            };
            if cache.get(key).is_some() {
                continue;
            }
            let p = mesh.vertex(vertex).position;
            cache.insert(
                key,
                CachedSample {
                    parts: SampleParts {
                        direct: PartEstimate {
                            rgb: [p.x * 0.01, p.y * 0.01, 0.5],
                            luminance_variance: 0.01,
                        },
                        indirect: PartEstimate {
                            rgb: [0.1, 0.1, p.z * 0.01],
                            luminance_variance: 0.01,
                        },
                        view_dependent: PartEstimate::default(),
                    },
                    quality: Quality {
                        paths: 64,
                        bounces: Some(2),
                    },
                    view_dependent: false,
                    eye: None,
                    last_seen: 0,
                },
            );
            shaded.push(vertex);
        }
    }
    shaded
}

/// Opens the file and loads every record: a camera that sees the whole site.
fn open(
    path: &Path,
    mesh: &mut SubdivisionMesh,
    cache: &mut ShadingCache,
) -> anyhow::Result<CacheFile> {
    let mut file =
        CacheFile::open(path, Duration::from_secs(3600), &key(), mesh).ok_or_else(|| {
            anyhow::anyhow!("the cache file at {} could not be opened", path.display())
        })?;
    file.load_all(mesh, cache);
    Ok(file)
}

/// One save of the whole refined mesh, one load of it, and one incremental save.
struct Trial {
    leaves: usize,
    samples: usize,
    snapshot_s: f64,
    writer_s: f64,
    save_wall_s: f64,
    full_bytes: u64,
    file_bytes: u64,
    load_s: f64,
    /// Of the load: opening (integrity check, the list of records), reading and decoding the
    /// records, replaying the splits, filling the cache.
    load_parts: (f64, f64, f64, f64),
    mono: Monolithic,
    saved_leaves: usize,
    loaded_leaves: usize,
    view_records: u64,
    view_bytes: u64,
    view_snapshot_s: f64,
    view_writer_s: f64,
}

/// The same records as one monolithic snapshot (`monolithic`).
struct Monolithic {
    /// Encoding the records, checksum, write, fsync, rename, fsync of the directory.
    save_s: f64,
    bytes: u64,
    /// Reading the file and verifying its checksum; then decoding, replaying and filling.
    read_s: f64,
    load_s: f64,
    leaves: usize,
}

/// Saves the mesh and samples as one snapshot beside the store, and loads it into a fresh mesh.
fn monolithic(
    dir: &Path,
    mesh: &SubdivisionMesh,
    cache: &ShadingCache,
) -> anyhow::Result<Monolithic> {
    let path = dir.join("snapshot.bin");
    let t = Instant::now();
    let bytes = monolithic::save(&path, &encoded_records(mesh, cache))?;
    let save_s = t.elapsed().as_secs_f64();
    let (mut fresh_mesh, mut fresh_cache) = fresh();
    let t = Instant::now();
    let records = monolithic::load(&path)?;
    let read_s = t.elapsed().as_secs_f64();
    restore_encoded(&records, &mut fresh_mesh, &mut fresh_cache).map_err(anyhow::Error::msg)?;
    Ok(Monolithic {
        save_s,
        bytes,
        read_s,
        load_s: t.elapsed().as_secs_f64(),
        leaves: fresh_mesh.leaf_count(),
    })
}

fn trial(dir: &Path, levels: usize) -> anyhow::Result<Trial> {
    let path = dir.join("bench.redb");
    let _ = std::fs::remove_file(&path);
    let (mut mesh, mut cache) = fresh();
    let mut file = open(&path, &mut mesh, &mut cache)?;
    refine_uniformly(&mut mesh, levels);
    shade(&mesh, &mut cache);
    let t = Instant::now();
    file.save_now(&mut mesh, &cache);
    let save_wall_s = t.elapsed().as_secs_f64();
    let (full, pauses) = (file.writer_stats(), file.pauses());
    let (leaves, samples) = (mesh.leaf_count(), cache.len());

    let centre = glam::Vec3::new(GRID as f32 * 0.5, GRID as f32 * 0.5, 0.0);
    refine_one_view(&mut mesh, centre, 2.0);
    let shaded = shade(&mesh, &mut cache);
    file.samples_changed(shaded);
    let before = (file.writer_stats(), file.pauses());
    file.save_now(&mut mesh, &cache);
    let (after, after_pauses) = (file.writer_stats(), file.pauses());
    let saved_leaves = mesh.leaf_count();
    drop(file);
    let mono = monolithic(dir, &mesh, &cache)?;
    let file_bytes = std::fs::metadata(&path)?.len();

    let (mut mesh, mut cache) = fresh();
    let t = Instant::now();
    let loaded = open(&path, &mut mesh, &mut cache)?;
    let load_s = t.elapsed().as_secs_f64();
    let r = loaded.restored();
    let load_parts = (
        r.open.as_secs_f64(),
        r.read.as_secs_f64(),
        r.replay.as_secs_f64(),
        r.samples_time.as_secs_f64(),
    );
    drop(loaded);
    Ok(Trial {
        leaves,
        samples,
        snapshot_s: pauses.total.as_secs_f64(),
        writer_s: full.busy.as_secs_f64(),
        save_wall_s,
        full_bytes: full.bytes,
        file_bytes,
        load_s,
        load_parts,
        mono,
        saved_leaves,
        loaded_leaves: mesh.leaf_count(),
        view_records: after.records - before.0.records,
        view_bytes: after.bytes - before.0.bytes,
        view_snapshot_s: (after_pauses.total - before.1.total).as_secs_f64(),
        view_writer_s: (after.busy - before.0.busy).as_secs_f64(),
    })
}

/// The pauses of periodic saves while a mesh is refined one view at a time, each timed from
/// outside: each `save_if_due` snapshots changed base triangles for at most `SNAPSHOT_SLICE`.
/// Returns (median, 95th percentile, longest) in ms, and the count.
fn periodic_pauses(dir: &Path, steps: u32) -> anyhow::Result<(f64, f64, f64, usize)> {
    let path = dir.join("periodic.redb");
    let _ = std::fs::remove_file(&path);
    let (mut mesh, mut cache) = fresh();
    let mut file = CacheFile::open(&path, Duration::ZERO, &key(), &mesh)
        .ok_or_else(|| anyhow::anyhow!("the cache file could not be opened"))?;
    refine_uniformly(&mut mesh, 2);
    let mut pauses = Vec::new();
    for step in 0..steps {
        let centre = glam::Vec3::new(
            (step % GRID) as f32 + 0.5,
            ((step / 3) % GRID) as f32 + 0.5,
            0.0,
        );
        refine_one_view(&mut mesh, centre, 3.0);
        let shaded = shade(&mesh, &mut cache);
        file.samples_changed(shaded);
        let t = Instant::now();
        file.save_if_due(&mut mesh, &cache);
        pauses.push(t.elapsed().as_secs_f64() * 1e3);
    }
    file.close(&mut mesh, &cache);
    pauses.sort_by(f64::total_cmp);
    let at = |q: f64| pauses[((pauses.len() - 1) as f64 * q).round() as usize];
    Ok((at(0.5), at(0.95), at(1.0), pauses.len()))
}

pub fn section(quick: bool) -> anyhow::Result<String> {
    let dir = tempfile_dir()?;
    let (levels, runs) = if quick {
        (QUICK_LEVELS, 1)
    } else {
        (LEVELS, 3)
    };
    let trials = (0..runs)
        .map(|_| trial(&dir, levels))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let med = |f: fn(&Trial) -> f64| median(trials.iter().map(f).collect());
    let t = &trials[0];
    let mut md = String::from("## Cache file (crates/sma: cache_file)\n\n");
    writeln!(
        md,
        "A {GRID}×{GRID} grid ({} base triangles) split red {levels} levels deep: {} leaves, {} samples \
         (one per vertex), saved to a fresh `redb` file, loaded into a fresh SMA mesh and cache, \
         then one view (the leaves within 2 units of the centre) refined once more and saved \
         again. {runs} run(s) on this shared 2-core machine (load average about 10 while measured: other \
         builds and benchmarks beside it): the times are noisy and pessimistic, the bytes are not.\n",
        2 * GRID * GRID,
        t.leaves,
        t.samples
    )?;
    writeln!(md, "| measure | value | target |\n|---|---:|---:|")?;
    writeln!(
        md,
        "| full save: writer thread (encode + commit, fsync) | {:.2} s | <= 1 s |",
        med(|t| t.writer_s)
    )?;
    writeln!(
        md,
        "| full save: snapshot on the schedule's thread | {:.2} s | (a clean stop; periodic saves are sliced) |",
        med(|t| t.snapshot_s)
    )?;
    writeln!(
        md,
        "| full save: wall time | {:.2} s | |",
        med(|t| t.save_wall_s)
    )?;
    writeln!(
        md,
        "| records' bytes / file size | {:.1} MiB / {:.1} MiB | |",
        t.full_bytes as f64 / 1048576.0,
        t.file_bytes as f64 / 1048576.0
    )?;
    writeln!(
        md,
        "| load of every record (a camera that sees the whole site: open with integrity check, read and decode, replay splits, fill cache) | {:.2} s | <= 1 s |",
        med(|t| t.load_s)
    )?;
    writeln!(
        md,
        "| of which: open (integrity check, list of records: all a start reads, records load as their base triangles become visible), read and decode, replay splits, fill cache | {:.2} s, {:.2} s, {:.2} s, {:.2} s | |",
        med(|t| t.load_parts.0),
        med(|t| t.load_parts.1),
        med(|t| t.load_parts.2),
        med(|t| t.load_parts.3)
    )?;
    writeln!(
        md,
        "| leaves after load | {} (saved: {}) | equal |",
        t.loaded_leaves, t.saved_leaves
    )?;
    writeln!(
        md,
        "| incremental save after one view: records, bytes | {} records, {:.1} KiB ({:.2} % of the full save) | only what changed |",
        t.view_records,
        t.view_bytes as f64 / 1024.0,
        100.0 * t.view_bytes as f64 / t.full_bytes.max(1) as f64
    )?;
    writeln!(
        md,
        "| incremental save: snapshot, writer | {:.1} ms, {:.1} ms | |",
        med(|t| t.view_snapshot_s) * 1e3,
        med(|t| t.view_writer_s) * 1e3
    )?;
    writeln!(
        md,
        "| monolithic snapshot of the same records: save (encode, checksum, temporary file, fsync, rename, fsync of the directory) | {:.2} s, {:.1} MiB | <= 1 s |",
        med(|t| t.mono.save_s),
        t.mono.bytes as f64 / 1048576.0
    )?;
    writeln!(
        md,
        "| monolithic snapshot: load (read and verify the checksum, then decode, replay, fill) | {:.2} s (read {:.2} s); {} leaves | <= 1 s |",
        med(|t| t.mono.load_s),
        med(|t| t.mono.read_s),
        t.mono.leaves
    )?;
    writeln!(
        md,
        "| monolithic snapshot: bytes an incremental save writes after one view | {:.1} MiB (the whole file, every save) | only what changed |",
        t.mono.bytes as f64 / 1048576.0
    )?;
    let (p50, p95, longest, count) = periodic_pauses(&dir, if quick { 60 } else { 150 })?;
    writeln!(
        md,
        "| schedule's pause per periodic save, {count} saves while refining view by view: median, 95th percentile, longest | {p50:.1} ms, {p95:.1} ms, {longest:.1} ms | <= 20 ms |\n",
    )?;
    writeln!(
        md,
        "Layout: one record per base triangle in `redb` against one monolithic snapshot of the same \
         records. Full save, writer time: {:.2} s against {:.2} s; load of everything: {:.2} s \
         against {:.2} s; an incremental save after one view: {:.1} KiB against {:.1} MiB (a \
         snapshot rewrites the whole file); and a start with the store reads only its list of \
         records ({:.2} s), the rest as it becomes visible, where a snapshot is read whole. The \
         store is kept: {}.\n",
        med(|t| t.writer_s),
        med(|t| t.mono.save_s),
        med(|t| t.load_s),
        med(|t| t.mono.load_s),
        t.view_bytes as f64 / 1024.0,
        t.mono.bytes as f64 / 1048576.0,
        med(|t| t.load_parts.0),
        if med(|t| t.writer_s) <= 1.0 && med(|t| t.load_s) <= 1.0 {
            "it meets the save and load targets, and only it saves incrementally and loads lazily"
        } else {
            "only it saves incrementally and loads lazily, though it misses a time target here"
        }
    )?;
    let (trials, good, failures) = crash_trials(&dir, if quick { 4 } else { 20 })?;
    writeln!(
        md,
        "Crash trials: a process saving view after view (the SMA's `CacheFile`, each save a commit) \
         killed with SIGKILL at a random moment, {trials} times; the file then opened with the \
         previous or the new commit's leaves in {good} of them (target: all).{}\n",
        failures
            .iter()
            .map(|f| format!("\n- {f}"))
            .collect::<String>()
    )?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(md)
}

/// A scratch folder under the system's temporary directory, never the user's cache directory.
fn tempfile_dir() -> anyhow::Result<std::path::PathBuf> {
    let dir = std::env::temp_dir().join(format!(
        "walkthrough-bench-cache-file-{}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}

/// The child of a crash trial (`walkthrough-bench cache-file-crash-child`): refines view after
/// view and saves after each, saying on stdout how many leaves each save holds, before it
/// starts (`saving N`) and once committed (`saved N`), until it is killed.
pub fn crash_child(path: &Path) -> anyhow::Result<()> {
    use std::io::Write as _;
    let (mut mesh, mut cache) = fresh();
    let mut file = open(path, &mut mesh, &mut cache)?;
    let mut out = std::io::stdout().lock();
    writeln!(out, "saved {}", mesh.leaf_count())?;
    for step in 0u32.. {
        let centre = glam::Vec3::new(
            (step * 7 % GRID) as f32 + 0.5,
            (step * 3 % GRID) as f32 + 0.5,
            0.0,
        );
        refine_one_view(&mut mesh, centre, 4.0);
        let shaded = shade(&mesh, &mut cache);
        file.samples_changed(shaded);
        writeln!(out, "saving {}", mesh.leaf_count())?;
        out.flush()?;
        file.save_now(&mut mesh, &cache);
        writeln!(out, "saved {}", mesh.leaf_count())?;
        out.flush()?;
    }
    Ok(())
}

/// Crash trials: a child saving view after view is killed with SIGKILL at a random moment; the
/// file must then open (not refused) with the leaves of the last commit the child finished or
/// of the one it was making, never anything else. Returns (trials, good ones, a failure's words).
fn crash_trials(dir: &Path, trials: usize) -> anyhow::Result<(usize, usize, Vec<String>)> {
    use rand::{RngExt, SeedableRng};
    use std::io::Read as _;
    let exe = std::env::current_exe()?;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    let (mut good, mut failures) = (0, Vec::new());
    let path = dir.join("crash.redb");
    let _ = std::fs::remove_file(&path);
    // The leaves the file held after the previous trial: all a child killed while loading it
    // can leave there.
    let mut previous = fresh().0.leaf_count();
    for trial in 0..trials {
        let mut child = std::process::Command::new(&exe)
            .arg("cache-file-crash-child")
            .arg(&path)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()?;
        std::thread::sleep(Duration::from_millis(rng.random_range(300..1500)));
        child.kill()?;
        child.wait()?;
        let mut said = String::new();
        child
            .stdout
            .take()
            .expect("piped")
            .read_to_string(&mut said)?;
        let counts = |word: &str| -> Vec<usize> {
            said.lines()
                .filter_map(|l| l.strip_prefix(word)?.trim().parse().ok())
                .collect()
        };
        let (saved, saving) = (counts("saved "), counts("saving "));
        let allowed: Vec<usize> = [saved.last().copied().unwrap_or(previous)]
            .into_iter()
            .chain(saving.last().copied())
            .collect();
        let (mut mesh, mut cache) = fresh();
        let opened = open(&path, &mut mesh, &mut cache);
        let refused = sma_rejected(&path).exists();
        match opened {
            Ok(_) if !refused && allowed.contains(&mesh.leaf_count()) => good += 1,
            _ => failures.push(format!(
                "trial {trial}: {} leaves after the kill, the child said {allowed:?}, refused: {refused}",
                mesh.leaf_count()
            )),
        }
        previous = mesh.leaf_count();
        if refused {
            let _ = std::fs::remove_file(sma_rejected(&path));
        }
    }
    Ok((trials, good, failures))
}

fn sma_rejected(path: &Path) -> std::path::PathBuf {
    std::path::PathBuf::from(format!("{}.rejected", path.display()))
}
