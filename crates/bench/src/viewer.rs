//! The viewer's figures for BENCHMARKS.md (DESIGN.md §2 viewer): how fast updates are applied (target: 2 M
//! triangles a second) and how long a frame takes at 100k and 1M triangles.
//!
//! Update batches are what the SMA sends between epochs: inserts of new triangles and removes of
//! random held ones, applied to the table and uploaded to the GPU, waiting for the queue so the
//! upload is really done. Frames draw a finely tessellated wall filling a 1024×768 view, because the
//! SMA sends only visible leaves: depth complexity stays near one, as in a real walkthrough.

use std::fmt::Write as _;
use std::time::Instant;

use protocol::direct_tile::{TilePixel, TileRect, ViewerTile};
use protocol::texture::Texcoords;
use protocol::types::Viewpoint;
use protocol::viewer_link::{Camera, CornerShading, ShownTriangle};

use viewer::direct_image::DirectImage;
use viewer::direct_texture::GpuDirect;
use viewer::draw::{DrawSettings, depth_range};
use viewer::gpu::{Gpu, headless_or_skip};
use viewer::looks::Looks;
use viewer::looks_texture::GpuLooks;
use viewer::offscreen::Offscreen;
use viewer::table::TriangleTable;
use viewer::update::TableOp;
use viewer::vertex_buffer::GpuTriangles;

use super::stats::median;

pub(crate) const WIDTH: u32 = 1024;
pub(crate) const HEIGHT: u32 = 768;

/// Times each texture repeats across the 4×3 wall, horizontally and vertically: a layer of 1024
/// texels lands on 256 pixels, minified 4:1 as a wall seen across a courtyard is.
const WALL_REPEATS: [f32; 2] = [4.0, 3.0];

/// What the wall's triangles are drawn with.
#[derive(Clone, Copy)]
pub(crate) enum Surface<'a> {
    /// No materials: every albedo one, layer 0 white (the path an untextured scene's pixels
    /// take).
    White,
    /// `looks`, its textured `materials` in vertical bands across the wall, each texture
    /// repeating [`WALL_REPEATS`] times over the wall.
    Textured {
        looks: &'a Looks,
        materials: &'a [u16],
    },
}

struct Plan {
    table_size: usize,
    batch: usize,
    batches_per_run: usize,
    runs: usize,
    frame_sizes: &'static [usize],
    frames: usize,
}

const FULL: Plan = Plan {
    table_size: 1_000_000,
    batch: 10_000,
    batches_per_run: 10,
    runs: 7,
    frame_sizes: &[100_000, 1_000_000],
    frames: 7,
};
const QUICK: Plan = Plan {
    table_size: 100_000,
    batch: 10_000,
    batches_per_run: 5,
    runs: 3,
    frame_sizes: &[100_000],
    frames: 3,
};

/// The Markdown section; `quick` uses smaller sizes and fewer runs (for CI).
pub fn section(quick: bool) -> anyhow::Result<String> {
    let plan = if quick { QUICK } else { FULL };
    let gpu = headless_or_skip("viewer benchmark")?;
    let mut out = String::from("## Viewer: applying updates and drawing\n\n");
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let adapter = gpu.as_ref().map_or("none".to_string(), Gpu::describe);
    writeln!(
        out,
        "Adapter: {adapter}; {cores} CPU cores; medians of {} runs.\n",
        plan.runs
    )?;
    writeln!(out, "| measure | median | min | max |\n|---|---|---|---|")?;

    let cpu = apply_rates(&plan, None)?;
    row(
        &mut out,
        &format!("updates applied, table only ({})", batch_words(&plan)),
        &cpu,
        "M tri/s",
    )?;
    if let Some(gpu) = &gpu {
        let with_upload = apply_rates(&plan, Some(gpu))?;
        let label = format!("updates applied + uploaded ({})", batch_words(&plan));
        row(&mut out, &label, &with_upload, "M tri/s")?;
        let mut tile_ratio = None;
        for &n in plan.frame_sizes {
            let times = frame_times(gpu, n, plan.frames, false, Surface::White)?;
            row(
                &mut out,
                &format!("frame time, {n} triangles, {WIDTH}×{HEIGHT}"),
                &times,
                "ms",
            )?;
            let with_tiles = frame_times(gpu, n, plan.frames, true, Surface::White)?;
            row(
                &mut out,
                &format!("frame time, {n} triangles, direct tiles over the view"),
                &with_tiles,
                "ms",
            )?;
            tile_ratio.get_or_insert((n, median(with_tiles) / median(times)));
        }
        if let Some((n, ratio)) = tile_ratio {
            let verdict = if ratio <= 1.1 { "met" } else { "NOT met" };
            writeln!(
                out,
                "\nFrame with per-pixel direct tiles at {n} triangles: {ratio:.2}× the frame \
                 without (target at most 1.1×): {verdict}."
            )?;
        }
        let verdict = if median(with_upload.clone()) >= 2.0 {
            "met"
        } else {
            "NOT met"
        };
        writeln!(
            out,
            "\nTarget of 2 M triangles/s applied (with upload): {verdict}."
        )?;
    } else {
        writeln!(
            out,
            "\nNo graphics adapter: upload and frame times not measured."
        )?;
    }
    Ok(out)
}

fn batch_words(plan: &Plan) -> String {
    format!(
        "{} table, batches of {}+{} ins+rem",
        plan.table_size, plan.batch, plan.batch
    )
}

pub(crate) fn row(out: &mut String, label: &str, values: &[f64], unit: &str) -> std::fmt::Result {
    let min = values.iter().copied().fold(f64::INFINITY, f64::min);
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    writeln!(
        out,
        "| {label} | {:.2} {unit} | {min:.2} | {max:.2} |",
        median(values.to_vec())
    )
}

/// Millions of triangles (inserted + removed) applied per second, one figure per run.
fn apply_rates(plan: &Plan, gpu: Option<&Gpu>) -> anyhow::Result<Vec<f64>> {
    let mut rng = XorShift(0x9e37_79b9_7f4a_7c15);
    let mut table = TriangleTable::new();
    let mut held: Vec<u64> = (0..plan.table_size as u64).collect();
    let mut next_id = plan.table_size as u64;
    table.apply(&[TableOp::Insert(
        held.iter()
            .map(|&id| random_triangle(id, &mut rng))
            .collect(),
    )]);
    let mut uploaded = gpu.map(GpuTriangles::new);
    if let (Some(g), Some(u)) = (gpu, uploaded.as_mut()) {
        u.sync(g, &mut table);
        g.wait_idle()?;
    }
    let mut rates = Vec::new();
    // Run 0 warms up (the first scatter dispatch compiles its shader) and is not counted.
    for run in 0..=plan.runs {
        let batches: Vec<Vec<TableOp>> = (0..plan.batches_per_run)
            .map(|_| {
                let inserts = (0..plan.batch)
                    .map(|_| {
                        next_id += 1;
                        held.push(next_id);
                        random_triangle(next_id, &mut rng)
                    })
                    .collect();
                let removes = (0..plan.batch)
                    .map(|_| held.swap_remove(rng.below(held.len())))
                    .collect();
                vec![TableOp::Insert(inserts), TableOp::Remove(removes)]
            })
            .collect();
        let start = Instant::now();
        for ops in &batches {
            table.apply(ops);
            if let (Some(g), Some(u)) = (gpu, uploaded.as_mut()) {
                u.sync(g, &mut table);
                g.queue.submit([]);
                g.wait_idle()?;
            }
        }
        let seconds = start.elapsed().as_secs_f64();
        if run == 0 {
            continue;
        }
        rates.push((2 * plan.batch * plan.batches_per_run) as f64 / seconds / 1e6);
    }
    Ok(rates)
}

/// Milliseconds per frame (draw + wait) for a wall of `n` triangles filling the view, drawn with
/// `surface`, with direct tiles over the whole view (every pixel shown from its tile) if `tiles`.
pub(crate) fn frame_times(
    gpu: &Gpu,
    n: usize,
    frames: usize,
    tiles: bool,
    surface: Surface,
) -> anyhow::Result<Vec<f64>> {
    let materials = match surface {
        Surface::White => &[][..],
        Surface::Textured { materials, .. } => materials,
    };
    let mut table = TriangleTable::new();
    table.apply(&[TableOp::Insert(wall(n, materials))]);
    let mut triangles = GpuTriangles::new(gpu);
    triangles.sync(gpu, &mut table);
    let camera = wall_camera();
    let offscreen = Offscreen::new(gpu, WIDTH, HEIGHT);
    let depth = depth_range(&camera, table.extent());
    let settings = DrawSettings {
        l_white: 2.0,
        ..DrawSettings::default()
    };
    let mut direct = GpuDirect::new(&gpu.device);
    if tiles {
        let mut image = DirectImage::default();
        image.follow(&camera);
        for rect in TileRect::cover(WIDTH, HEIGHT) {
            image.accept(&ViewerTile {
                camera_seq: camera.seq,
                rect,
                samples: 16,
                pixels: vec![TilePixel::new([0.3, 0.2, 0.1], 0.0); rect.pixels()],
            });
        }
        direct.upload(gpu, &image);
    }
    let mut looks = GpuLooks::new(gpu);
    if let Surface::Textured { looks: held, .. } = surface {
        looks.sync(gpu, held);
    }
    let layers = (&triangles, tiles.then_some(&direct), &looks);
    offscreen.draw_frame(gpu, layers, &camera, depth, &settings)?; // warm-up
    (0..frames)
        .map(|_| {
            let start = Instant::now();
            offscreen.draw_frame(gpu, layers, &camera, depth, &settings)?;
            Ok(start.elapsed().as_secs_f64() * 1e3)
        })
        .collect()
}

/// A 4×3 wall at z = 0 cut into `n` triangles (rounded to a grid), radiance varying across it;
/// with `materials`, each of them on a vertical band of it, its texture coordinates running
/// [`WALL_REPEATS`] periods across the wall (material 0 and no coordinates without).
fn wall(n: usize, materials: &[u16]) -> Vec<ShownTriangle> {
    let cols = ((n as f64 / 2.0 * 4.0 / 3.0).sqrt().ceil() as usize).max(1);
    let rows = (n / 2).div_ceil(cols).max(1);
    let point = |i: usize, j: usize| {
        [
            4.0 * i as f32 / cols as f32 - 2.0,
            3.0 * j as f32 / rows as f32 - 1.5,
            0.0,
        ]
    };
    let radiance = |p: [f32; 3]| [0.5 + 0.25 * p[0], 0.6, 0.4 + 0.2 * p[1]];
    let uv = |p: [f32; 3]| {
        [
            (p[0] + 2.0) / 4.0 * WALL_REPEATS[0],
            (1.5 - p[1]) / 3.0 * WALL_REPEATS[1],
        ]
    };
    let mut out = Vec::with_capacity(2 * cols * rows);
    for j in 0..rows {
        for i in 0..cols {
            let [a, b, c, d] = [
                point(i, j),
                point(i + 1, j),
                point(i + 1, j + 1),
                point(i, j + 1),
            ];
            for (k, positions) in [[a, b, c], [a, c, d]].into_iter().enumerate() {
                let id = (2 * (j * cols + i) + k) as u64;
                let (material, texcoords) = match materials {
                    [] => (0, Texcoords::default()),
                    _ => (
                        materials[i * materials.len() / cols],
                        Texcoords::encode(positions.map(uv), false),
                    ),
                };
                out.push(ShownTriangle {
                    id,
                    positions,
                    material,
                    texcoords,
                    shading: CornerShading {
                        illumination: positions.map(radiance),
                        ..CornerShading::default()
                    },
                });
            }
        }
    }
    out
}

/// Looks at the wall from where it just fills a 1024×768 view.
fn wall_camera() -> Camera {
    let vp = Viewpoint {
        name: "wall".into(),
        eye: [0.0, 0.0, 2.5],
        target: [0.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 60.0,
    };
    Camera::from_viewpoint(&vp, 1, WIDTH, HEIGHT)
}

fn random_triangle(id: u64, rng: &mut XorShift) -> ShownTriangle {
    let mut p = || [rng.unit(), rng.unit(), rng.unit()];
    let positions = [p(), p(), p()];
    ShownTriangle {
        id,
        positions,
        material: 0,
        texcoords: Default::default(),
        shading: CornerShading {
            illumination: [p(), p(), p()],
            ..CornerShading::default()
        },
    }
}

/// A tiny deterministic generator: the benchmark needs repeatable ids, not statistical quality.
struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wall_has_about_n_triangles_with_unique_ids() {
        let w = wall(1000, &[]);
        assert!((1000..1100).contains(&w.len()), "{}", w.len());
        let ids: std::collections::HashSet<u64> = w.iter().map(|t| t.id).collect();
        assert_eq!(ids.len(), w.len());
        assert!(w.iter().all(|t| t.material == 0));
    }

    /// Textured, every material has a band, from left to right, and the coordinates run
    /// `WALL_REPEATS` periods across the wall.
    #[test]
    fn a_textured_wall_has_every_material_in_bands_and_repeats_its_textures() {
        let w = wall(1000, &[3, 5, 9]);
        let materials: std::collections::BTreeSet<u16> = w.iter().map(|t| t.material).collect();
        assert_eq!(materials, [3, 5, 9].into());
        let (left, right) = (&w[0], &w[w.len() - 1]);
        assert!(left.material == 3 && right.material == 9);
        for t in [left, right] {
            for (p, uv) in t.positions.iter().zip(t.texcoords.decode()) {
                let want = [
                    (p[0] + 2.0) / 4.0 * WALL_REPEATS[0],
                    (1.5 - p[1]) / 3.0 * WALL_REPEATS[1],
                ];
                for a in 0..2 {
                    let off = want[a] - uv[a];
                    assert!(
                        (off - off.round()).abs() < 1e-3,
                        "{p:?}: {uv:?}, want {want:?}"
                    );
                }
            }
        }
    }
}
