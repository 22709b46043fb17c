//! The on-screen panel (egui): what the system is doing, the keys, and buttons for what the keys
//! do. It only reads the viewer's state and answers with [`Action`]s; the window applies them
//! exactly as it applies key presses.

use egui::{Rect, pos2, vec2};
use protocol::viewer_link::SmaMemory;

use crate::ToneMap;
use crate::view_state::{Activity, ViewState};

/// Panel width and inner margin, in points.
pub const WIDTH: f32 = 230.0;
const MARGIN: f32 = 8.0;
/// Viewpoint buttons: a grid at the top of the panel, so their places are known (the window test
/// clicks them).
const BUTTON_SIZE: [f32; 2] = [104.0, 24.0];
const BUTTON_GAP: f32 = 6.0;
const BUTTONS_PER_ROW: usize = 2;

/// The keys, as the panel lists them.
pub const KEYS: &[(&str, &str)] = &[
    ("W A S D / arrows", "walk, strafe, turn"),
    ("Q / E", "sink / rise"),
    ("drag", "look around"),
    ("+ / - / wheel", "walking speed"),
    ("1–9", "viewpoints"),
    ("C", "next criterion"),
    ("P", "pause / resume refinement"),
    ("T", "tone map"),
    ("F", "wireframe"),
    ("H", "hide / show this panel"),
    ("Esc", "quit"),
];

/// Where viewpoint button `index` lies, in points from the window's top-left corner.
pub fn viewpoint_button(index: usize) -> Rect {
    let (row, col) = (index / BUTTONS_PER_ROW, index % BUTTONS_PER_ROW);
    let [w, h] = BUTTON_SIZE;
    Rect::from_min_size(
        pos2(
            MARGIN + col as f32 * (w + BUTTON_GAP),
            MARGIN + row as f32 * (h + BUTTON_GAP),
        ),
        vec2(w, h),
    )
}

/// What the panel shows, taken from the viewer's state for one frame. It owns its text, so a
/// headless snapshot can carry it to the thread that draws it.
#[derive(Clone, Debug)]
pub struct Facts {
    pub scene: Option<String>,
    pub sma: String,
    pub activity: Activity,
    pub samples: u64,
    pub samples_per_sec: f32,
    pub shown: usize,
    /// Paths per sample and bounce depth, as the scene asks for them.
    pub quality: Option<String>,
    pub fps: f64,
    pub renderers: u32,
    /// The SMA's own memory by part, as its latest `Stats` said.
    pub sma_memory: SmaMemory,
    pub viewpoints: Vec<String>,
    pub criteria: Vec<String>,
    pub criterion: Option<String>,
    pub tone_map: ToneMap,
    pub wireframe: bool,
    pub paused: bool,
}

impl Facts {
    /// The facts of the viewer's state; the front end's own (fps, its switches) are the
    /// caller's to fill in.
    pub fn of(state: &ViewState, sma: &str) -> Facts {
        let scene = state.scene.as_ref();
        let quality = scene.map(|s| match s.quality.bounces {
            Some(b) => format!("{} paths, {b} bounces", s.quality.paths),
            None => format!("{} paths, unbounded", s.quality.paths),
        });
        Facts {
            scene: scene.map(|s| s.name.clone()),
            sma: if state.connected {
                sma
            } else {
                "connecting…"
            }
            .to_string(),
            activity: state.activity(),
            samples: state.epoch.map_or(0, |e| e.samples),
            samples_per_sec: state.stats.samples_per_sec,
            shown: state.table.len(),
            quality,
            fps: 0.0,
            renderers: state.stats.renderers,
            sma_memory: state.stats.memory,
            viewpoints: scene.map_or(Vec::new(), |s| {
                s.viewpoints.iter().map(|v| v.name.clone()).collect()
            }),
            criteria: scene.map_or(Vec::new(), |s| s.criteria.clone()),
            criterion: state.refinement.as_ref().map(|(c, _)| c.clone()),
            tone_map: crate::ToneMap::default(),
            wireframe: false,
            paused: false,
        }
    }
}

/// What a click asks for.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    Viewpoint(usize),
    Criterion(String),
    ToneMap(ToneMap),
    Wireframe(bool),
    Pause(bool),
}

/// Lays the panel out for one frame and returns the clicks.
pub fn show(ui: &mut egui::Ui, facts: &Facts) -> Vec<Action> {
    let mut actions = Vec::new();
    let frame = egui::Frame::side_top_panel(ui.style()).inner_margin(MARGIN);
    egui::Panel::left("status")
        .exact_size(WIDTH)
        .resizable(false)
        .frame(frame)
        .show(ui, |ui| {
            viewpoints(ui, facts, &mut actions);
            ui.separator();
            status(ui, facts);
            ui.separator();
            controls(ui, facts, &mut actions);
            ui.separator();
            keys(ui);
        });
    actions
}

fn viewpoints(ui: &mut egui::Ui, facts: &Facts, actions: &mut Vec<Action>) {
    let rows = facts.viewpoints.len().div_ceil(BUTTONS_PER_ROW);
    let height = rows as f32 * (BUTTON_SIZE[1] + BUTTON_GAP);
    ui.allocate_space(vec2(WIDTH - 2.0 * MARGIN, height));
    for (i, name) in facts.viewpoints.iter().enumerate() {
        let label = match i {
            0..9 => format!("{} {name}", i + 1),
            _ => name.to_string(),
        };
        if ui
            .put(viewpoint_button(i), egui::Button::new(label))
            .clicked()
        {
            actions.push(Action::Viewpoint(i));
        }
    }
}

fn status(ui: &mut egui::Ui, facts: &Facts) {
    egui::Grid::new("facts").num_columns(2).show(ui, |ui| {
        let mut row = |name: &str, value: String| {
            ui.label(name);
            ui.strong(value);
            ui.end_row();
        };
        row("scene", facts.scene.as_deref().unwrap_or("—").to_string());
        row("state", facts.activity.to_string());
        row("samples", facts.samples.to_string());
        row("samples/s", format!("{:.0}", facts.samples_per_sec));
        row("triangles shown", facts.shown.to_string());
        row(
            "criterion",
            facts.criterion.as_deref().unwrap_or("—").to_string(),
        );
        row(
            "quality",
            facts.quality.clone().unwrap_or_else(|| "—".to_string()),
        );
        row("fps", format!("{:.1}", facts.fps));
        row("SMA", facts.sma.to_string());
        row("renderers", facts.renderers.to_string());
        let [total, mesh, cache] = memory_mib(facts.sma_memory);
        row("SMA memory", format!("{total:.1} MiB"));
        row("mesh / cache", format!("{mesh:.1} / {cache:.1} MiB"));
    });
}

/// The SMA's memory in MiB: in all, its mesh, its cache.
fn memory_mib(m: SmaMemory) -> [f64; 3] {
    [m.mesh_bytes + m.cache_bytes, m.mesh_bytes, m.cache_bytes]
        .map(|bytes| bytes as f64 / f64::from(1 << 20))
}

fn controls(ui: &mut egui::Ui, facts: &Facts, actions: &mut Vec<Action>) {
    ui.label("criterion");
    ui.horizontal_wrapped(|ui| {
        for name in &facts.criteria {
            let active = facts.criterion.as_deref() == Some(name.as_str());
            if ui.selectable_label(active, name).clicked() && !active {
                actions.push(Action::Criterion(name.clone()));
            }
        }
    });
    ui.horizontal(|ui| {
        ui.label("tone map");
        for op in [ToneMap::Drago, ToneMap::Reinhard] {
            if ui
                .selectable_label(facts.tone_map == op, op.name())
                .clicked()
            {
                actions.push(Action::ToneMap(op));
            }
        }
    });
    let mut wireframe = facts.wireframe;
    if ui.checkbox(&mut wireframe, "wireframe").changed() {
        actions.push(Action::Wireframe(wireframe));
    }
    let mut paused = facts.paused;
    if ui.checkbox(&mut paused, "pause refinement").changed() {
        actions.push(Action::Pause(paused));
    }
}

fn keys(ui: &mut egui::Ui) {
    egui::Grid::new("keys").num_columns(2).show(ui, |ui| {
        for (key, what) in KEYS {
            ui.monospace(*key);
            ui.small(*what);
            ui.end_row();
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn viewpoint_buttons_fill_rows_of_two_inside_the_panel_without_overlapping() {
        let rects: Vec<Rect> = (0..5).map(viewpoint_button).collect();
        assert_eq!(rects[0].min, pos2(MARGIN, MARGIN));
        assert_eq!(rects[1].top(), rects[0].top());
        assert!(rects[2].top() > rects[0].bottom());
        for (i, a) in rects.iter().enumerate() {
            assert!(a.right() <= WIDTH - MARGIN, "button {i} leaves the panel");
            for b in &rects[i + 1..] {
                assert!(!a.intersects(*b));
            }
        }
    }
}
