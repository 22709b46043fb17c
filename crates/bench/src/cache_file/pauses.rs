//! The pause a periodic save costs the schedule's thread (DESIGN.md §5: saving is periodic, on
//! another thread; the schedule pauses at most 20 ms), timed from outside each `save_if_due`
//! while a walk refines a mesh view by view: by the wall clock (what the schedule waits,
//! preemption by the machine's other work included) and by the thread's CPU clock (the work
//! itself). `save_if_due` snapshots changed base triangles for at most `SNAPSHOT_SLICE`, but one
//! base triangle's record is never cut, so the deepest subtree bounds the tail.

use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

use glam::Vec3;
use sma::cache_file::CacheFile;

use super::{GRID, fresh, key, refine_one_view, refine_uniformly, shade};

/// A walk: the mesh split red `levels` deep, then `views` views, each refining the leaves within
/// `radius` of its centre once more down to `finest` splits, shading their new vertices and
/// making a periodic save due (period zero: every view saves).
pub(super) struct Walk {
    what: &'static str,
    levels: usize,
    finest: u32,
    radius: f32,
    views: u32,
    centre: fn(u32) -> Vec3,
}

/// Across the site, to one level past the full save's mesh; and a close look, a person walking
/// up to one spot, whose few base triangles are split three levels deeper still.
pub(super) fn walks(levels: usize, quick: bool) -> [Walk; 2] {
    [
        Walk {
            what: "across the site",
            levels: levels - 1,
            finest: levels as u32,
            radius: 2.5,
            views: if quick { 60 } else { 150 },
            centre: |view| {
                Vec3::new(
                    (view % GRID) as f32 + 0.5,
                    ((view / 3) % GRID) as f32 + 0.5,
                    0.0,
                )
            },
        },
        Walk {
            what: "up to one spot",
            levels: 2,
            finest: levels as u32 + 3,
            radius: 1.0,
            views: 40,
            centre: |view| Vec3::new(20.0 + 0.1 * view as f32, 22.5, 0.0),
        },
    ]
}

/// The pauses of one walk, in ms.
pub(super) struct PeriodicPauses {
    wall: Vec<f64>,
    cpu: Vec<f64>,
    /// Leaves at the start and at the end of the walk.
    leaves: (usize, usize),
    /// The most leaves one base triangle held at the end.
    largest_base: usize,
}

/// The CPU time of the calling thread.
pub(super) fn thread_cpu_time() -> Duration {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `t` is a valid timespec for the call to fill; the clock id is a constant.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    Duration::new(t.tv_sec as u64, t.tv_nsec as u32)
}

/// (median, 95th percentile, longest) of `values`.
fn tail(values: &[f64]) -> (f64, f64, f64) {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.95), at(1.0))
}

pub(super) fn periodic_pauses(dir: &Path, walk: &Walk) -> anyhow::Result<PeriodicPauses> {
    let path = dir.join("periodic.redb");
    let _ = std::fs::remove_file(&path);
    let (mut mesh, mut cache) = fresh();
    let mut file = CacheFile::open(&path, Duration::ZERO, &key(), &mesh)
        .ok_or_else(|| anyhow::anyhow!("the cache file could not be opened"))?;
    refine_uniformly(&mut mesh, walk.levels);
    let start_leaves = mesh.leaf_count();
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    for view in 0..walk.views {
        refine_one_view(&mut mesh, (walk.centre)(view), walk.radius, walk.finest);
        let shaded = shade(&mesh, &mut cache);
        file.samples_changed(shaded);
        let (t, c) = (Instant::now(), thread_cpu_time());
        file.save_if_due(&mut mesh, &cache);
        cpu.push((thread_cpu_time() - c).as_secs_f64() * 1e3);
        wall.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let largest_base = (0..mesh.base_count() as u32)
        .map(|b| mesh.leaves_of_base(b).len())
        .max()
        .unwrap_or(0);
    let leaves = (start_leaves, mesh.leaf_count());
    file.close(&mut mesh, &cache);
    Ok(PeriodicPauses {
        wall,
        cpu,
        leaves,
        largest_base,
    })
}

/// The walk's two rows of the section's table.
pub(super) fn rows(md: &mut String, walk: &Walk, p: &PeriodicPauses) -> std::fmt::Result {
    let ((w50, w95, wmax), (c50, c95, cmax)) = (tail(&p.wall), tail(&p.cpu));
    writeln!(
        md,
        "| schedule's pause per periodic save, {} saves on a walk {} ({} leaves split {} levels deep; each view's leaves within {} units split once more, to {} levels at most: {} leaves at the end, at most {} in one base triangle): median, 95th percentile, longest, by the wall clock | {w50:.1} ms, {w95:.1} ms, {wmax:.1} ms | <= 20 ms |",
        p.wall.len(),
        walk.what,
        p.leaves.0,
        walk.levels,
        walk.radius,
        walk.finest,
        p.leaves.1,
        p.largest_base,
    )?;
    writeln!(
        md,
        "| the same pauses by the thread's CPU clock (the work; the wall clock adds preemption by the machine's other work) | {c50:.1} ms, {c95:.1} ms, {cmax:.1} ms | |",
    )
}
