//! The per-pixel competitor of `bench walk`: what a progressive path-tracing viewport does. The
//! project's renderer traces the current camera per pixel (`renderer::reference::render`, one path
//! per pixel a frame, the interactive depth, on every core through rayon), averages its frames
//! while the camera stays, and starts again whenever the camera changes. What it shows at an
//! instant is its last completed average: while walking a frame of one path per pixel, rendered
//! for the camera of a moment before; at a stop an average that keeps improving. It follows the
//! same path in real time as the system's headless viewer does, alone on the machine.

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use renderer::reference::{ReferenceSettings, render};

use super::route::{WalkCamera, WalkPlan};
use super::truths::Scene;
use crate::convergence::INTERACTIVE_BOUNCES;
use crate::metrics::LinearImage;

/// What the viewport showed at each asked time, and how many frames it completed.
pub(crate) struct ViewportRun {
    /// Per asked time (in order): the frame shown, and how many frames it averages.
    pub shown: Vec<(Arc<LinearImage>, u32)>,
    /// Frames completed, in all and while walking.
    pub frames: u64,
    pub walking_frames: u64,
    /// Seconds the walk took (its length) and of those, walking.
    pub seconds: f64,
    pub walking_seconds: f64,
}

impl ViewportRun {
    pub fn frames_per_second(&self) -> f64 {
        self.frames as f64 / self.seconds.max(1e-9)
    }

    pub fn walking_frames_per_second(&self) -> f64 {
        self.walking_frames as f64 / self.walking_seconds.max(1e-9)
    }
}

/// The running average of one camera's frames.
struct Average {
    camera: WalkCamera,
    sum: Vec<Vec3>,
    covered: Vec<bool>,
    frames: u32,
}

impl Average {
    fn image(&self, width: u32, height: u32) -> LinearImage {
        let n = self.frames.max(1) as f32;
        LinearImage {
            width,
            height,
            rgb: self.sum.iter().map(|p| (*p / n).to_array()).collect(),
            alpha: Some(
                self.covered
                    .iter()
                    .map(|&c| f32::from(u8::from(c)))
                    .collect(),
            ),
        }
    }
}

/// Follows `plan` in real time from now, showing frames of `width`×`height`; records what is
/// shown at each of `at` (seconds, ascending).
pub(crate) fn follow(
    scene: &Scene,
    plan: &WalkPlan,
    at: &[f64],
    width: u32,
    height: u32,
) -> ViewportRun {
    let blank = Arc::new(LinearImage {
        width,
        height,
        rgb: vec![[0.0; 3]; (width * height) as usize],
        alpha: None,
    });
    let mut shown_now: (Arc<LinearImage>, u32) = (blank, 0);
    let mut shown = Vec::with_capacity(at.len());
    let mut average: Option<Average> = None;
    let (mut frames, mut walking_frames) = (0u64, 0u64);
    let started = Instant::now();
    loop {
        let t = started.elapsed().as_secs_f64();
        if t >= plan.seconds() {
            break;
        }
        let camera = plan.camera_at(t);
        let same = |a: &Average| (a.camera.eye, a.camera.target) == (camera.eye, camera.target);
        if !average.as_ref().is_some_and(same) {
            average = None;
        }
        let settings = ReferenceSettings {
            width,
            height,
            spp: 1,
            bounces: Some(INTERACTIVE_BOUNCES),
            // A stream of its own per frame; none is the ground truth's (seed 1).
            seed: 1_000 + frames,
        };
        let (image, _) = render(
            &scene.world,
            &scene.camera(&camera, width, height),
            &settings,
            None,
        );
        let done = started.elapsed().as_secs_f64();
        // The times that passed while this frame was traced saw the frame before it.
        while shown.len() < at.len() && at[shown.len()] <= done {
            shown.push(shown_now.clone());
        }
        let avg = average.get_or_insert_with(|| Average {
            camera,
            sum: vec![Vec3::ZERO; image.pixels.len()],
            covered: vec![false; image.pixels.len()],
            frames: 0,
        });
        for ((s, c), (p, hit)) in avg
            .sum
            .iter_mut()
            .zip(avg.covered.iter_mut())
            .zip(image.pixels.iter().zip(&image.covered))
        {
            *s += *p;
            *c |= *hit;
        }
        avg.frames += 1;
        shown_now = (Arc::new(avg.image(width, height)), avg.frames);
        frames += 1;
        if plan.walking_at(camera.step) {
            walking_frames += 1;
        }
    }
    while shown.len() < at.len() {
        shown.push(shown_now.clone());
    }
    let walking_steps = (0..plan.steps()).filter(|&k| plan.walking_at(k)).count();
    ViewportRun {
        shown,
        frames,
        walking_frames,
        seconds: plan.seconds(),
        walking_seconds: walking_steps as f64 / super::route::STEPS_PER_SECOND,
    }
}
