//! A flat grid mesh, for tests, the synthetic experiments and the benchmarks.

use glam::Vec3;
use scene::{Mesh, Triangle};

fn tri(vertices: [u32; 3]) -> Triangle {
    Triangle {
        vertices,
        material: 0,
    }
}

/// An `n` × `n` grid of unit squares in the z = 0 plane, two triangles each, spanning
/// `[0, n] × [0, n]`.
pub fn grid_mesh(n: u32) -> Mesh {
    let row = n + 1;
    let positions = (0..row * row)
        .map(|i| Vec3::new((i % row) as f32, (i / row) as f32, 0.0))
        .collect();
    let triangles = (0..n * n)
        .flat_map(|c| {
            let (x, y) = (c % n, c / n);
            let v = y * row + x;
            [tri([v, v + 1, v + row + 1]), tri([v, v + row + 1, v + row])]
        })
        .collect();
    Mesh {
        positions,
        normals: vec![Vec3::Z; (row * row) as usize],
        triangles,
    }
}
