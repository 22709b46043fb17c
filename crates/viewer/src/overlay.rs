//! egui on top of the drawn frame: [`PanelPainter`] lays out the [`panel`](crate::panel) and
//! draws it over a target (egui-wgpu); the window's [`Overlay`] feeds it winit's input
//! (egui-winit), headless snapshots with `--overlay` a fixed screen.

use std::sync::Arc;

use winit::window::Window;

use crate::panel::{self, Action, Facts};

pub struct PanelPainter {
    context: egui::Context,
    renderer: egui_wgpu::Renderer,
}

impl PanelPainter {
    pub fn new(device: &wgpu::Device, format: wgpu::TextureFormat) -> PanelPainter {
        PanelPainter {
            context: egui::Context::default(),
            renderer: egui_wgpu::Renderer::new(device, format, Default::default()),
        }
    }

    /// Lays the panel out for `input` and records its drawing over `target` (already drawn,
    /// `size` pixels); returns the clicks and what egui asks of the platform.
    pub fn paint(
        &mut self,
        (device, queue): (&wgpu::Device, &wgpu::Queue),
        encoder: &mut wgpu::CommandEncoder,
        (target, size): (&wgpu::TextureView, [u32; 2]),
        input: egui::RawInput,
        facts: &Facts,
    ) -> (Vec<Action>, egui::PlatformOutput) {
        let mut actions = Vec::new();
        let output = self
            .context
            .run_ui(input, |ui| actions = panel::show(ui, facts));
        let jobs = self
            .context
            .tessellate(output.shapes, output.pixels_per_point);
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: size,
            pixels_per_point: output.pixels_per_point,
        };
        for (id, deltas) in &output.textures_delta.set {
            for delta in deltas {
                self.renderer.update_texture(device, queue, *id, delta);
            }
        }
        let callbacks = self
            .renderer
            .update_buffers(device, queue, encoder, &jobs, &screen);
        queue.submit(callbacks);
        let pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("panel"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Load,
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        self.renderer
            .render(&mut pass.forget_lifetime(), &jobs, &screen);
        for id in &output.textures_delta.free {
            self.renderer.free_texture(id);
        }
        (actions, output.platform_output)
    }

    /// Whether egui asks for another frame soon (an animation, a hover change).
    pub fn wants_repaint(&self) -> bool {
        self.context.has_requested_repaint()
    }
}

/// What egui sees of a headless image: a screen of `size` pixels, one pixel per point.
pub fn fixed_screen([width, height]: [u32; 2]) -> egui::RawInput {
    egui::RawInput {
        screen_rect: Some(egui::Rect::from_min_size(
            egui::Pos2::ZERO,
            egui::vec2(width as f32, height as f32),
        )),
        ..Default::default()
    }
}

/// The window's panel: egui-winit's input into a [`PanelPainter`].
pub struct Overlay {
    painter: PanelPainter,
    input: egui_winit::State,
    window: Arc<Window>,
}

impl Overlay {
    pub fn new(window: Arc<Window>, device: &wgpu::Device, format: wgpu::TextureFormat) -> Overlay {
        let painter = PanelPainter::new(device, format);
        let input = egui_winit::State::new(
            painter.context.clone(),
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            None,
        );
        Overlay {
            painter,
            input,
            window,
        }
    }

    /// Feeds a window event to egui. `consumed`: egui took it (a click on the panel), so the
    /// camera must not see it. `repaint`: the panel must be drawn again for the event to take
    /// effect; egui judges a click only in the next pass, so a press that is not redrawn for is
    /// never a click.
    pub fn on_event(&mut self, event: &winit::event::WindowEvent) -> egui_winit::EventResponse {
        self.input.on_window_event(&self.window, event)
    }

    /// Draws the panel over `target`, the window's frame; returns the clicks.
    pub fn draw(
        &mut self,
        gpu: (&wgpu::Device, &wgpu::Queue),
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        facts: &Facts,
    ) -> Vec<Action> {
        let input = self.input.take_egui_input(&self.window);
        let size = self.window.inner_size();
        let (actions, platform) = self.painter.paint(
            gpu,
            encoder,
            (target, [size.width, size.height]),
            input,
            facts,
        );
        self.input.handle_platform_output(&self.window, platform);
        actions
    }

    pub fn wants_repaint(&self) -> bool {
        self.painter.wants_repaint()
    }
}
