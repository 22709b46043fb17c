//! The walking camera of the window: move along the view, strafe, rise; turn about the scene's up
//! and pitch about the camera's right. It starts exactly at a named viewpoint's camera
//! (`Camera::from_viewpoint`), so an untouched view matches the SMA's and the renderer's images.

use glam::{Quat, Vec3};
use protocol::types::{Bounds, Viewpoint};
use protocol::viewer_link::Camera;

/// Looking closer than this to straight up or down is refused (the yaw axis would degenerate).
const MAX_ELEVATION_DEG: f32 = 85.0;

#[derive(Clone, Debug, PartialEq)]
pub struct WalkCamera {
    pub eye: Vec3,
    pub rotation: Quat,
    /// The scene's up, the axis of yaw.
    pub up: Vec3,
    pub fov_y_deg: f32,
    /// Metres per second.
    pub speed: f32,
}

impl WalkCamera {
    pub fn at_viewpoint(vp: &Viewpoint, speed: f32) -> WalkCamera {
        let camera = Camera::from_viewpoint(vp, 0, 1, 1);
        WalkCamera {
            eye: Vec3::from(vp.eye),
            rotation: camera.rotation(),
            up: Vec3::from(vp.up).normalize_or(Vec3::Y),
            fov_y_deg: vp.fov_y_deg.clamp(1.0, 170.0),
            speed,
        }
    }

    /// A view of the whole box from outside, for scenes without viewpoints.
    pub fn overlooking(bounds: &Bounds, speed: f32) -> WalkCamera {
        let (lo, hi) = (Vec3::from(bounds.min), Vec3::from(bounds.max));
        let centre = (lo + hi) * 0.5;
        let eye = centre + (hi - lo) * Vec3::new(0.0, 0.5, 1.5) + Vec3::Z;
        let vp = Viewpoint {
            name: "overview".into(),
            eye: eye.to_array(),
            target: centre.to_array(),
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 60.0,
        };
        Self::at_viewpoint(&vp, speed)
    }

    pub fn camera(&self, width: u32, height: u32) -> Camera {
        Camera {
            seq: 0,
            eye: self.eye.to_array(),
            orientation: self.rotation.to_array(),
            fov_y_deg: self.fov_y_deg,
            width,
            height,
        }
    }

    /// Moves by `forward`, `right` and `rise` (each in -1..=1) for `dt_s` seconds at `speed`.
    pub fn walk(&mut self, forward: f32, right: f32, rise: f32, dt_s: f32) {
        let step = self.rotation * Vec3::NEG_Z * forward
            + self.rotation * Vec3::X * right
            + self.up * rise;
        self.eye += step.normalize_or_zero() * self.speed * dt_s;
    }

    /// Turns left by `yaw` and up by `pitch` radians; the elevation stays within ±85°.
    pub fn turn(&mut self, yaw: f32, pitch: f32) {
        let yawed = Quat::from_axis_angle(self.up, yaw) * self.rotation;
        let elevation = (yawed * Vec3::NEG_Z).dot(self.up).clamp(-1.0, 1.0).asin();
        let limit = MAX_ELEVATION_DEG.to_radians();
        let pitch = (elevation + pitch).clamp(-limit, limit) - elevation;
        self.rotation = (yawed * Quat::from_axis_angle(Vec3::X, pitch)).normalize();
    }
}

/// A walking speed that crosses the scene's box in about ten seconds.
pub fn default_speed(bounds: &Bounds) -> f32 {
    let diagonal = (Vec3::from(bounds.max) - Vec3::from(bounds.min)).length();
    if diagonal.is_finite() && diagonal > 0.0 {
        diagonal / 10.0
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn viewpoint() -> Viewpoint {
        Viewpoint {
            name: "v".into(),
            eye: [0.0, 1.0, 5.0],
            target: [0.0, 1.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 50.0,
        }
    }

    #[test]
    fn starts_exactly_at_the_viewpoint_camera() {
        let w = WalkCamera::at_viewpoint(&viewpoint(), 1.0);
        assert_eq!(
            w.camera(64, 48),
            Camera::from_viewpoint(&viewpoint(), 0, 64, 48)
        );
    }

    #[test]
    fn walks_along_the_view_and_turns_about_up() {
        let mut w = WalkCamera::at_viewpoint(&viewpoint(), 2.0);
        w.walk(1.0, 0.0, 0.0, 0.5);
        assert!(
            w.eye.abs_diff_eq(Vec3::new(0.0, 1.0, 4.0), 1e-5),
            "{}",
            w.eye
        );
        w.turn(std::f32::consts::FRAC_PI_2, 0.0);
        let forward = w.rotation * Vec3::NEG_Z;
        assert!(forward.abs_diff_eq(Vec3::NEG_X, 1e-5), "{forward}");
        w.turn(0.0, 2.0);
        let elevation = (w.rotation * Vec3::NEG_Z).y.asin().to_degrees();
        assert!((elevation - 85.0).abs() < 1e-3, "pitched to {elevation}°");
        assert!(
            (w.rotation * Vec3::X).abs_diff_eq(Vec3::NEG_Z, 1e-5),
            "pitch must keep the heading"
        );
    }
}
