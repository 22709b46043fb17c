//! The one camera convention of the system, so the SMA's visibility pass, the viewer's drawing and
//! the renderer's reference images agree pixel for pixel.
//!
//! The camera frame looks down -Z with +Y up (right-handed); `rotation` turns it into the world.
//! Pixel (x, y) counts from the top-left corner; pixel centres sit at +0.5. Depth maps to 0..1 as
//! wgpu expects.
//!
//! GPU passes draw **relative to an origin** near the eye ([`relative_to`],
//! [`Pinhole::view_projection_from`]): a scene far from the world origin (coordinates around 1e5,
//! where f32 spacing is about 0.008, DESIGN.md §7) then shades like a centred one. A vertex shader
//! that multiplied world positions by a matrix with a 1e5 translation would cancel two large
//! numbers in f32 and move every vertex by millimetres to centimetres, so depth tests fight and
//! edges wander; the subtraction is done here, in f64, before anything reaches the GPU.

use glam::{DVec3, Mat3, Mat4, Quat, Vec3};

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

    /// Half the image plane's height at unit distance down the view direction, `tan(fov_y / 2)`:
    /// in the camera frame (-Z forward, +Y up) the image spans `±half_height` in y and
    /// `±half_height · aspect` in x at z = -1. Every ray through the image, and every drawing of
    /// what it sees, is scaled by it.
    pub fn half_height(&self) -> f32 {
        (0.5 * self.fov_y_deg.to_radians()).tan()
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

    /// World -> camera for positions given relative to `origin` (as [`relative_to`] makes
    /// them). Its translation is `origin - eye`, taken in f64: none at all when the origin is the
    /// eye, and only as large as the scene when it is a point of the scene.
    pub fn view_matrix_from(&self, origin: DVec3) -> Mat4 {
        let shift = (origin - self.eye.as_dvec3()).as_vec3();
        Mat4::from_quat(self.rotation.inverse()) * Mat4::from_translation(shift)
    }

    /// Clip from positions relative to `origin`: the same pixels as [`Pinhole::view_projection`]
    /// of the absolute positions, without its loss of precision far from the world origin.
    pub fn view_projection_from(&self, origin: DVec3, near: f32, far: f32) -> Mat4 {
        self.projection(near, far) * self.view_matrix_from(origin)
    }

    /// World-space unit direction through image point (x, y) in pixels (x = 0.5 is the centre of
    /// the first column).
    pub fn ray_direction(&self, x: f32, y: f32) -> Vec3 {
        let t = self.half_height();
        let sx = (2.0 * x / self.width.max(1) as f32 - 1.0) * t * self.aspect();
        let sy = (1.0 - 2.0 * y / self.height.max(1) as f32) * t;
        (self.rotation * Vec3::new(sx, sy, -1.0)).normalize()
    }
}

/// `p - origin`, taken in f64 and rounded once: the vertex positions a camera-relative pass
/// uploads.
pub fn relative_to(p: Vec3, origin: DVec3) -> Vec3 {
    (p.as_dvec3() - origin).as_vec3()
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

    /// The image's top edge and right edge, at unit depth, sit at the half extents.
    #[test]
    fn half_height_is_where_the_edge_rays_meet_unit_depth() {
        let c = Pinhole::look_at(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 60.0, [640, 480]);
        let top = c.ray_direction(320.0, 0.0);
        let right = c.ray_direction(640.0, 240.0);
        assert!((top.y / -top.z - c.half_height()).abs() < 1e-6);
        assert!((right.x / -right.z - c.half_height() * c.aspect()).abs() < 1e-6);
        assert!((c.half_height() - 30f32.to_radians().tan()).abs() < 1e-7);
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

    /// Far from the world origin the absolute matrix moves vertices by centimetres; the relative
    /// one projects them where an exact (f64) projection does.
    #[test]
    fn relative_projection_is_exact_where_the_absolute_one_is_not() {
        let far_away = Vec3::new(1.0e5, 0.0, 1.0e5);
        let c = Pinhole::look_at(
            far_away + Vec3::new(0.3, 1.7, 6.1),
            far_away + Vec3::new(2.0, 1.1, -3.0),
            Vec3::Y,
            50.0,
            [1024, 768],
        );
        let exact = |p: DVec3| {
            let view =
                glam::DMat4::from_rotation_translation(c.rotation.as_dquat(), c.eye.as_dvec3())
                    .inverse();
            let clip = c.projection(0.1, 100.0).as_dmat4() * view * p.extend(1.0);
            let ndc = clip.truncate() / clip.w;
            glam::DVec2::new((ndc.x + 1.0) * 512.0, (1.0 - ndc.y) * 384.0)
        };
        let pixel = |m: Mat4, p: Vec3| {
            let clip = m * p.extend(1.0);
            let ndc = clip.truncate() / clip.w;
            glam::DVec2::new((ndc.x as f64 + 1.0) * 512.0, (1.0 - ndc.y as f64) * 384.0)
        };
        let origin = c.eye.as_dvec3();
        let relative = c.view_projection_from(origin, 0.1, 100.0);
        let absolute = c.view_projection(0.1, 100.0);
        let (mut worst_relative, mut worst_absolute) = (0.0f64, 0.0f64);
        for k in 0..50 {
            let offset = Vec3::new(
                k as f32 * 0.37 - 9.0,
                (k % 7) as f32 * 0.5,
                -(k as f32) * 0.41,
            );
            let p = far_away + offset;
            let want = exact(p.as_dvec3());
            worst_relative =
                worst_relative.max(pixel(relative, relative_to(p, origin)).distance(want));
            worst_absolute = worst_absolute.max(pixel(absolute, p).distance(want));
        }
        assert!(worst_relative < 0.01, "relative: {worst_relative} px off");
        assert!(
            worst_absolute > 0.1,
            "absolute: only {worst_absolute} px off"
        );
    }

    #[test]
    fn looking_straight_up_still_has_a_frame() {
        let c = Pinhole::look_at(Vec3::ZERO, Vec3::Y, Vec3::Y, 60.0, [4, 4]);
        assert!(c.forward().abs_diff_eq(Vec3::Y, 1e-5));
    }
}
