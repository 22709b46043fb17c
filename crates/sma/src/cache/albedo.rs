//! The diffuse albedo at each vertex of the subdivision mesh (DESIGN.md §5, "Parts, and
//! textures"): the texel of its material's texture at the vertex's object-space point, or the
//! material's `Kd`. The renderers answer illumination; this is what multiplies it before a
//! viewer is sent the vertex's radiance (`sample::display_radiance`), looked up once per vertex
//! as the mesh grows.

use std::sync::Arc;

use scene::Scene;

use crate::mesh::{SubdivisionMesh, VertexId};

/// An albedo channel is stored in 16 bits over 0..2 (a physical albedo is at most 1; an MTL
/// that states more still fits): steps of 2^-15, far below a display step.
const STEPS_PER_UNIT: f32 = 32_768.0;

/// The albedo of every vertex looked up so far, by vertex id (vertices are never renumbered).
#[derive(Clone, Debug, Default)]
pub(super) struct VertexAlbedos {
    /// Without a scene (the cache's unit tests, benchmarks of the cache alone) every albedo is
    /// one.
    scene: Option<Arc<Scene>>,
    albedos: Vec<[u16; 3]>,
}

impl VertexAlbedos {
    pub(super) fn of(scene: Arc<Scene>) -> VertexAlbedos {
        VertexAlbedos {
            scene: Some(scene),
            albedos: Vec::new(),
        }
    }

    /// Looks up the vertices of `mesh` beyond those already known.
    pub(super) fn cover(&mut self, mesh: &SubdivisionMesh) {
        let Some(scene) = &self.scene else {
            return;
        };
        let known = self.albedos.len();
        self.albedos.extend((known..mesh.vertex_count()).map(|v| {
            let vertex = mesh.vertex(v as VertexId);
            let t = vertex.base_triangle as usize;
            let albedo = if t < scene.mesh.triangles.len() {
                scene.albedo_at(t, vertex.bary).to_array()
            } else {
                [1.0; 3]
            };
            albedo.map(|c| {
                (c.max(0.0) * STEPS_PER_UNIT)
                    .round()
                    .min(f32::from(u16::MAX)) as u16
            })
        }));
    }

    /// The albedo at `vertex`: one where it was not looked up (no scene).
    pub(super) fn at(&self, vertex: VertexId) -> [f32; 3] {
        self.albedos
            .get(vertex as usize)
            .map_or([1.0; 3], |a| a.map(|c| f32::from(c) / STEPS_PER_UNIT))
    }

    pub(super) fn bytes(&self) -> usize {
        self.albedos.len() * size_of::<[u16; 3]>()
    }
}
