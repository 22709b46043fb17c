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
    /// Bytes the scene's textures and material table take on this viewer's GPU, where the
    /// front end knows them (the window's own).
    pub texture_bytes: Option<u64>,
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
            texture_bytes: None,
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
        for (name, value) in memory_rows(&facts.sma_memory) {
            row(name, value);
        }
        if let Some(bytes) = facts.texture_bytes {
            row(
                "textures on GPU",
                format!("{:.1} MiB", bytes as f64 / f64::from(1 << 20)),
            );
        }
    });
}

/// The SMA's memory as the panel's rows: accounted against the budget (and whether the budget
/// stopped refinement), the parts, the process's resident memory.
fn memory_rows(m: &SmaMemory) -> Vec<(&'static str, String)> {
    let mib = |bytes: u64| bytes as f64 / f64::from(1 << 20);
    let bound = if m.memory_bound { ", memory-bound" } else { "" };
    vec![
        (
            "SMA memory",
            format!(
                "{:.1} of {:.0} MiB{bound}",
                mib(m.accounted_bytes()),
                mib(m.budget_bytes)
            ),
        ),
        (
            "mesh / cache / viewers",
            format!(
                "{:.1} / {:.1} / {:.1} MiB",
                mib(m.mesh_bytes()),
                mib(m.cache_bytes),
                mib(m.viewers_bytes)
            ),
        ),
        (
            "SMA resident",
            m.rss_bytes
                .map_or("—".to_string(), |b| format!("{:.1} MiB", mib(b))),
        ),
    ]
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

    #[test]
    fn memory_rows_say_the_accounted_total_against_the_budget_and_when_it_binds() {
        let m = SmaMemory {
            nodes_bytes: 1 << 20,
            vertices_bytes: 1 << 20,
            edge_tables_bytes: 0,
            cache_bytes: 4 << 20,
            viewers_bytes: 2 << 20,
            budget_bytes: 16 << 20,
            rss_bytes: None,
            memory_bound: false,
        };
        let rows = memory_rows(&m);
        assert_eq!(rows[0].1, "8.0 of 16 MiB");
        assert_eq!(rows[1].1, "2.0 / 4.0 / 2.0 MiB");
        assert_eq!(rows[2].1, "—");
        let bound = memory_rows(&SmaMemory {
            memory_bound: true,
            rss_bytes: Some(100 << 20),
            ..m
        });
        assert_eq!(bound[0].1, "8.0 of 16 MiB, memory-bound");
        assert_eq!(bound[2].1, "100.0 MiB");
    }
}
