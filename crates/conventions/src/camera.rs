//! The one camera convention of the system, so the SMA's visibility pass, the viewer's drawing and
//! the renderer's reference images agree pixel for pixel.
//!
//! The camera frame looks down -Z with +Y up (right-handed); `rotation` turns it into the world.
//! Pixel (x, y) counts from the top-left corner; pixel centres sit at +0.5. Depth maps to 0..1 as
//! wgpu expects.

use glam::{Mat3, Mat4, Quat, Vec3};

/// A pinhole camera: where it is, where it looks, and the image it makes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pinhole {
    pub eye: Vec3,
    pub rotation: Quat,
    /// Vertical field of view, degrees.
    pub fov_y_deg: f32,
    pub width: u32,
    pub height: u32,
}

impl Pinhole {
    /// The camera at `eye` looking at `target`, `up` being up.
    pub fn look_at(eye: Vec3, target: Vec3, up: Vec3, fov_y_deg: f32, size: [u32; 2]) -> Pinhole {
        Pinhole {
            eye,
            rotation: look_rotation(eye, target, up),
            fov_y_deg,
            width: size[0],
            height: size[1],
        }
    }

    /// Width over height (an empty image counts as one pixel).
    pub fn aspect(&self) -> f32 {
        self.width.max(1) as f32 / self.height.max(1) as f32
    }

    /// Unit view direction.
    pub fn forward(&self) -> Vec3 {
        self.rotation * Vec3::NEG_Z
    }

    /// World -> camera.
    pub fn view_matrix(&self) -> Mat4 {
        Mat4::from_rotation_translation(self.rotation, self.eye).inverse()
    }

    /// Camera -> clip, depth 0..1 (wgpu), right-handed.
    pub fn projection(&self, near: f32, far: f32) -> Mat4 {
        glam::camera::rh::proj::directx::perspective(
            self.fov_y_deg.to_radians(),
            self.aspect(),
            near,
            far,
        )
    }

    pub fn view_projection(&self, near: f32, far: f32) -> Mat4 {
        self.projection(near, far) * self.view_matrix()
    }

    /// World-space unit direction through image point (x, y) in pixels (x = 0.5 is the centre of
    /// the first column).
    pub fn ray_direction(&self, x: f32, y: f32) -> Vec3 {
        let t = (0.5 * self.fov_y_deg.to_radians()).tan();
        let sx = (2.0 * x / self.width.max(1) as f32 - 1.0) * t * self.aspect();
        let sy = (1.0 - 2.0 * y / self.height.max(1) as f32) * t;
        (self.rotation * Vec3::new(sx, sy, -1.0)).normalize()
    }
}

/// Rotation taking the camera frame (-Z forward, +Y up) to look from `eye` at `target`.
pub fn look_rotation(eye: Vec3, target: Vec3, up: Vec3) -> Quat {
    let f = (target - eye).normalize_or(Vec3::NEG_Z);
    let mut r = f.cross(up);
    if r.length_squared() < 1e-12 {
        r = f.any_orthonormal_vector();
    }
    let r = r.normalize();
    let u = r.cross(f);
    Quat::from_mat3(&Mat3::from_cols(r, u, -f)).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Pinhole {
        Pinhole::look_at(
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(4.0, 2.5, -1.0),
            Vec3::Y,
            60.0,
            [640, 480],
        )
    }

    #[test]
    fn centre_ray_looks_at_target() {
        let c = camera();
        let d = c.ray_direction(320.0, 240.0);
        let want = (Vec3::new(4.0, 2.5, -1.0) - Vec3::new(1.0, 2.0, 3.0)).normalize();
        assert!(d.abs_diff_eq(want, 1e-5), "{d} vs {want}");
        assert!(c.forward().abs_diff_eq(want, 1e-5));
    }

    #[test]
    fn ray_directions_project_back_to_their_pixels() {
        let c = camera();
        let vp = c.view_projection(0.1, 100.0);
        for (x, y) in [(0.5, 0.5), (100.25, 400.5), (639.5, 10.0)] {
            let p = c.eye + c.ray_direction(x, y) * 7.0;
            let clip = vp * p.extend(1.0);
            let ndc = clip.truncate() / clip.w;
            let px = (ndc.x + 1.0) * 0.5 * 640.0;
            let py = (1.0 - ndc.y) * 0.5 * 480.0;
            assert!(
                (px - x).abs() < 1e-2 && (py - y).abs() < 1e-2,
                "{px},{py} vs {x},{y}"
            );
            assert!((0.0..=1.0).contains(&ndc.z));
        }
    }

    #[test]
    fn looking_straight_up_still_has_a_frame() {
        let c = Pinhole::look_at(Vec3::ZERO, Vec3::Y, Vec3::Y, 60.0, [4, 4]);
        assert!(c.forward().abs_diff_eq(Vec3::Y, 1e-5));
    }
}
