//! The interactive window (winit 0.30): walk with WASD/arrows and mouse look, and talk to the SMA.
//!
//! Keys: W/S or Up/Down walk, A/D strafe, Left/Right turn, Q/E sink/rise, drag with the left
//! button to look, +/- (or the wheel) change speed, 1–9 jump to the scene's viewpoints, C switches
//! the criterion, P pauses/resumes refinement, F toggles the wireframe, T the tone-mapping
//! operator, H hides the panel, Esc quits. The panel ([`crate::panel`]) lists them and offers the
//! same switches to the mouse. Frames are drawn on demand (an update arrived, the camera moved,
//! the panel changed), so an idle viewer leaves the CPU to the renderers.

use std::collections::HashSet;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, anyhow};
use protocol::viewer_link::ViewerToSma;
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::camera_sender::{CameraSender, DEFAULT_INTERVAL};
use crate::config::ViewerConfig;
use crate::direct_texture::GpuDirect;
use crate::draw::{DrawSettings, Drawer, Output, depth_range, depth_texture};
use crate::gpu::Gpu;
use crate::link::{EventQueue, Link, event_queue};
use crate::looks_texture::GpuLooks;
use crate::overlay::Overlay;
use crate::panel::{Action, Facts};
use crate::progress::ProgressPrinter;
use crate::session::{next_criterion, pick_viewpoint, preferences};
use crate::vertex_buffer::GpuTriangles;
use crate::view_state::{Reaction, ViewState};
use crate::walk_camera::{WalkCamera, default_speed};

/// Title prefix, also what the window test searches for.
pub const TITLE: &str = "walkthrough viewer";
/// What the window logs (at `debug`, with `panel` shown or not) once it has drawn and has
/// nothing more to draw until an input or the SMA changes something: the window test waits for
/// it before a click, which must then be drawn for on its own.
pub const SETTLED: &str = "window settled";
const TITLE_EVERY: Duration = Duration::from_millis(500);
/// Longest step of one frame: a key tapped after a long idle moves a little, not far.
const MAX_FRAME_S: f32 = 0.1;
const LOOK_RAD_PER_PIXEL: f32 = 0.003;
const TURN_RAD_PER_S: f32 = 1.5;
const SPEED_STEP: f32 = 1.5;

pub(crate) fn run(config: &ViewerConfig) -> anyhow::Result<()> {
    // winit's own queue of user events has no bound, so the link's events wait in a bounded one
    // and winit carries only a wake-up, one at a time.
    let event_loop = EventLoop::<LinkWoke>::with_user_event().build()?;
    let proxy = event_loop.create_proxy();
    let (notify, events) = event_queue(move || {
        let _ = proxy.send_event(LinkWoke);
    });
    let link = Link::spawn(config.connect.clone(), notify)?;
    let mut app = App::new(config.clone(), link, events);
    event_loop.run_app(&mut app)?;
    let App {
        link,
        events,
        failure,
        ..
    } = app;
    // Nothing takes the link's events any more: a link waiting for room stops waiting.
    drop(events);
    link.close();
    failure.map_or(Ok(()), Err)
}

/// The link has queued events ([`event_queue`]).
struct LinkWoke;

/// The window and what draws into it.
struct Display {
    overlay: Overlay,
    triangles: GpuTriangles,
    /// The per-pixel direct tiles of the resting camera (`ViewState::direct`).
    direct: GpuDirect,
    /// The scene's materials and textures (`ViewState::looks`).
    looks: GpuLooks,
    drawer: Drawer,
    depth: wgpu::TextureView,
    config: wgpu::SurfaceConfiguration,
    // Declared before the window it presents to, so it is dropped first.
    surface: wgpu::Surface<'static>,
    gpu: Gpu,
    window: Arc<Window>,
}

impl Display {
    fn open(event_loop: &ActiveEventLoop, config: &ViewerConfig) -> anyhow::Result<Display> {
        let attributes = Window::default_attributes()
            .with_title(TITLE)
            .with_inner_size(PhysicalSize::new(config.width, config.height));
        let window = Arc::new(event_loop.create_window(attributes)?);
        let instance = wgpu::Instance::new(
            wgpu::InstanceDescriptor::new_with_display_handle(Box::new(
                event_loop.owned_display_handle(),
            ))
            .with_env(),
        );
        let surface = instance.create_surface(window.clone())?;
        let gpu = pollster::block_on(Gpu::open(instance, Some(&surface)))?;
        tracing::debug!(adapter = %gpu.describe(), "window");
        let size = window.inner_size();
        let mut config = surface
            .get_default_config(&gpu.adapter, size.width.max(1), size.height.max(1))
            .ok_or_else(|| anyhow!("the adapter cannot present to this window"))?;
        // An sRGB target encodes for us; otherwise the shader does (draw.wgsl).
        let caps = surface.get_capabilities(&gpu.adapter);
        if let Some(&srgb) = caps.formats.iter().find(|f| f.is_srgb()) {
            config.format = srgb;
        }
        config.present_mode = wgpu::PresentMode::AutoVsync;
        surface.configure(&gpu.device, &config);
        Ok(Display {
            overlay: Overlay::new(window.clone(), &gpu.device, config.format),
            triangles: GpuTriangles::new(&gpu),
            direct: GpuDirect::new(&gpu.device),
            looks: GpuLooks::new(&gpu),
            drawer: Drawer::new(&gpu.device, config.format, Output::Display),
            depth: depth_texture(&gpu.device, config.width, config.height),
            config,
            surface,
            gpu,
            window,
        })
    }

    fn resize(&mut self, size: PhysicalSize<u32>) {
        self.config.width = size.width.max(1);
        self.config.height = size.height.max(1);
        self.surface.configure(&self.gpu.device, &self.config);
        self.depth = depth_texture(&self.gpu.device, self.config.width, self.config.height);
    }

    fn size(&self) -> (u32, u32) {
        (self.config.width, self.config.height)
    }
}

/// Keys held, and keys pressed since the last frame (a tap shorter than a frame still moves).
#[derive(Default)]
struct Keys {
    held: HashSet<KeyCode>,
    tapped: HashSet<KeyCode>,
}

impl Keys {
    fn down(&self, codes: &[KeyCode]) -> bool {
        codes
            .iter()
            .any(|c| self.held.contains(c) || self.tapped.contains(c))
    }

    fn axis(&self, plus: &[KeyCode], minus: &[KeyCode]) -> f32 {
        f32::from(u8::from(self.down(plus))) - f32::from(u8::from(self.down(minus)))
    }

    fn moving(&self) -> bool {
        !self.held.is_empty() || !self.tapped.is_empty()
    }

    /// Moves the camera for one frame of `dt_s` seconds.
    fn steer(&self, walk: &mut WalkCamera, dt_s: f32) {
        use KeyCode::*;
        let forward = self.axis(&[KeyW, ArrowUp], &[KeyS, ArrowDown]);
        let right = self.axis(&[KeyD], &[KeyA]);
        let rise = self.axis(&[KeyE], &[KeyQ]);
        walk.walk(forward, right, rise, dt_s);
        let turn = self.axis(&[ArrowLeft], &[ArrowRight]);
        if turn != 0.0 {
            walk.turn(turn * TURN_RAD_PER_S * dt_s, 0.0);
        }
    }
}

struct App {
    config: ViewerConfig,
    link: Link,
    events: EventQueue,
    state: ViewState,
    display: Option<Display>,
    walk: Option<WalkCamera>,
    sender: CameraSender,
    keys: Keys,
    settings: DrawSettings,
    /// The criterion this viewer asked for, if any, and whether it paused refinement.
    criterion: Option<String>,
    paused: bool,
    panel: bool,
    fps: f64,
    progress: ProgressPrinter,
    /// Left button held: mouse look.
    dragging: bool,
    cursor: Option<PhysicalPosition<f64>>,
    last_frame: Instant,
    frames: u32,
    title_at: Instant,
    /// A frame was drawn since the window last settled ([`SETTLED`]).
    drawn: bool,
    failure: Option<anyhow::Error>,
}

impl App {
    fn new(config: ViewerConfig, link: Link, events: EventQueue) -> App {
        let now = Instant::now();
        App {
            settings: DrawSettings {
                tone_map: config.tone_map,
                l_white: 1.0,
                wireframe: config.wireframe,
                ..DrawSettings::default()
            },
            criterion: config.criterion.clone(),
            paused: config.no_refine,
            panel: true,
            fps: 0.0,
            progress: ProgressPrinter::new(config.progress),
            config,
            link,
            events,
            state: ViewState::default(),
            display: None,
            walk: None,
            sender: CameraSender::new(DEFAULT_INTERVAL),
            keys: Keys::default(),
            dragging: false,
            cursor: None,
            last_frame: now,
            frames: 0,
            title_at: now,
            drawn: false,
            failure: None,
        }
    }

    fn redraw(&self) {
        if let Some(d) = &self.display {
            d.window.request_redraw();
        }
    }

    /// A new session: the SMA knows nothing of us, so say everything again.
    fn restate(&mut self) {
        let Some(scene) = &self.state.scene else {
            return;
        };
        if self.walk.is_none() {
            let speed = default_speed(&scene.bounds);
            let start = pick_viewpoint(scene, self.config.view.as_deref()).unwrap_or_else(|e| {
                tracing::warn!("{e:#}; starting at the first viewpoint");
                scene.viewpoints.first().cloned()
            });
            self.walk = Some(match start {
                Some(vp) => WalkCamera::at_viewpoint(&vp, speed),
                None => WalkCamera::overlooking(&scene.bounds, speed),
            });
        }
        if let (Some(walk), Some(d)) = (&self.walk, &self.display) {
            let (w, h) = d.size();
            let camera = self.sender.force(&walk.camera(w, h), Instant::now());
            self.state.direct.follow(&camera);
            self.link.send(ViewerToSma::Camera(camera));
        }
        for msg in preferences(self.criterion.as_deref(), self.paused) {
            self.link.send(msg);
        }
    }

    fn offer_camera(&mut self) {
        if let (Some(walk), Some(d)) = (&self.walk, &self.display) {
            let (w, h) = d.size();
            if let Some(camera) = self.sender.offer(&walk.camera(w, h), Instant::now()) {
                self.state.direct.follow(&camera);
                self.link.send(ViewerToSma::Camera(camera));
            }
        }
    }

    fn key_pressed(&mut self, code: KeyCode, event_loop: &ActiveEventLoop) {
        const DIGITS: [KeyCode; 9] = [
            KeyCode::Digit1,
            KeyCode::Digit2,
            KeyCode::Digit3,
            KeyCode::Digit4,
            KeyCode::Digit5,
            KeyCode::Digit6,
            KeyCode::Digit7,
            KeyCode::Digit8,
            KeyCode::Digit9,
        ];
        let action = match code {
            KeyCode::Escape => {
                event_loop.exit();
                None
            }
            KeyCode::KeyC => {
                let scene = self.state.scene.as_ref();
                let current = self.state.refinement.as_ref().map(|(c, _)| c.as_str());
                scene
                    .and_then(|s| next_criterion(s, current))
                    .map(Action::Criterion)
            }
            KeyCode::KeyP => Some(Action::Pause(!self.paused)),
            KeyCode::KeyF => Some(Action::Wireframe(!self.settings.wireframe)),
            KeyCode::KeyT => Some(Action::ToneMap(self.settings.tone_map.next())),
            KeyCode::KeyH => {
                self.panel = !self.panel;
                None
            }
            KeyCode::Equal | KeyCode::NumpadAdd | KeyCode::PageUp => {
                self.scale_speed(SPEED_STEP);
                None
            }
            KeyCode::Minus | KeyCode::NumpadSubtract | KeyCode::PageDown => {
                self.scale_speed(1.0 / SPEED_STEP);
                None
            }
            _ => DIGITS
                .iter()
                .position(|&d| d == code)
                .map(Action::Viewpoint),
        };
        if let Some(action) = action {
            self.apply(action);
        }
    }

    /// What a key or a click on the panel asks for.
    fn apply(&mut self, action: Action) {
        match action {
            Action::Viewpoint(i) => {
                let viewpoint = self.state.scene.as_ref().and_then(|s| s.viewpoints.get(i));
                if let (Some(vp), Some(walk)) = (viewpoint, self.walk.as_mut()) {
                    *walk = WalkCamera::at_viewpoint(vp, walk.speed);
                    tracing::debug!(viewpoint = %vp.name, "jumped");
                }
            }
            Action::Criterion(name) => {
                self.link
                    .send(ViewerToSma::SetCriterion { name: name.clone() });
                self.criterion = Some(name);
            }
            Action::Pause(paused) => {
                self.paused = paused;
                self.link.send(if paused {
                    ViewerToSma::Pause
                } else {
                    ViewerToSma::Resume
                });
            }
            Action::Wireframe(on) => self.settings.wireframe = on,
            Action::ToneMap(op) => self.settings.tone_map = op,
        }
        self.redraw();
    }

    fn scale_speed(&mut self, factor: f32) {
        if let Some(walk) = &mut self.walk {
            walk.speed *= factor;
        }
    }

    fn frame(&mut self) {
        let now = Instant::now();
        let dt = now
            .duration_since(self.last_frame)
            .as_secs_f32()
            .min(MAX_FRAME_S);
        self.last_frame = now;
        if let Some(walk) = &mut self.walk {
            self.keys.steer(walk, dt);
        }
        self.keys.tapped.clear();
        self.offer_camera();
        let (Some(d), Some(walk)) = (&mut self.display, &self.walk) else {
            return;
        };
        let upload = d.triangles.sync(&d.gpu, &mut self.state.table);
        tracing::trace!(?upload, "frame upload");
        d.direct.sync(&d.gpu, &mut self.state.direct);
        d.looks.sync(&d.gpu, &self.state.looks);
        let texture = match d.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                d.surface.configure(&d.gpu.device, &d.config);
                d.window.request_redraw();
                return;
            }
            other => {
                tracing::debug!("no frame this time: {other:?}");
                return;
            }
        };
        let view = texture.texture.create_view(&Default::default());
        let (w, h) = d.size();
        let camera = walk.camera(w, h);
        self.settings.l_white = self.state.l_white;
        self.settings.sky = self.state.sky();
        let depth = depth_range(&camera, self.state.table.extent());
        let mut encoder = d.gpu.device.create_command_encoder(&Default::default());
        d.drawer.draw(
            &d.gpu.queue,
            &mut encoder,
            &view,
            &d.depth,
            &d.triangles,
            (
                self.state.direct.shown_for(&camera).then_some(&d.direct),
                &d.looks,
            ),
            &camera,
            depth,
            &self.settings,
        );
        let actions = if self.panel {
            let facts = Facts {
                fps: self.fps,
                paused: self.paused,
                tone_map: self.settings.tone_map,
                wireframe: self.settings.wireframe,
                texture_bytes: Some(d.looks.bytes()),
                ..Facts::of(&self.state, &self.config.connect)
            };
            let gpu = (&d.gpu.device, &d.gpu.queue);
            d.overlay.draw(gpu, &mut encoder, &view, &facts)
        } else {
            Vec::new()
        };
        d.gpu.queue.submit([encoder.finish()]);
        d.gpu.queue.present(texture);
        self.frames += 1;
        self.drawn = true;
        for action in actions {
            self.apply(action);
        }
    }

    fn update_title(&mut self) {
        let elapsed = self.title_at.elapsed();
        let Some(d) = &self.display else { return };
        if elapsed < TITLE_EVERY {
            return;
        }
        let fps = self.frames as f64 / elapsed.as_secs_f64();
        self.fps = fps;
        (self.frames, self.title_at) = (0, Instant::now());
        let title = match (&self.state.scene, self.state.connected) {
            (Some(scene), true) => {
                let (criterion, paused) = self
                    .state
                    .refinement
                    .clone()
                    .unwrap_or_else(|| ("?".into(), self.paused));
                format!(
                    "{TITLE} — {} | {} triangles | {:.0} samples/s | {fps:.1} fps | {criterion}{}",
                    scene.name,
                    self.state.table.len(),
                    self.state.stats.samples_per_sec,
                    if paused { " (paused)" } else { "" }
                )
            }
            _ => format!("{TITLE} — connecting to {}…", self.config.connect),
        };
        d.window.set_title(&title);
    }
}

impl ApplicationHandler<LinkWoke> for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.display.is_some() {
            return;
        }
        match Display::open(event_loop, &self.config).context("opening the window") {
            Ok(display) => {
                self.display = Some(display);
                self.restate();
            }
            Err(e) => {
                self.failure = Some(e);
                event_loop.exit();
            }
        }
    }

    fn user_event(&mut self, _: &ActiveEventLoop, _: LinkWoke) {
        self.events.woken();
        while let Ok(event) = self.events.receiver.try_recv() {
            match self.state.handle(event) {
                Reaction::Resend => self.restate(),
                Reaction::Drawn(_) | Reaction::Tile | Reaction::Nothing => {}
            }
        }
        self.redraw();
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        let panel = match &mut self.display {
            Some(d) if self.panel => d.overlay.on_event(&event),
            _ => egui_winit::EventResponse::default(),
        };
        if panel.repaint && !matches!(event, WindowEvent::RedrawRequested) {
            self.redraw();
        }
        if panel.consumed {
            // A click or a hover on the panel: do not steer with it.
            if !matches!(
                event,
                WindowEvent::KeyboardInput { .. } | WindowEvent::RedrawRequested
            ) {
                return;
            }
        }
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let Some(d) = &mut self.display {
                    d.resize(size);
                }
                self.redraw();
            }
            WindowEvent::KeyboardInput { event, .. } => {
                let PhysicalKey::Code(code) = event.physical_key else {
                    return;
                };
                match event.state {
                    ElementState::Pressed if !event.repeat => {
                        self.keys.held.insert(code);
                        self.keys.tapped.insert(code);
                        self.key_pressed(code, event_loop);
                    }
                    ElementState::Pressed => {}
                    ElementState::Released => {
                        self.keys.held.remove(&code);
                    }
                }
                self.redraw();
            }
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                self.dragging = state == ElementState::Pressed;
            }
            WindowEvent::CursorMoved { position, .. } => {
                let last = self.cursor.replace(position);
                if let (true, Some(last), Some(walk)) = (self.dragging, last, &mut self.walk) {
                    let (dx, dy) = (position.x - last.x, position.y - last.y);
                    walk.turn(
                        -dx as f32 * LOOK_RAD_PER_PIXEL,
                        -dy as f32 * LOOK_RAD_PER_PIXEL,
                    );
                    self.redraw();
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let up = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y > 0.0,
                    MouseScrollDelta::PixelDelta(p) => p.y > 0.0,
                };
                self.scale_speed(if up { SPEED_STEP } else { 1.0 / SPEED_STEP });
            }
            WindowEvent::RedrawRequested => self.frame(),
            _ => {}
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        let panel_busy = self.panel
            && self
                .display
                .as_ref()
                .is_some_and(|d| d.overlay.wants_repaint());
        if self.keys.moving() || panel_busy {
            self.redraw();
        } else if std::mem::take(&mut self.drawn) {
            tracing::debug!(panel = self.panel, "{SETTLED}");
        }
        // A camera change held back by the rate limit goes out on one of these wake-ups.
        self.offer_camera();
        self.update_title();
        self.progress.tick(&self.state);
        event_loop.set_control_flow(ControlFlow::WaitUntil(Instant::now() + DEFAULT_INTERVAL));
    }
}
