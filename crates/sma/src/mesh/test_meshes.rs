//! Small hand-made meshes for the tests of the SMA core.

use glam::Vec3;
use scene::{Mesh, Triangle};

pub(crate) use super::grid::grid_mesh as grid;

/// Two triangles sharing the diagonal of the unit square.
pub(crate) fn square() -> Mesh {
    Mesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
        normals: vec![Vec3::Z; 4],
        triangles: vec![
            Triangle {
                vertices: [0, 1, 2],
                material: 0,
            },
            Triangle {
                vertices: [0, 2, 3],
                material: 0,
            },
        ],
    }
}
