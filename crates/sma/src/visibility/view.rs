//! What a pass looks through: a camera and a depth range. Every pass draws camera-relative
//! (`conventions::camera`): vertices reach the GPU as `p - origin`, taken in f64, and the matrix
//! is built for that origin, so a scene far from the world origin (coordinates around 1e5,
//! DESIGN.md §7) gets the same ID buffer as a centred one (DESIGN.md §3 steps 2–3).

use conventions::camera::Pinhole;
use glam::{DVec3, Mat4};

use super::id_pass::reversed_z;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub camera: Pinhole,
    pub near: f32,
    pub far: f32,
}

impl View {
    /// The eye: the origin of what is uploaded for this view alone.
    pub fn eye(&self) -> DVec3 {
        self.camera.eye.as_dvec3()
    }

    /// Clip (reversed Z) from positions relative to `origin`.
    pub fn matrix_from(&self, origin: DVec3) -> Mat4 {
        reversed_z(
            self.camera
                .view_projection_from(origin, self.near, self.far),
        )
    }

    pub fn width(&self) -> u32 {
        self.camera.width
    }

    pub fn height(&self) -> u32 {
        self.camera.height
    }
}
