//! Where on a walking viewer's image its next steps look (DESIGN.md §3 step 9: what stays in view
//! is worked on in the order the next steps will see it, the current view first, then ahead
//! along the motion). The plan (`plan`) weighs each visible leaf by its distance on the image
//! from a point, the *focus*: the image's centre for a camera at rest, and for a moving one the
//! point its view will be centred on half a second on, the last step's motion (its turn and its
//! move) continued. Turning right puts the focus right of the centre: what lies left leaves the
//! view first, and what lies right stays longest. Walking straight on keeps it at the centre,
//! where the view grows from; stepping sideways moves it the way of the step, by as much as the
//! surface seen at the centre, at its depth, moves on the image.
//!
//! Only the order of the work changes, never what is asked for: a leaf out of view is never
//! planned, and a new view's missing samples still come before everything else (`need`).

use std::f32::consts::FRAC_PI_2;
use std::time::{Duration, Instant};

use glam::{Quat, Vec3};
use protocol::viewer_link::{CAMERA_INTERVAL, Camera};

use crate::mesh::SubdivisionMesh;
use crate::visibility::LeafView;

/// How far ahead the focus looks: a few steps of a person walking, short enough that the motion
/// of the last step still says where the view goes.
pub const LOOKAHEAD: Duration = Duration::from_millis(500);

/// Two cameras closer in time than this (taken in one turn) count as this far apart, so one
/// quick step does not throw the focus to the image's edge.
const MIN_STEP: Duration = Duration::from_millis(20);

/// The turn continued for the look-ahead is at most a quarter turn.
const MAX_TURN: f32 = FRAC_PI_2;

/// The longest lead a walking camera's view is drawn with (`lead`): a few passes of a large
/// view, no further than the last steps' motion still says where the walker goes.
pub const MAX_LEAD: Duration = Duration::from_millis(600);

/// A lead continues a turn by at most this (half a 60° view's height) and a move by at most
/// this many metres (a walker's pace over [`MAX_LEAD`], and some).
const MAX_LEAD_TURN: f32 = std::f32::consts::FRAC_PI_6;
const MAX_LEAD_MOVE: f32 = 1.5;

/// A step faster than this (m/s, rad/s) is a cut, not a walk (a viewer jumping to a named
/// viewpoint), and one that came after a longer pause than [`MAX_LEAD_STEP`] starts from rest:
/// neither says where the camera goes next, and a view led by either showed what the camera
/// would not see.
const MAX_WALK_SPEED: f32 = 20.0;
const MAX_TURN_RATE: f32 = std::f32::consts::TAU;
const MAX_LEAD_STEP: Duration = Duration::from_millis(500);

/// The last step's motion: the turn from the previous camera's orientation to the current one's
/// (in the world frame), the eye's move, and the step's length in seconds (at least `min_step`).
struct Motion {
    turn: Quat,
    moved: Vec3,
    step_s: f32,
}

impl Motion {
    fn of(
        (previous, previous_at): (&Camera, Instant),
        (current, current_at): (&Camera, Instant),
        min_step: Duration,
    ) -> Motion {
        let (before, now) = (previous.pinhole(), current.pinhole());
        let mut turn = now.rotation * before.rotation.inverse();
        if turn.w < 0.0 {
            turn = -turn;
        }
        let step = current_at
            .saturating_duration_since(previous_at)
            .max(min_step);
        Motion {
            turn,
            moved: now.eye - before.eye,
            step_s: step.as_secs_f32(),
        }
    }

    /// Whether it is a step of someone walking, looking about: not a cut, not a first step
    /// after a pause.
    fn is_walking(&self) -> bool {
        let turned = self.turn.to_axis_angle().1;
        self.step_s <= MAX_LEAD_STEP.as_secs_f32()
            && self.moved.length() <= MAX_WALK_SPEED * self.step_s
            && (!turned.is_finite() || turned <= MAX_TURN_RATE * self.step_s)
    }

    /// The turn continued for `k` steps, at most `max` radians.
    fn turn_for(&self, k: f32, max: f32) -> Quat {
        let (axis, angle) = self.turn.to_axis_angle();
        if angle.is_finite() && angle > 0.0 {
            Quat::from_axis_angle(axis, (angle * k).min(max))
        } else {
            Quat::IDENTITY
        }
    }
}

/// The camera `current` will be `by` from now if it goes on as it went from `previous`: its
/// turn and its move continued (at most [`MAX_LEAD_TURN`] and [`MAX_LEAD_MOVE`]). A walking
/// viewer's view is drawn from it (DESIGN.md §3 step 9): the view reaches the viewer a pass
/// later and is shown until the next one, while the head goes on turning, so a view of the
/// camera as it was left the edge the head turns into black (what leaves the view on the other
/// side the viewer keeps, `shown`). Two cameras read in one turn count as a viewer's
/// [`CAMERA_INTERVAL`] apart; a cut or a first step after a pause is not led.
pub fn lead(previous: (&Camera, Instant), current: (&Camera, Instant), by: Duration) -> Camera {
    let motion = Motion::of(previous, current, CAMERA_INTERVAL);
    if !motion.is_walking() {
        return current.0.clone();
    }
    let k = by.as_secs_f32() / motion.step_s;
    let now = current.0.pinhole();
    let rotation = (motion.turn_for(k, MAX_LEAD_TURN) * now.rotation).normalize();
    let moved = (motion.moved * k).clamp_length_max(MAX_LEAD_MOVE);
    Camera {
        eye: (now.eye + moved).to_array(),
        orientation: rotation.to_array(),
        ..current.0.clone()
    }
}

/// The focus in pixels of `current`, which came at `current_at` after `previous` at
/// `previous_at`, seeing the surface at its image's centre at `depth` along its view direction
/// (None: nothing there; then only the turn moves the focus). On the image: clamped to its
/// border.
pub fn focus(
    previous: (&Camera, Instant),
    current: (&Camera, Instant),
    depth: Option<f32>,
) -> (f32, f32) {
    let motion = Motion::of(previous, current, MIN_STEP);
    let k = LOOKAHEAD.as_secs_f32() / motion.step_s;
    let now = current.0.pinhole();
    let forward = motion.turn_for(k, MAX_TURN) * now.forward();
    // Where the view will be centred, as seen from the current eye.
    let towards = match depth {
        Some(depth) => motion.moved * k + forward * depth,
        None => forward,
    };
    let local = now.rotation.inverse() * towards;
    let (half_h, half_w) = (now.half_height(), now.half_height() * now.aspect());
    let (sx, sy) = if local.z < -1e-6 {
        (local.x / -local.z / half_w, local.y / -local.z / half_h)
    } else {
        // Beside or behind the eye: towards that side, at the border.
        let (sx, sy) = (local.x / half_w, local.y / half_h);
        let far = sx.abs().max(sy.abs());
        if far > 0.0 {
            (sx / far, sy / far)
        } else {
            (0.0, 0.0)
        }
    };
    let (w, h) = (now.width as f32, now.height as f32);
    (
        0.5 * w * (1.0 + sx.clamp(-1.0, 1.0)),
        0.5 * h * (1.0 - sy.clamp(-1.0, 1.0)),
    )
}

/// How far along `camera`'s view direction lies the surface seen at the centre of `view`, if
/// any: a leaf's centroid stands for it.
pub fn centre_depth(view: &LeafView, mesh: &SubdivisionMesh, camera: &Camera) -> Option<f32> {
    let (w, h) = (view.visible.width as usize, view.visible.height as usize);
    let leaf = view.pixel_leaves.get(h / 2 * w + w / 2)?;
    let [a, b, c] = mesh.leaf_positions(leaf);
    let centroid: Vec3 = (a + b + c) / 3.0;
    let depth = (centroid - camera.eye_vec()).dot(camera.pinhole().forward());
    (depth > 0.0).then_some(depth)
}

#[cfg(test)]
mod tests {
    use super::*;
    use conventions::camera::look_rotation;

    const W: u32 = 200;
    const H: u32 = 100;

    fn camera(eye: Vec3, target: Vec3) -> Camera {
        Camera {
            seq: 0,
            eye: eye.to_array(),
            orientation: look_rotation(eye, target, Vec3::Y).to_array(),
            fov_y_deg: 60.0,
            width: W,
            height: H,
        }
    }

    /// The focus after one 33-ms step from `a` to `b`, the surface at `depth`.
    fn after_step(a: &Camera, b: &Camera, depth: Option<f32>) -> (f32, f32) {
        let t0 = Instant::now();
        focus((a, t0), (b, t0 + Duration::from_millis(33)), depth)
    }

    #[test]
    fn at_rest_or_walking_straight_on_the_focus_is_the_centre() {
        let a = camera(Vec3::ZERO, Vec3::NEG_Z);
        let (x, y) = after_step(&a, &a, Some(5.0));
        assert!(
            (x - 100.0).abs() < 1e-3 && (y - 50.0).abs() < 1e-3,
            "{x} {y}"
        );
        let b = camera(Vec3::new(0.0, 0.0, -0.05), Vec3::new(0.0, 0.0, -1.0));
        let (x, y) = after_step(&a, &b, Some(5.0));
        assert!(
            (x - 100.0).abs() < 1e-3 && (y - 50.0).abs() < 1e-3,
            "{x} {y}"
        );
    }

    #[test]
    fn turning_or_stepping_right_puts_the_focus_right_and_no_further_than_the_border() {
        let a = camera(Vec3::ZERO, Vec3::NEG_Z);
        // About 1.7° in 33 ms, some 26° in half a second: right of the centre (x 142 of 200),
        // inside the image.
        let turned = camera(Vec3::ZERO, Vec3::new(0.03, 0.0, -1.0));
        let (x, y) = after_step(&a, &turned, None);
        assert!(x > 130.0 && x < 200.0 && (y - 50.0).abs() < 1e-3, "{x} {y}");
        // A fast turn: at the border, not beyond.
        let fast = camera(Vec3::ZERO, Vec3::new(0.3, 0.0, -1.0));
        assert_eq!(after_step(&a, &fast, None).0, 200.0);
        // Stepping right, looking ahead: right of the centre, more for a nearer surface.
        let stepped = camera(Vec3::new(0.02, 0.0, 0.0), Vec3::new(0.02, 0.0, -1.0));
        let near = after_step(&a, &stepped, Some(1.0)).0;
        let far = after_step(&a, &stepped, Some(10.0)).0;
        assert!(near > far && far > 100.0, "{near} {far}");
        // Turning left, or up: the other way.
        let left = camera(Vec3::ZERO, Vec3::new(-0.03, 0.0, -1.0));
        assert!(after_step(&a, &left, None).0 < 70.0);
        let up = camera(Vec3::ZERO, Vec3::new(0.0, 0.03, -1.0));
        assert!(after_step(&a, &up, None).1 < 25.0);
    }

    fn forward_of(camera: &Camera) -> Vec3 {
        camera.pinhole().forward()
    }

    #[test]
    fn at_rest_the_lead_is_the_camera_and_a_turn_or_a_step_goes_on_the_same_way() {
        let t0 = Instant::now();
        let later = t0 + CAMERA_INTERVAL;
        let a = camera(Vec3::ZERO, Vec3::NEG_Z);
        let still = lead((&a, t0), (&a, later), MAX_LEAD);
        assert!((still.eye_vec() - a.eye_vec()).length() < 1e-6);
        assert!(forward_of(&still).angle_between(forward_of(&a)) < 1e-4);
        // About 1.7° a step to the right: 300 ms on, six steps more, about 10° further right.
        let turned = camera(Vec3::ZERO, Vec3::new(0.03, 0.0, -1.0));
        let led = lead((&a, t0), (&turned, later), Duration::from_millis(300));
        let step = forward_of(&a).angle_between(forward_of(&turned));
        let further = forward_of(&turned).angle_between(forward_of(&led));
        assert!((further / step - 6.0).abs() < 0.1, "{further} after {step}");
        assert!(forward_of(&led).x > forward_of(&turned).x, "to the right");
        assert_eq!((led.width, led.height, led.seq), (W, H, turned.seq));
        // Walking on: 5 cm a step, 30 cm in six.
        let stepped = camera(Vec3::new(0.0, 0.0, -0.05), Vec3::new(0.0, 0.0, -1.05));
        let led = lead((&a, t0), (&stepped, later), Duration::from_millis(300));
        assert!((led.eye_vec() - Vec3::new(0.0, 0.0, -0.35)).length() < 1e-4);
    }

    #[test]
    fn a_lead_is_bounded_and_two_cameras_read_at_once_count_a_viewers_interval_apart() {
        let t0 = Instant::now();
        let a = camera(Vec3::ZERO, Vec3::NEG_Z);
        // 15° and 0.9 m in a step, still a walk (300°/s, 18 m/s): continued for 0.6 s, 180°
        // and 10.8 m, cut to the bounds.
        let fast = camera(Vec3::new(0.9, 0.0, 0.0), Vec3::new(0.9 + 0.268, 0.0, -1.0));
        let led = lead((&a, t0), (&fast, t0 + CAMERA_INTERVAL), MAX_LEAD);
        let turn = forward_of(&fast).angle_between(forward_of(&led));
        assert!((turn - MAX_LEAD_TURN).abs() < 1e-3, "{turn}");
        let moved = (led.eye_vec() - fast.eye_vec()).length();
        assert!((moved - MAX_LEAD_MOVE).abs() < 1e-3, "{moved}");
        let turned = camera(Vec3::ZERO, Vec3::new(0.01, 0.0, -1.0));
        let by = Duration::from_millis(200);
        let at_once = lead((&a, t0), (&turned, t0), by);
        let apart = lead((&a, t0), (&turned, t0 + CAMERA_INTERVAL), by);
        assert_eq!(at_once, apart);
    }

    #[test]
    fn a_jump_to_another_viewpoint_or_a_first_step_after_a_pause_is_not_led() {
        let t0 = Instant::now();
        let a = camera(Vec3::ZERO, Vec3::NEG_Z);
        let by = Duration::from_millis(300);
        // To the wall's other side in one step: far faster than a walk.
        let jumped = camera(Vec3::new(0.0, 0.0, -10.0), Vec3::ZERO);
        assert_eq!(lead((&a, t0), (&jumped, t0 + CAMERA_INTERVAL), by), jumped);
        // Half a turn in one step.
        let about = camera(Vec3::ZERO, Vec3::Z);
        assert_eq!(lead((&a, t0), (&about, t0 + CAMERA_INTERVAL), by), about);
        // A small step, but after a second at rest.
        let stepped = camera(Vec3::new(0.05, 0.0, 0.0), Vec3::new(0.05, 0.0, -1.0));
        let after_pause = t0 + Duration::from_secs(1);
        assert_eq!(lead((&a, t0), (&stepped, after_pause), by), stepped);
        assert_ne!(
            lead((&a, t0), (&stepped, t0 + CAMERA_INTERVAL), by),
            stepped
        );
    }

    #[test]
    fn two_cameras_at_one_instant_do_not_throw_the_focus() {
        let a = camera(Vec3::ZERO, Vec3::NEG_Z);
        let turned = camera(Vec3::ZERO, Vec3::new(0.01, 0.0, -1.0));
        let t0 = Instant::now();
        let same_instant = focus((&a, t0), (&turned, t0), None);
        let one_step = focus((&a, t0), (&turned, t0 + MIN_STEP), None);
        assert_eq!(same_instant, one_step);
        assert!(same_instant.0 < 200.0);
    }
}
