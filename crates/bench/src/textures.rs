//! The textures section of BENCHMARKS.md: diffuse textures end to end (DESIGN.md §5, "Parts,
//! and textures"), measured side by side in one run:
//! - the wire: bytes per inserted textured diffuse triangle beside untextured ones ([`wire`]);
//! - Sponza's textures (and `bracara-textured`'s) reaching a viewer from a real SMA process,
//!   from `SceneInfo` to the last `Texture` ([`arrival`]);
//! - the GPU bytes of the viewer's texture array for both, as its panel counts them
//!   (`GpuLooks::bytes`);
//! - a frame of 100 k textured triangles at 1024×768 against the untextured frame, by the
//!   viewer section's frame timing ([`super::viewer::frame_times`]).

use std::fmt::Write as _;

use viewer::gpu::{Gpu, headless_or_skip};
use viewer::looks::Looks;
use viewer::looks_texture::GpuLooks;

use super::stats::median;
use super::viewer::{HEIGHT, Surface, WIDTH, frame_times, row};

mod arrival;
mod wire;

use arrival::Arrival;

/// Triangles of the frame measured textured against untextured.
const FRAME_TRIANGLES: usize = 100_000;
/// Sponza's textures at a viewer within this many seconds of `SceneInfo`.
const ARRIVAL_TARGET_S: f64 = 1.0;
/// The textured frame at most this many times the untextured one.
const FRAME_TARGET: f64 = 1.3;

struct Plan {
    /// Viewer connections per scene, and rounds of textured and untextured frames.
    runs: usize,
    /// Frames per round.
    frames: usize,
}

const FULL: Plan = Plan { runs: 7, frames: 7 };
const QUICK: Plan = Plan { runs: 3, frames: 3 };

/// One scene's textures as they reached a viewer, or why they were not measured.
struct SceneArrival {
    label: &'static str,
    /// Whether the arrival target applies to it.
    judged: bool,
    arrival: anyhow::Result<Arrival>,
}

/// The Markdown section; `quick` takes fewer runs (a smoke run).
pub fn section(quick: bool) -> anyhow::Result<String> {
    let plan = if quick { QUICK } else { FULL };
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let mut md =
        String::from("## Textures: the wire, their arrival, the viewer's memory and frame\n\n");
    writeln!(
        md,
        "Diffuse textures on (DESIGN.md §5, \"Parts, and textures\"). Medians of {} runs; measured on \
         a shared machine ({cores} cores, other work running), so the frame is judged by the ratio of \
         textured to untextured frames measured side by side in this run.\n",
        plan.runs
    )?;
    write_wire(&mut md)?;
    let temp = tempfile::tempdir()?;
    let arrivals = [
        SceneArrival {
            label: wire::SCENE,
            judged: false,
            arrival: arrival::measure(wire::SCENE, plan.runs, temp.path()),
        },
        SceneArrival {
            label: "Sponza (textures on)",
            judged: true,
            arrival: arrival::sponza_textured()
                .and_then(|toml| arrival::measure(toml, plan.runs, temp.path())),
        },
    ];
    write_arrivals(&mut md, &arrivals)?;
    match headless_or_skip("textures benchmark")? {
        Some(gpu) => {
            let looks: Vec<(&SceneArrival, &Arrival, Looks)> = arrivals
                .iter()
                .filter_map(|s| {
                    let a = s.arrival.as_ref().ok()?;
                    Some((s, a, viewer_looks(a)))
                })
                .collect();
            write_memory(&mut md, &gpu, &looks)?;
            // Sponza's textures where they arrived, else bracara's.
            match looks.last() {
                Some((scene, arrival, looks)) => {
                    write_frame_cost(&mut md, &gpu, &plan, scene.label, arrival, looks)?
                }
                None => writeln!(md, "No textures arrived: the frame was not measured.\n")?,
            }
        }
        None => writeln!(
            md,
            "No graphics adapter: the viewer's texture memory and frame not measured.\n"
        )?,
    }
    Ok(md)
}

fn verdict(met: bool) -> &'static str {
    if met { "met" } else { "NOT met" }
}

fn write_wire(md: &mut String) -> anyhow::Result<()> {
    let bytes = wire::measure()?;
    let (textured, untextured) = (bytes.textured, bytes.untextured);
    writeln!(
        md,
        "### On the wire\n\nInserts of `{}`'s leaves (every leaf split red {} times), material and \
         coordinates as the SMA makes them, shading of a diffuse leaf (no view-dependent part).\n",
        wire::SCENE,
        wire::REFINEMENTS
    )?;
    writeln!(
        md,
        "| triangles | count | bytes per triangle |\n|---|---:|---:|"
    )?;
    writeln!(
        md,
        "| textured diffuse (material, 16-bit coordinates) | {} | {:.1} |",
        textured.0, textured.1
    )?;
    writeln!(
        md,
        "| untextured material (material, zero coordinates) | {} | {:.1} |",
        untextured.0, untextured.1
    )?;
    writeln!(
        md,
        "| the textured ones without material and coordinates (the wire before textures) | {} | {:.1} |\n",
        textured.0, bytes.textured_bare
    )?;
    writeln!(
        md,
        "Target: a textured triangle at most {:.2} bytes (1.25 × {:.1}, an untextured triangle \
         before textures): {:.1} bytes, {:.2}× the same triangles without material and coordinates: \
         {}.\n",
        wire::TARGET,
        wire::BEFORE_TEXTURES,
        textured.1,
        textured.1 / bytes.textured_bare,
        verdict(textured.1 <= wire::TARGET)
    )?;
    Ok(())
}

fn write_arrivals(md: &mut String, arrivals: &[SceneArrival]) -> anyhow::Result<()> {
    writeln!(
        md,
        "### Textures reaching a viewer\n\nA real SMA process on loopback (no renderer: it serves \
         viewers without one), viewers connected one after the other; time from holding `SceneInfo` \
         to holding the last `Texture` (PNGs of at most 1024 texels a side). Target for Sponza: at \
         most {ARRIVAL_TARGET_S:.0} s.\n"
    )?;
    writeln!(
        md,
        "| scene | textures | PNG bytes | SceneInfo → last Texture, median (min–max) | connect → last Texture | target met |\n\
         |---|---:|---:|---:|---:|:-:|"
    )?;
    for scene in arrivals {
        let a = match &scene.arrival {
            Ok(a) => a,
            Err(e) => {
                let why = format!("{e:#}").replace('\n', " ");
                writeln!(md, "| {} | not measured: {why} | | | | |", scene.label)?;
                continue;
            }
        };
        let seconds = median(a.seconds.clone());
        let min = a.seconds.iter().copied().fold(f64::INFINITY, f64::min);
        let max = a.seconds.iter().copied().fold(0.0, f64::max);
        let met = if scene.judged {
            verdict(seconds <= ARRIVAL_TARGET_S)
        } else {
            "—"
        };
        writeln!(
            md,
            "| {} | {} | {:.2} MiB | {:.1} ms ({:.1}–{:.1}) | {:.1} ms | {met} |",
            scene.label,
            a.images.len(),
            a.png_bytes() as f64 / f64::from(1 << 20),
            seconds * 1e3,
            min * 1e3,
            max * 1e3,
            median(a.from_connect.clone()) * 1e3
        )?;
    }
    md.push('\n');
    Ok(())
}

/// The looks a viewer holds once `arrival`'s textures are decoded.
fn viewer_looks(arrival: &Arrival) -> Looks {
    let mut looks = Looks::of(&arrival.info);
    for image in &arrival.images {
        looks.accept(image);
    }
    looks
}

fn write_memory(
    md: &mut String,
    gpu: &Gpu,
    looks: &[(&SceneArrival, &Arrival, Looks)],
) -> anyhow::Result<()> {
    writeln!(
        md,
        "### The viewer's texture memory\n\nThe GPU bytes of the texture array (one square layer \
         per texture with its mips, sRGB) and the material table, as the viewer's panel counts \
         them.\n"
    )?;
    writeln!(md, "| scene | textures | GPU bytes |\n|---|---:|---:|")?;
    for (scene, arrival, held) in looks {
        let mut on_gpu = GpuLooks::new(gpu);
        on_gpu.sync(gpu, held);
        writeln!(
            md,
            "| {} | {} | {:.1} MiB |",
            scene.label,
            arrival.images.len(),
            on_gpu.bytes() as f64 / f64::from(1 << 20)
        )?;
    }
    md.push('\n');
    Ok(())
}

/// Rounds of untextured and textured frames of the same wall, alternating, with `looks`' textured
/// materials in bands across it.
fn write_frame_cost(
    md: &mut String,
    gpu: &Gpu,
    plan: &Plan,
    label: &str,
    arrival: &Arrival,
    looks: &Looks,
) -> anyhow::Result<()> {
    let materials: Vec<u16> = (arrival.info.materials.iter().enumerate())
        .filter(|(_, m)| m.texture.is_some())
        .map(|(i, _)| i as u16)
        .collect();
    let (mut white, mut textured) = (Vec::new(), Vec::new());
    for _ in 0..plan.runs {
        white.extend(frame_times(
            gpu,
            FRAME_TRIANGLES,
            plan.frames,
            false,
            Surface::White,
        )?);
        let surface = Surface::Textured {
            looks,
            materials: &materials,
        };
        textured.extend(frame_times(
            gpu,
            FRAME_TRIANGLES,
            plan.frames,
            false,
            surface,
        )?);
    }
    writeln!(
        md,
        "### The viewer's frame\n\nA wall of {FRAME_TRIANGLES} triangles filling a {WIDTH}×{HEIGHT} \
         view, untextured, and textured with the {} textured materials of {label}, in bands (each \
         texture minified about 4:1, so its mips are read), {} rounds of {} frames each, \
         alternating. Adapter: {}.\n",
        materials.len(),
        plan.runs,
        plan.frames,
        gpu.describe()
    )?;
    writeln!(md, "| frame | median | min | max |\n|---|---|---|---|")?;
    row(md, "untextured", &white, "ms")?;
    row(md, "textured", &textured, "ms")?;
    let ratio = median(textured) / median(white);
    writeln!(
        md,
        "\nTextured frame {ratio:.2}× the untextured one (target at most {FRAME_TARGET}×): {}.\n",
        verdict(ratio <= FRAME_TARGET)
    )?;
    Ok(())
}
