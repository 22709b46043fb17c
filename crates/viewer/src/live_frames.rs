//! Headless frames drawn as the window draws them (`--draw-frames`): every frame at the current
//! camera, from the triangle table kept on the GPU by its changed slots, at most
//! [`MAX_FRAME_RATE`] a second (what a window's vsync allows), each timed. It measures what a
//! person at the window would see of the frame rate while the system works (DESIGN.md §3 step 9:
//! work while walking must not slow the viewer's frames), where snapshots are drawn apart, later,
//! so as not to disturb what they measure (`snapshot_painter`).
//!
//! The frames are written, one line each, to `frames.csv` in the snapshot folder: the run's
//! clock when the frame began and the milliseconds it took, GPU included.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use protocol::viewer_link::Camera;

use crate::direct_texture::GpuDirect;
use crate::draw::{DrawSettings, depth_range};
use crate::gpu::Gpu;
use crate::looks_texture::GpuLooks;
use crate::offscreen::Offscreen;
use crate::vertex_buffer::GpuTriangles;
use crate::view_state::ViewState;

/// A window's frames come no faster than its display refreshes.
pub const MAX_FRAME_RATE: f64 = 60.0;

/// The file the frames are written to, in the snapshot folder.
pub const FRAMES_CSV: &str = "frames.csv";

/// The window's drawing, offscreen, and the frames drawn so far.
pub struct LiveFrames {
    gpu: Gpu,
    offscreen: Offscreen,
    triangles: GpuTriangles,
    direct: GpuDirect,
    looks: GpuLooks,
    /// (the run's clock at the frame's start, its duration), in order.
    frames: Vec<(f64, Duration)>,
    next_at: Instant,
    out: PathBuf,
}

impl LiveFrames {
    /// A device of its own, drawing `width`×`height`; the frames go to `out`/[`FRAMES_CSV`].
    pub fn new(width: u32, height: u32, out: &Path) -> anyhow::Result<LiveFrames> {
        let gpu = Gpu::headless().context("a device for --draw-frames")?;
        Ok(LiveFrames {
            offscreen: Offscreen::new(&gpu, width, height),
            triangles: GpuTriangles::new(&gpu),
            direct: GpuDirect::new(&gpu.device),
            looks: GpuLooks::new(&gpu),
            gpu,
            frames: Vec::new(),
            next_at: Instant::now(),
            out: out.join(FRAMES_CSV),
        })
    }

    /// How long until the next frame is due (zero: now).
    pub fn due_in(&self) -> Duration {
        self.next_at.saturating_duration_since(Instant::now())
    }

    /// Draws a frame of `state` at `camera` if one is due, `t` seconds into the run: the table's
    /// changed slots go up first, as the window's frame sends them.
    pub fn draw_if_due(
        &mut self,
        state: &mut ViewState,
        camera: &Camera,
        settings: &DrawSettings,
        t: f64,
    ) -> anyhow::Result<()> {
        let start = Instant::now();
        if start < self.next_at {
            return Ok(());
        }
        self.next_at = start + Duration::from_secs_f64(1.0 / MAX_FRAME_RATE);
        self.triangles.sync(&self.gpu, &mut state.table);
        self.direct.sync(&self.gpu, &mut state.direct);
        self.looks.sync(&self.gpu, &state.looks);
        let direct = state.direct.shown_for(camera).then_some(&self.direct);
        let layers = (&self.triangles, direct, &self.looks);
        let depth = depth_range(camera, state.table.extent());
        self.offscreen
            .draw_frame(&self.gpu, layers, camera, depth, settings)?;
        self.frames.push((t, start.elapsed()));
        Ok(())
    }

    /// Writes the frames drawn, and says how many a second came.
    pub fn finish(&self) -> anyhow::Result<()> {
        let mut text = String::from("time_s,frame_ms\n");
        for (t, spent) in &self.frames {
            text.push_str(&format!("{t:.4},{:.3}\n", spent.as_secs_f64() * 1e3));
        }
        std::fs::File::create(&self.out)
            .and_then(|mut f| f.write_all(text.as_bytes()))
            .with_context(|| format!("writing {}", self.out.display()))?;
        let span = match (self.frames.first(), self.frames.last()) {
            (Some((a, _)), Some((b, _))) if b > a => b - a,
            _ => 0.0,
        };
        let fps = if span > 0.0 {
            (self.frames.len() - 1) as f64 / span
        } else {
            0.0
        };
        tracing::info!(
            frames = self.frames.len(),
            fps = format!("{fps:.1}"),
            "frames drawn, in {}",
            self.out.display()
        );
        Ok(())
    }
}
