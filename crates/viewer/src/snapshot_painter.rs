//! Headless snapshots drawn away from the system they measure (DESIGN.md §10).
//!
//! Drawing a snapshot on Mesa's software rasterizer costs about 50–150 ms of both cores at
//! 1024×768, and the convergence benchmark takes several a second in the first seconds (at set
//! sample counts), just when the picture improves fastest: drawn at the instant, they took about
//! a third of the paths of a run's first second from the renderer they were measuring (bracara
//! VT, single runs: 0.47 M paths traced at 1.0 s, against 0.69 M with the drawing put off). So at
//! the instant the viewer only copies what it would draw — the table's vertices, the camera, the
//! tone map and the panel's facts, a [`Frame`] — and the snapshot writer's thread draws it later,
//! through a GPU device of its own opened on that thread: the rasterizer's worker threads are
//! created there and so inherit its lowest scheduling priority (`snapshot_files`). The image is
//! the one the viewer would have drawn at the instant, whenever it is drawn.

use std::sync::Arc;

use anyhow::Context;
use protocol::viewer_link::Camera;

use crate::direct_image::DirectImage;
use crate::direct_texture::GpuDirect;
use crate::draw::{DrawSettings, depth_range};
use crate::gpu::Gpu;
use crate::looks::Looks;
use crate::looks_texture::GpuLooks;
use crate::offscreen::{DISPLAY_FORMAT, Offscreen, Snapshot};
use crate::overlay::{PanelPainter, fixed_screen};
use crate::panel::Facts;
use crate::table::{Extent, TriangleTable, Vertex};
use crate::vertex_buffer::GpuTriangles;

/// Everything a snapshot shows, copied at its instant.
pub struct Frame {
    /// Three per shown triangle, as the table holds them.
    pub vertices: Vec<Vertex>,
    pub extent: Option<Extent>,
    pub camera: Camera,
    pub settings: DrawSettings,
    /// The panel drawn over the display image (`--overlay`), or none.
    pub facts: Option<Facts>,
    /// The direct tiles of the camera, if a picture of it shows some.
    pub direct: Option<DirectImage>,
    /// The scene's materials and textures (shared: they change only when a texture arrives).
    pub looks: Arc<Looks>,
}

impl Frame {
    /// The copy of `table` and the rest of what the viewer would draw now.
    pub fn capture(
        (table, direct, looks): (&TriangleTable, &DirectImage, &Arc<Looks>),
        camera: &Camera,
        settings: DrawSettings,
        facts: Option<Facts>,
    ) -> Frame {
        Frame {
            vertices: table.vertices().to_vec(),
            extent: table.extent(),
            camera: camera.clone(),
            settings,
            facts,
            direct: direct.copy_for(camera),
            looks: Arc::clone(looks),
        }
    }

    /// Memory the frame holds while it waits to be drawn.
    pub fn bytes(&self) -> usize {
        let direct = self
            .direct
            .as_ref()
            .map_or(0, |d| std::mem::size_of_val(d.texels()));
        std::mem::size_of::<Frame>() + std::mem::size_of_val(self.vertices.as_slice()) + direct
    }
}

/// What the snapshots look like: their size, and whether the panel is drawn over them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Canvas {
    pub width: u32,
    pub height: u32,
    pub overlay: bool,
}

/// The device and targets that draw frames into snapshots, owned by the thread that opened them.
pub struct SnapshotPainter {
    gpu: Gpu,
    offscreen: Offscreen,
    triangles: GpuTriangles,
    direct: GpuDirect,
    looks: GpuLooks,
    panel: Option<PanelPainter>,
}

impl SnapshotPainter {
    /// Opens a headless device on the calling thread (a missing adapter is an error here).
    pub fn open(canvas: Canvas) -> anyhow::Result<SnapshotPainter> {
        let gpu = Gpu::headless().context("opening the device that draws snapshots")?;
        let panel = canvas
            .overlay
            .then(|| PanelPainter::new(&gpu.device, DISPLAY_FORMAT));
        Ok(SnapshotPainter {
            offscreen: Offscreen::new(&gpu, canvas.width, canvas.height),
            triangles: GpuTriangles::new(&gpu),
            direct: GpuDirect::new(&gpu.device),
            looks: GpuLooks::new(&gpu),
            panel,
            gpu,
        })
    }

    /// The adapter, for the log.
    pub fn describe(&self) -> String {
        self.gpu.describe()
    }

    /// Draws `frame` and reads it back.
    pub fn paint(&mut self, frame: &Frame) -> anyhow::Result<Snapshot> {
        self.triangles
            .replace(&self.gpu, &frame.vertices, frame.extent);
        let direct = frame.direct.as_ref().map(|image| {
            self.direct.upload(&self.gpu, image);
            &self.direct
        });
        self.looks.sync(&self.gpu, &frame.looks);
        let depth = depth_range(&frame.camera, frame.extent);
        let gpu = (&self.gpu.device, &self.gpu.queue);
        let panel = &mut self.panel;
        let mut paint = |encoder: &mut wgpu::CommandEncoder,
                         target: (&wgpu::TextureView, [u32; 2])| {
            if let (Some(panel), Some(facts)) = (panel.as_mut(), frame.facts.as_ref()) {
                panel.paint(gpu, encoder, target, fixed_screen(target.1), facts);
            }
        };
        self.offscreen.snapshot_painted(
            &self.gpu,
            (&self.triangles, direct, &self.looks),
            &frame.camera,
            depth,
            &frame.settings,
            &mut paint,
        )
    }
}
