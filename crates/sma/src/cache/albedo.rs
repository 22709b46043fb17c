//! The diffuse albedo at each vertex of the subdivision mesh (DESIGN.md §5, "Parts, and
//! textures"): the texel of its material's texture at the vertex's object-space point, or the
//! material's `Kd`. The renderers answer illumination; this is what multiplies it into the
//! radiance the SMA's criteria, L_white and stopping rule judge (`sample::display_radiance`),
//! looked up once per vertex as the mesh grows. A viewer multiplies its own albedo in per pixel:
//! it is sent each shown leaf's material and corner texture coordinates (`leaf_surface`).

use std::sync::Arc;

use protocol::texture::Texcoords;
use scene::Scene;
use scene::texture::Wrap;

use crate::mesh::{NodeId, SubdivisionMesh, VertexId};

/// An albedo channel is stored in 16 bits over 0..2 (a physical albedo is at most 1; an MTL
/// that states more still fits): steps of 2^-15, far below a display step.
const STEPS_PER_UNIT: f32 = 32_768.0;

/// The albedo of every vertex looked up so far, by vertex id; a midpoint vertex the mesh freed
/// (`SubdivisionMesh::free_unused_midpoints`) is looked up again once reused.
#[derive(Clone, Debug, Default)]
pub(super) struct VertexAlbedos {
    /// Without a scene (the cache's unit tests, benchmarks of the cache alone) every albedo is
    /// one.
    scene: Option<Arc<Scene>>,
    albedos: Vec<[u16; 3]>,
    /// Freed vertices, looked up again once a split reuses them.
    stale: Vec<VertexId>,
}

impl VertexAlbedos {
    pub(super) fn of(scene: Arc<Scene>) -> VertexAlbedos {
        VertexAlbedos {
            scene: Some(scene),
            albedos: Vec::new(),
            stale: Vec::new(),
        }
    }

    /// Looks up the vertices of `mesh` beyond those already known, and the freed ones a split
    /// has reused since.
    pub(super) fn cover(&mut self, mesh: &SubdivisionMesh) {
        let Some(scene) = &self.scene else {
            return;
        };
        let look_up = |v: VertexId| {
            let vertex = mesh.vertex(v);
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
        };
        let known = self.albedos.len();
        self.albedos
            .extend((known..mesh.vertex_count()).map(|v| look_up(v as VertexId)));
        let albedos = &mut self.albedos;
        self.stale.retain(|&v| {
            let reused = !mesh.is_free_vertex(v);
            if reused {
                albedos[v as usize] = look_up(v);
            }
            !reused
        });
    }

    /// `vertices` were freed: each is looked up again once reused.
    pub(super) fn forget(&mut self, vertices: &[VertexId]) {
        if self.scene.is_some() {
            self.stale.extend(vertices);
        }
    }

    /// The albedo at `vertex`: one where it was not looked up (no scene).
    pub(super) fn at(&self, vertex: VertexId) -> [f32; 3] {
        self.albedos
            .get(vertex as usize)
            .map_or([1.0; 3], |a| a.map(|c| f32::from(c) / STEPS_PER_UNIT))
    }

    /// The material of leaf `leaf`'s scene triangle and its corners' texture coordinates, the
    /// map's scale and offset applied (MTL `-s`, `-o`); none for a material without a texture.
    pub(super) fn leaf_surface(&self, mesh: &SubdivisionMesh, leaf: NodeId) -> (u16, Texcoords) {
        let Some(scene) = &self.scene else {
            return (0, Texcoords::default());
        };
        let (t, bary) = mesh.leaf_in_scene_triangle(leaf);
        let Some(triangle) = scene.mesh.triangles.get(t as usize) else {
            return (0, Texcoords::default());
        };
        let material = u16::try_from(triangle.material).unwrap_or(u16::MAX);
        let texcoords = match &scene.materials[triangle.material as usize].diffuse_map {
            None => Texcoords::default(),
            Some(map) => Texcoords::encode(
                bary.map(|b| {
                    (scene.texcoord_at(t as usize, b) * map.scale + map.offset).to_array()
                }),
                map.wrap == Wrap::Clamp,
            ),
        };
        (material, texcoords)
    }

    pub(super) fn bytes(&self) -> usize {
        self.albedos.capacity() * size_of::<[u16; 3]>()
            + self.stale.capacity() * size_of::<VertexId>()
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use protocol::renderer_link::{Quality, SampleKey};
    use protocol::{PartEstimate, SampleParts, Side};

    use super::*;
    use crate::cache::{CachedSample, ShadingCache};
    use crate::mesh::MeshParams;

    /// Read back, a sample is the albedo at its vertex times its illumination plus its
    /// view-dependent part: a texel of bracara's paving where the vertex lies on the ground
    /// (varying from vertex to vertex), the marble's `Kd` exactly on untextured marble.
    #[test]
    fn a_vertex_is_shown_with_its_albedo_times_its_illumination() {
        let scene = Arc::new(scene::load("bracara-textured").expect("built-in"));
        let mesh = SubdivisionMesh::new(&scene.mesh, MeshParams::default());
        let mut cache = ShadingCache::new(usize::MAX).with_albedos_of(Arc::clone(&scene));
        cache.cover_albedos(&mesh);
        let part = |rgb: [f32; 3], luminance_variance| PartEstimate {
            rgb,
            luminance_variance,
        };
        let parts = SampleParts {
            direct: part([2.0, 3.0, 4.0], 0.5),
            indirect: part([1.0; 3], 0.1),
            view_dependent: part([0.25; 3], 0.01),
        };
        let (mut ground, mut marble) = (Vec::new(), Vec::new());
        for vertex in 0..mesh.vertex_count() as VertexId {
            let v = mesh.vertex(vertex);
            let Some(material) = scene
                .mesh
                .triangles
                .get(v.base_triangle as usize)
                .map(|t| &scene.materials[t.material as usize])
            else {
                continue;
            };
            let key = SampleKey {
                vertex,
                side: Side::Front,
            };
            cache.insert(
                key,
                CachedSample {
                    parts,
                    quality: Quality {
                        paths: 16,
                        bounces: Some(2),
                    },
                    view_dependent: false,
                    eye: None,
                    last_seen: 0,
                },
            );
            let shown = Vec3::from(cache.get(key).expect("cached").rgb());
            let albedo = scene.albedo_at(v.base_triangle as usize, v.bary);
            let want = albedo * Vec3::new(3.0, 4.0, 5.0) + 0.25;
            // Within the stored means' quantisation (2^-9 of the largest channel).
            assert!(
                (shown - want).abs().max_element() <= 4e-3 * want.max_element(),
                "vertex {vertex} of {}: {shown} vs {want}",
                material.name
            );
            match material.name.as_str() {
                "ground" => ground.push(albedo),
                "marble" => marble.push(albedo),
                _ => {}
            }
        }
        assert!(!marble.is_empty() && marble.iter().all(|&a| a == Vec3::new(0.78, 0.76, 0.72)));
        assert!(ground.len() > 4);
        assert!(
            ground.iter().any(|&a| a != ground[0]),
            "the paving's texels differ from vertex to vertex"
        );
        // The estimate criteria read is the displayed one too.
        let key = SampleKey {
            vertex: 0,
            side: Side::Front,
        };
        if let Some(e) = cache.estimate(key, None) {
            assert_eq!(e.rgb(), cache.get(key).expect("cached").rgb());
        }
    }
}
