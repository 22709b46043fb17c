//! The scripted walks of `bench walk`: per scene a route of waypoints and stops, turned into the
//! viewer's `--camera-path` keyframes at 30 camera steps a second. A person walks at about
//! 1.4 m/s with the eyes at 1.7 m, looks ahead along the way with slow head turns to either side,
//! turns towards what a stop is for during the last second and a half before it, holds the camera
//! still for the stop (2–10 s) and turns back to the way ahead once walking on. The route is walked
//! twice: the second pass starts again from the first waypoint (a cut where the route does not
//! end where it began) and repeats the first step for step, so that its stops and moments have
//! the first pass's cameras.

use std::fmt::Write as _;

use glam::{Vec3, vec3};

/// Camera steps a second (the path's keyframes while walking).
pub(crate) const STEPS_PER_SECOND: f64 = 30.0;
/// Walking speed, m/s (each stretch between waypoints is rounded to whole steps).
pub(crate) const WALKING_SPEED: f32 = 1.4;
const EYE_HEIGHT: f32 = 1.7;
/// How long the head takes to turn towards a stop's subject, and back to the way ahead.
const TURN_S: f32 = 1.5;
/// Head turns while walking: the gaze swings this far to either side of the way ahead…
const GLANCE_DEG: f32 = 20.0;
/// …once every this many seconds of walking.
const GLANCE_PERIOD_S: f32 = 7.0;
/// While walking the eyes look this far below the horizon (the ground a few metres ahead).
const WALKING_PITCH_DEG: f32 = -4.0;
/// A move between two steps longer than this is a cut (the second pass's start).
const CUT_M: f32 = 1.0;
/// Passes over the route.
pub(crate) const PASSES: u32 = 2;

/// One part of a route.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Leg {
    /// Walk in a straight line to (x, z), at eye height.
    To(f32, f32),
    /// Stand still where the last leg ended, looking at `look_at`, for `seconds`.
    Stop {
        look_at: [f32; 3],
        seconds: f32,
        what: &'static str,
    },
}

/// A scene's walk: where it starts (x, z) and its legs.
#[derive(Clone, Debug)]
pub(crate) struct Route {
    /// The scene's name (the path file is `<name>.path`).
    pub scene: &'static str,
    pub start: (f32, f32),
    pub legs: Vec<Leg>,
    pub fov_y_deg: f32,
}

impl Route {
    /// A short walk for smoke runs: the first stop, a few metres of the first stretch, and a
    /// stop at its end looking at the second stop's subject; stops of `stop_s`.
    pub(crate) fn quick(&self, metres: f32, stop_s: f32) -> Route {
        let stops: Vec<&Leg> = self
            .legs
            .iter()
            .filter(|l| matches!(l, Leg::Stop { .. }))
            .collect();
        let first_to = self
            .legs
            .iter()
            .find_map(|l| match l {
                Leg::To(x, z) => Some((*x, *z)),
                Leg::Stop { .. } => None,
            })
            .unwrap_or(self.start);
        let (from, to) = (flat(self.start), flat(first_to));
        let end = from + (to - from).normalize_or_zero() * metres.min(from.distance(to));
        let shorten = |leg: &Leg| match *leg {
            Leg::Stop { look_at, what, .. } => Leg::Stop {
                look_at,
                seconds: stop_s,
                what,
            },
            Leg::To(..) => *leg,
        };
        let mut legs = vec![shorten(stops[0]), Leg::To(end.x, end.z)];
        legs.extend(stops.get(1).copied().map(shorten));
        Route {
            scene: self.scene,
            start: self.start,
            legs,
            fov_y_deg: self.fov_y_deg,
        }
    }

    /// The route up to its `n`th stop, that stop included: a shorter walk whose stops have the
    /// whole route's cameras (a reproduction of what the whole walk shows at its first stops).
    pub(crate) fn first_stops(&self, n: usize) -> Route {
        let mut seen = 0;
        let end = self
            .legs
            .iter()
            .position(|l| {
                seen += usize::from(matches!(l, Leg::Stop { .. }));
                seen == n
            })
            .map_or(self.legs.len(), |i| i + 1);
        Route {
            legs: self.legs[..end].to_vec(),
            ..self.clone()
        }
    }
}

fn flat((x, z): (f32, f32)) -> Vec3 {
    vec3(x, EYE_HEIGHT, z)
}

/// A camera of the walk: eye and target (mm), at a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct WalkCamera {
    pub step: usize,
    pub eye: Vec3,
    pub target: Vec3,
}

impl WalkCamera {
    pub fn time_s(&self) -> f64 {
        self.step as f64 / STEPS_PER_SECOND
    }
}

/// A stop of one pass: the camera holds from `start` for `steps` steps.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct StopPlan {
    /// 1 or 2.
    pub pass: u32,
    /// The stop's number on the route, from 1.
    pub number: usize,
    pub what: &'static str,
    pub camera: WalkCamera,
    pub steps: usize,
}

impl StopPlan {
    pub fn start_s(&self) -> f64 {
        self.camera.time_s()
    }

    pub fn seconds(&self) -> f64 {
        self.steps as f64 / STEPS_PER_SECOND
    }
}

/// A moment while walking at which the picture shown is judged.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct MomentPlan {
    pub pass: u32,
    /// The moment's number within its pass, from 1 (the same on both passes).
    pub number: usize,
    pub camera: WalkCamera,
}

/// The walk, generated: every step's camera, the stops and the moments.
#[derive(Clone, Debug)]
pub(crate) struct WalkPlan {
    pub scene: &'static str,
    pub fov_y_deg: f32,
    /// One camera per step, both passes.
    pub cameras: Vec<WalkCamera>,
    /// Whether each step of a pass is a walking one (not at a stop).
    walking: Vec<bool>,
    pub steps_per_pass: usize,
    pub stops: Vec<StopPlan>,
    pub moments: Vec<MomentPlan>,
}

/// A stretch of one pass, in whole steps.
enum Phase {
    Walk {
        from: Vec3,
        to: Vec3,
        steps: usize,
    },
    Hold {
        at: Vec3,
        look_at: Vec3,
        steps: usize,
    },
}

impl Phase {
    fn steps(&self) -> usize {
        match self {
            Phase::Walk { steps, .. } | Phase::Hold { steps, .. } => *steps,
        }
    }
}

fn phases(route: &Route) -> (Vec<Phase>, Vec<&'static str>) {
    let mut at = flat(route.start);
    let mut phases = Vec::new();
    let mut names = Vec::new();
    for leg in &route.legs {
        match *leg {
            Leg::To(x, z) => {
                let to = flat((x, z));
                let steps = (at.distance(to) / WALKING_SPEED * STEPS_PER_SECOND as f32).round();
                phases.push(Phase::Walk {
                    from: at,
                    to,
                    steps: (steps as usize).max(1),
                });
                at = to;
            }
            Leg::Stop {
                look_at,
                seconds,
                what,
            } => {
                let steps = (seconds * STEPS_PER_SECOND as f32).round() as usize;
                phases.push(Phase::Hold {
                    at,
                    look_at: Vec3::from(look_at),
                    steps: steps.max(1),
                });
                names.push(what);
            }
        }
    }
    (phases, names)
}

/// Yaw (about +Y, 0 towards +Z) and pitch of a direction.
fn angles(d: Vec3) -> (f32, f32) {
    let d = d.normalize_or(Vec3::Z);
    (d.x.atan2(d.z), d.y.clamp(-1.0, 1.0).asin())
}

fn direction(yaw: f32, pitch: f32) -> Vec3 {
    vec3(
        pitch.cos() * yaw.sin(),
        pitch.sin(),
        pitch.cos() * yaw.cos(),
    )
}

/// `a` turned towards `b` by `s` of the shorter way round.
fn turn(a: f32, b: f32, s: f32) -> f32 {
    use std::f32::consts::{PI, TAU};
    let d = (b - a + PI).rem_euclid(TAU) - PI;
    a + d * s
}

fn smoothstep(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// Rounded to the millimetre, as the path file writes it.
fn mm(v: Vec3) -> Vec3 {
    (v * 1000.0).round() / 1000.0
}

/// A stop's subject direction, and the walking seconds to or from it.
type Subject = (Vec3, f32);

/// Where the gaze goes at walking step `k` of a pass (`walked_s`: seconds walked in this pass
/// so far): ahead with a head turn, blended towards the stop before or after within `TURN_S`.
struct Gaze<'a> {
    phases: &'a [Phase],
}

impl Gaze<'_> {
    /// The subject direction of the nearest hold before phase `i` and after it, with the walking
    /// seconds to each.
    fn neighbours(&self, i: usize, s: f32) -> (Option<Subject>, Option<Subject>) {
        let secs = |p: &Phase| p.steps() as f32 / STEPS_PER_SECOND as f32;
        let subject = |p: &Phase| match p {
            Phase::Hold { at, look_at, .. } => Some(*look_at - *at),
            Phase::Walk { .. } => None,
        };
        let here = secs(&self.phases[i]);
        let mut before = None;
        let mut since = here * s;
        for p in self.phases[..i].iter().rev() {
            if let Some(d) = subject(p) {
                before = Some((d, since));
                break;
            }
            since += secs(p);
        }
        let mut after = None;
        let mut until = here * (1.0 - s);
        for p in &self.phases[i + 1..] {
            if let Some(d) = subject(p) {
                after = Some((d, until));
                break;
            }
            until += secs(p);
        }
        (before, after)
    }

    fn look(&self, i: usize, s: f32, ahead: Vec3, walked_s: f32) -> Vec3 {
        let (yaw, _) = angles(ahead);
        let swing = std::f32::consts::TAU * walked_s / GLANCE_PERIOD_S;
        let mut yaw = yaw + GLANCE_DEG.to_radians() * swing.sin();
        let mut pitch = WALKING_PITCH_DEG.to_radians() * (1.0 + 0.5 * (2.0 * swing).cos());
        let (before, after) = self.neighbours(i, s);
        // The nearer stop wins; the one ahead when both are as near.
        let towards = [after, before]
            .into_iter()
            .flatten()
            .map(|(d, secs)| (d, smoothstep(1.0 - secs / TURN_S)))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((subject, w)) = towards {
            let (sy, sp) = angles(subject);
            yaw = turn(yaw, sy, w);
            pitch += (sp - pitch) * w;
        }
        direction(yaw, pitch)
    }
}

/// How far ahead of the eye a walking target is put (the direction is what counts).
const TARGET_DISTANCE: f32 = 10.0;

/// Generates the walk: both passes' cameras, the stops, and `moments` moments per pass spread
/// evenly over the walking steps of the pass.
pub(crate) fn generate(route: &Route, moments: usize) -> WalkPlan {
    let (phases, names) = phases(route);
    let gaze = Gaze { phases: &phases };
    let mut pass = Vec::new();
    let mut walking = Vec::new();
    let mut holds = Vec::new();
    let mut walked = 0usize;
    for (i, phase) in phases.iter().enumerate() {
        match *phase {
            Phase::Walk { from, to, steps } => {
                for k in 0..steps {
                    let s = k as f32 / steps as f32;
                    let eye = from.lerp(to, s);
                    let walked_s = walked as f32 / STEPS_PER_SECOND as f32;
                    let look = gaze.look(i, s, to - from, walked_s);
                    pass.push((mm(eye), mm(eye + look * TARGET_DISTANCE)));
                    walking.push(true);
                    walked += 1;
                }
            }
            Phase::Hold { at, look_at, steps } => {
                holds.push((pass.len(), steps));
                pass.extend(std::iter::repeat_n((mm(at), mm(look_at)), steps));
                walking.extend(std::iter::repeat_n(false, steps));
            }
        }
    }
    let steps_per_pass = pass.len();
    let cameras: Vec<WalkCamera> = (0..PASSES as usize)
        .flat_map(|_| pass.iter())
        .enumerate()
        .map(|(step, &(eye, target))| WalkCamera { step, eye, target })
        .collect();
    let stops = (0..PASSES)
        .flat_map(|p| {
            holds
                .iter()
                .zip(&names)
                .enumerate()
                .map(move |(n, (&(start, steps), &what))| (p, n, start, steps, what))
        })
        .map(|(p, n, start, steps, what)| StopPlan {
            pass: p + 1,
            number: n + 1,
            what,
            camera: cameras[p as usize * steps_per_pass + start],
            steps,
        })
        .collect();
    let walking_steps: Vec<usize> = (0..steps_per_pass).filter(|&k| walking[k]).collect();
    let count = moments.min(walking_steps.len());
    let moments = (0..PASSES)
        .flat_map(|p| (0..count).map(move |m| (p, m)))
        .map(|(p, m)| {
            let k = walking_steps[(2 * m + 1) * walking_steps.len() / (2 * count)];
            MomentPlan {
                pass: p + 1,
                number: m + 1,
                camera: cameras[p as usize * steps_per_pass + k],
            }
        })
        .collect();
    WalkPlan {
        scene: route.scene,
        fov_y_deg: route.fov_y_deg,
        cameras,
        walking,
        steps_per_pass,
        stops,
        moments,
    }
}

impl WalkPlan {
    pub fn steps(&self) -> usize {
        self.cameras.len()
    }

    pub fn seconds(&self) -> f64 {
        self.steps() as f64 / STEPS_PER_SECOND
    }

    /// Whether `step` (of either pass) is a walking one.
    pub fn walking_at(&self, step: usize) -> bool {
        self.walking[step % self.steps_per_pass]
    }

    /// The camera the path gives at `t` seconds (the step in force, held at the end).
    pub fn camera_at(&self, t: f64) -> WalkCamera {
        let step = (t * STEPS_PER_SECOND).floor().max(0.0) as usize;
        self.cameras[step.min(self.cameras.len() - 1)]
    }

    /// The viewer's `--camera-path` text: a keyframe per walking step; a stop is its first and
    /// last step, between which the viewer's interpolation holds the camera.
    pub fn path_text(&self) -> String {
        let mut text = format!(
            "# {} walk for `walkthrough-bench walk`, generated by crates/bench/src/walk/route.rs: \
             do not edit.\n# {} passes of {} camera steps at {} a second ({:.1} s in all), \
             {} stops a pass:\n",
            self.scene,
            PASSES,
            self.steps_per_pass,
            STEPS_PER_SECOND,
            self.seconds(),
            self.stops.len() / PASSES as usize
        );
        for s in self.stops.iter().filter(|s| s.pass == 1) {
            let _ = writeln!(
                text,
                "#   stop {} at {:.2} s for {:.1} s: {}",
                s.number,
                s.start_s(),
                s.seconds(),
                s.what
            );
        }
        text.push_str("# time_s  eye_x eye_y eye_z  target_x target_y target_z  fov_y_deg\n");
        let n = self.cameras.len();
        for (k, c) in self.cameras.iter().enumerate() {
            let held = |j: usize| !self.walking_at(j) && self.cameras[j].eye == c.eye;
            let inside_hold = !self.walking_at(k)
                && k > 0
                && k + 1 < n
                && held(k - 1)
                && held(k + 1)
                && self.cameras[k - 1].target == c.target
                && self.cameras[k + 1].target == c.target;
            if inside_hold {
                continue;
            }
            self.keyframe(&mut text, c.time_s(), c);
            // Where the second pass starts with a cut, the last camera holds until just before
            // it: the viewer's interpolation would sweep across the site within one step.
            let next = k + 1;
            if next == self.steps_per_pass && self.cameras[next].eye.distance(c.eye) > CUT_M {
                self.keyframe(&mut text, next as f64 / STEPS_PER_SECOND - 0.001, c);
            }
        }
        text
    }

    fn keyframe(&self, text: &mut String, t: f64, c: &WalkCamera) {
        let _ = writeln!(
            text,
            "{t:.3} {:.3} {:.3} {:.3} {:.3} {:.3} {:.3} {}",
            c.eye.x, c.eye.y, c.eye.z, c.target.x, c.target.y, c.target.z, self.fov_y_deg
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::walk::sites;

    #[test]
    fn walks_at_walking_speed_and_holds_still_at_the_stops() {
        let plan = generate(&sites::bracara(), 30);
        for w in plan.cameras.windows(2) {
            let moved = w[0].eye.distance(w[1].eye) * STEPS_PER_SECOND as f32;
            let cut = w[1].step == plan.steps_per_pass;
            assert!(cut || moved < 1.6, "{moved} m/s at step {}", w[1].step);
        }
        for stop in &plan.stops {
            let held = &plan.cameras[stop.camera.step..stop.camera.step + stop.steps];
            assert!(
                held.iter()
                    .all(|c| (c.eye, c.target) == (stop.camera.eye, stop.camera.target))
            );
            assert!((2.0..=10.0).contains(&stop.seconds()), "{stop:?}");
        }
        assert_eq!(plan.stops.len(), 16);
        assert!((9_000..11_000).contains(&plan.steps()), "{}", plan.steps());
    }

    #[test]
    fn the_second_pass_repeats_the_first_and_moments_are_while_walking() {
        for route in [sites::bracara(), sites::sponza()] {
            let plan = generate(&route, 30);
            let (first, second) = plan.cameras.split_at(plan.steps_per_pass);
            assert!(
                first
                    .iter()
                    .zip(second)
                    .all(|(a, b)| (a.eye, a.target) == (b.eye, b.target))
            );
            assert_eq!(plan.moments.len(), 60);
            for m in &plan.moments {
                assert!(plan.walking_at(m.camera.step), "{m:?}");
                let twin = plan
                    .moments
                    .iter()
                    .find(|o| o.number == m.number && o.pass != m.pass)
                    .unwrap();
                assert_eq!(
                    (twin.camera.eye, twin.camera.target),
                    (m.camera.eye, m.camera.target)
                );
            }
        }
    }

    #[test]
    fn the_head_turns_towards_a_stop_before_reaching_it() {
        let plan = generate(&sites::bracara(), 30);
        let stop = &plan.stops[2];
        let subject = (stop.camera.target - stop.camera.eye).normalize();
        let look = |step: usize| {
            let c = plan.cameras[step];
            (c.target - c.eye).normalize().dot(subject)
        };
        let far = stop.camera.step - 4 * STEPS_PER_SECOND as usize;
        assert!(look(stop.camera.step - 1) > 0.999 && look(far) < look(stop.camera.step - 20));
    }

    #[test]
    fn the_cut_to_the_second_pass_holds_the_last_camera_until_it() {
        let plan = generate(&sites::bracara(), 30);
        let text = plan.path_text();
        let cut = plan.steps_per_pass as f64 / STEPS_PER_SECOND;
        let keys: Vec<Vec<f64>> = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| l.split(' ').map(|f| f.parse().unwrap()).collect())
            .collect();
        let at = keys.iter().position(|k| k[0] >= cut - 0.0015).unwrap();
        assert_eq!(keys[at][1..], keys[at - 1][1..], "held until the cut");
        assert!(keys[at + 1][0] - keys[at][0] < 0.002);
        let last = plan.cameras[plan.steps_per_pass - 1].eye;
        assert_eq!(keys[at][1], f64::from(last.x));
    }

    #[test]
    fn a_quick_walk_is_short_and_keeps_two_stops() {
        let plan = generate(&sites::bracara().quick(3.0, 1.0), 3);
        assert_eq!(plan.stops.len(), 4);
        assert!(plan.seconds() < 12.0, "{}", plan.seconds());
        assert_eq!(plan.moments.len(), 6);
    }

    #[test]
    fn the_first_stops_of_a_route_are_its_stops_and_end_the_walk() {
        let whole = generate(&sites::bracara(), 0);
        let cut = generate(&sites::bracara().first_stops(2), 0);
        assert_eq!(cut.stops.len(), 2 * PASSES as usize);
        assert_eq!(cut.stops[..2], whole.stops[..2]);
        let last = &cut.stops[1];
        assert_eq!(last.camera.step + last.steps, cut.steps_per_pass);
    }

    #[test]
    fn the_path_text_holds_every_walking_step_and_each_stop_s_ends() {
        let plan = generate(&sites::sponza(), 30);
        let keys = plan
            .path_text()
            .lines()
            .filter(|l| !l.starts_with('#'))
            .count();
        let walking = (0..plan.steps()).filter(|&k| plan.walking_at(k)).count();
        assert!(
            keys >= walking && keys <= walking + 2 * plan.stops.len() + 2,
            "{keys}"
        );
    }
}
