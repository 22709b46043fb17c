//! The camera of the wire in the system's one camera convention (`conventions::camera`), so the
//! SMA's visibility pass, the viewer's drawing and the renderer's reference images agree pixel for
//! pixel.

use conventions::camera::{Pinhole, look_rotation};
use glam::{Mat4, Quat, Vec3};

use crate::types::Viewpoint;
use crate::viewer_link::Camera;

impl Camera {
    /// The camera of a named viewpoint at a given image size.
    pub fn from_viewpoint(vp: &Viewpoint, seq: u64, width: u32, height: u32) -> Camera {
        let eye = Vec3::from(vp.eye);
        Camera {
            seq,
            eye: vp.eye,
            orientation: look_rotation(eye, Vec3::from(vp.target), Vec3::from(vp.up)).to_array(),
            fov_y_deg: vp.fov_y_deg,
            width,
            height,
        }
    }

    /// The pinhole this camera is.
    pub fn pinhole(&self) -> Pinhole {
        Pinhole {
            eye: self.eye_vec(),
            rotation: self.rotation(),
            fov_y_deg: self.fov_y_deg,
            width: self.width,
            height: self.height,
        }
    }

    pub fn rotation(&self) -> Quat {
        Quat::from_array(self.orientation).normalize()
    }

    pub fn eye_vec(&self) -> Vec3 {
        Vec3::from(self.eye)
    }

    /// Unit view direction.
    pub fn forward(&self) -> Vec3 {
        self.pinhole().forward()
    }

    pub fn aspect(&self) -> f32 {
        self.pinhole().aspect()
    }

    /// World -> camera.
    pub fn view_matrix(&self) -> Mat4 {
        self.pinhole().view_matrix()
    }

    /// Camera -> clip, depth 0..1 (wgpu), right-handed.
    pub fn projection(&self, near: f32, far: f32) -> Mat4 {
        self.pinhole().projection(near, far)
    }

    pub fn view_projection(&self, near: f32, far: f32) -> Mat4 {
        self.pinhole().view_projection(near, far)
    }

    /// World-space unit direction through image point (x, y) in pixels (x = 0.5 is the centre of
    /// the first column).
    pub fn ray_direction(&self, x: f32, y: f32) -> Vec3 {
        self.pinhole().ray_direction(x, y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_viewpoint_camera_is_the_pinhole_looking_at_its_target() {
        let vp = Viewpoint {
            name: "t".into(),
            eye: [1.0, 2.0, 3.0],
            target: [4.0, 2.5, -1.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 60.0,
        };
        let c = Camera::from_viewpoint(&vp, 0, 640, 480);
        let want = Pinhole::look_at(
            Vec3::from(vp.eye),
            Vec3::from(vp.target),
            Vec3::from(vp.up),
            60.0,
            [640, 480],
        );
        assert!(
            c.ray_direction(10.5, 20.5)
                .abs_diff_eq(want.ray_direction(10.5, 20.5), 1e-6)
        );
        assert!(
            c.view_projection(0.1, 100.0)
                .abs_diff_eq(want.view_projection(0.1, 100.0), 1e-6)
        );
    }
}
