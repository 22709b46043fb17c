//! The diffuse albedo the SMA judges each vertex's samples with (DESIGN.md §5, "Parts, and
//! textures"; §6): the mean of the linear albedo over the leaves around the vertex, by area,
//! each leaf's mean taken over stratified points of its scene triangle in texture space (the
//! material's `Kd` for an untextured one). A viewer multiplies the texture in per pixel, so
//! what a person sees of a vertex's illumination is spread over those leaves' texels: a single
//! texel at the vertex would be an arbitrary one on a texture finer than the leaves, and a
//! dark texture would attract samples no one could see only where a vertex happens to land on
//! a light texel. The mean is taken once, when the vertex is first covered (its leaves are then
//! the largest they will be, the footprint its hat spreads over), and kept in 6 bytes per
//! vertex, counted with the cache. `sample::display_radiance` is where it meets the
//! illumination. A viewer is sent each shown leaf's material and corner texture coordinates
//! (`leaf_surface`).

use std::sync::Arc;

use glam::Vec3;
use protocol::texture::Texcoords;
use scene::Scene;
use scene::texture::Wrap;

use crate::mesh::{NodeId, SubdivisionMesh, VertexId};

/// An albedo channel is stored in 16 bits over 0..2 (a physical albedo is at most 1; an MTL
/// that states more still fits): steps of 2^-15, far below a display step.
const STEPS_PER_UNIT: f32 = 32_768.0;

/// The mean albedo around every vertex covered so far, by vertex id; a midpoint vertex the mesh
/// freed (`SubdivisionMesh::free_unused_midpoints`) is covered again once reused.
#[derive(Clone, Debug, Default)]
pub(super) struct VertexAlbedos {
    /// Without a scene (the cache's unit tests, benchmarks of the cache alone) every albedo is
    /// one.
    scene: Option<Arc<Scene>>,
    albedos: Vec<[u16; 3]>,
    /// Freed vertices, covered again once a split reuses them.
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

    /// Takes the mean albedo around the vertices of `mesh` beyond those already known, and
    /// around the freed ones a split has reused since.
    pub(super) fn cover(&mut self, mesh: &SubdivisionMesh) {
        let Some(scene) = &self.scene else {
            return;
        };
        let known = self.albedos.len();
        let mut wanted: Vec<VertexId> = (known..mesh.vertex_count())
            .map(|v| v as VertexId)
            .collect();
        self.stale.retain(|&v| {
            let reused = !mesh.is_free_vertex(v);
            if reused {
                wanted.push(v);
            }
            !reused
        });
        if wanted.is_empty() {
            return;
        }
        let means = mean_albedos_around(scene, mesh, &mut wanted);
        self.albedos.resize(mesh.vertex_count(), [0; 3]);
        for (&v, albedo) in wanted.iter().zip(means) {
            self.albedos[v as usize] = albedo.to_array().map(|c| {
                (c.max(0.0) * STEPS_PER_UNIT)
                    .round()
                    .min(f32::from(u16::MAX)) as u16
            });
        }
    }

    /// `vertices` were freed: each is covered again once reused.
    pub(super) fn forget(&mut self, vertices: &[VertexId]) {
        if self.scene.is_some() {
            self.stale.extend(vertices);
        }
    }

    /// The mean albedo around `vertex`: one where it was not covered (no scene).
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

/// The most points a leaf's mean albedo is taken over: with about one per texel of its footprint
/// up to this, the mean of a texture far finer than the leaf is within a few hundredths.
const MAX_POINTS_PER_LEAF: usize = 64;

/// The mean albedo over the area of the leaves around each vertex of `vertices` (sorted here),
/// in that order. A vertex on no leaf of any area (a scene vertex no triangle uses, a freed
/// one) takes the albedo at its own point, or one off the scene's triangles.
fn mean_albedos_around(
    scene: &Scene,
    mesh: &SubdivisionMesh,
    vertices: &mut [VertexId],
) -> Vec<Vec3> {
    vertices.sort_unstable();
    // A bit per vertex passes over most leaves' corners without a search: a refinement step
    // adds a few hundred vertices to a mesh of up to millions of leaves.
    let mut wanted = vec![0u64; mesh.vertex_count().div_ceil(64)];
    for &v in vertices.iter() {
        wanted[v as usize / 64] |= 1 << (v % 64);
    }
    let is_wanted = |v: VertexId| wanted[v as usize / 64] & (1 << (v % 64)) != 0;
    let mut sums = vec![(Vec3::ZERO, 0.0f32); vertices.len()];
    for leaf in mesh.leaves() {
        let corners = mesh.node(leaf).vertices;
        if !corners.iter().any(|&v| is_wanted(v)) {
            continue;
        }
        let mut at = corners.map(|v| vertices.binary_search(&v).ok());
        let [a, b, c] = mesh.leaf_positions(leaf);
        let area = 0.5 * (b - a).cross(c - a).length();
        if area.is_nan() || area <= 0.0 {
            continue;
        }
        let mean = leaf_mean_albedo(scene, mesh, leaf);
        // A corner listed twice (a degenerate leaf) counts once.
        at.sort_unstable();
        let mut last = None;
        for i in at.into_iter().flatten() {
            if last != Some(i) {
                sums[i].0 += area * mean;
                sums[i].1 += area;
                last = Some(i);
            }
        }
    }
    vertices
        .iter()
        .zip(sums)
        .map(|(&v, (sum, area))| {
            if area > 0.0 {
                return sum / area;
            }
            let vertex = mesh.vertex(v);
            let t = vertex.base_triangle as usize;
            if t < scene.mesh.triangles.len() {
                scene.albedo_at(t, vertex.bary)
            } else {
                Vec3::ONE
            }
        })
        .collect()
}

/// The mean albedo over leaf `leaf`: `Kd` (or one off the scene's triangles) untextured; else
/// the mean over about one point per texel of the leaf's footprint in the texture, at most
/// `MAX_POINTS_PER_LEAF`, spread over the triangle by a Fibonacci lattice (stratified in both
/// directions, and not aligned with a texture's rows as a regular grid would be).
fn leaf_mean_albedo(scene: &Scene, mesh: &SubdivisionMesh, leaf: NodeId) -> Vec3 {
    let (t, bary) = mesh.leaf_in_scene_triangle(leaf);
    let t = t as usize;
    if t >= scene.mesh.triangles.len() {
        return Vec3::ONE;
    }
    let material = scene.material_of(t);
    let Some(map) = &material.diffuse_map else {
        return material.kd;
    };
    let [a, b, c] = bary.map(|p| scene.texcoord_at(t, p) * map.scale);
    let texels = 0.5
        * (b - a).perp_dot(c - a).abs()
        * map.texture.width() as f32
        * map.texture.height() as f32;
    let points = if texels.is_finite() {
        (texels.ceil() as usize).clamp(1, MAX_POINTS_PER_LEAF)
    } else {
        MAX_POINTS_PER_LEAF
    };
    let [p0, p1, p2] = bary.map(glam::Vec2::from);
    let golden = 0.5 * (5f32.sqrt() - 1.0);
    let sum: Vec3 = (0..points)
        .map(|i| {
            // (r1, r2) on the unit square, onto the triangle with even density.
            let r1 = (i as f32 + 0.5) / points as f32;
            let r2 = (i as f32 * golden).fract();
            let s = r1.sqrt();
            let p = p0 * (1.0 - s) + p1 * (s * (1.0 - r2)) + p2 * (s * r2);
            scene.albedo_at(t, p.to_array())
        })
        .sum();
    sum / points as f32
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use protocol::renderer_link::{Quality, SampleKey};
    use protocol::{PartEstimate, SampleParts, Side};

    use super::*;
    use crate::cache::{CachedSample, ShadingCache};
    use crate::mesh::MeshParams;

    /// Read back, a sample is the mean albedo around its vertex times its illumination plus
    /// its view-dependent part: near the paving texture's mean where the vertex lies on
    /// bracara's ground (its base leaves span many texels), the marble's `Kd` on untextured
    /// marble.
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
            cache.insert(key, diffuse_sample(parts));
            let shown = Vec3::from(cache.get(key).expect("cached").rgb());
            let albedo = Vec3::from(cache.albedos.at(vertex));
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
        let kd = Vec3::new(0.78, 0.76, 0.72);
        assert!(!marble.is_empty());
        for a in marble {
            assert!((a - kd).abs().max_element() < 1e-3, "marble {a} vs {kd}");
        }
        assert!(ground.len() > 4);
        let paving = scene
            .materials
            .iter()
            .find(|m| m.name == "ground")
            .expect("bracara's ground");
        let map = paving.diffuse_map.as_ref().expect("textured ground");
        let mean = match map.rule {
            scene::settings::AlbedoRule::KdTimesTexture => paving.kd * map.texture.mean(),
            scene::settings::AlbedoRule::Texture => map.texture.mean(),
        };
        for a in ground {
            assert!((a - mean).abs().max_element() < 0.1, "ground {a} vs {mean}");
        }
        // The estimate criteria read is the displayed one too.
        let key = SampleKey {
            vertex: 0,
            side: Side::Front,
        };
        if let Some(e) = cache.estimate(key, None) {
            assert_eq!(e.rgb(), cache.get(key).expect("cached").rgb());
        }
    }

    /// A 4 m square (two triangles) whose texture coordinates are `8 × position + 0.25`: every
    /// vertex down to 1 m leaves sits on the centre of texel (0, 1) of the 2 × 2 texture
    /// `texels`, which repeats 8 times a metre, far finer than any leaf.
    /// A diffuse sample of 16 paths with `parts`.
    fn diffuse_sample(parts: SampleParts) -> CachedSample {
        CachedSample {
            parts,
            quality: Quality {
                paths: 16,
                bounces: Some(2),
            },
            view_dependent: false,
            eye: None,
            last_seen: 0,
        }
    }

    fn square_textured_with(texels: [[u8; 3]; 4]) -> (Arc<Scene>, SubdivisionMesh) {
        use scene::settings::AlbedoRule;
        use scene::{DiffuseMap, Material, SceneBuilder, SceneSettings, Texture};
        let settings = SceneSettings {
            name: "textured square".into(),
            obj: String::new(),
            units: "m".into(),
            crease_angle_deg: 45.0,
            sun: None,
            sky: Default::default(),
            quality: Default::default(),
            viewpoints: vec![scene::ViewpointSetting {
                name: "above".into(),
                eye: [2.0, 2.0, 4.0],
                target: [2.0, 2.0, 0.0],
                up: [0.0, 1.0, 0.0],
                fov_y_deg: 60.0,
            }],
            textures: scene::TextureSettings {
                enabled: true,
                albedo: AlbedoRule::Texture,
            },
        };
        let mut material = Material::diffuse("square", Vec3::ONE);
        material.diffuse_map = Some(DiffuseMap::generated(
            Texture::from_srgb8(2, 2, &texels),
            "texels.png".into(),
            AlbedoRule::Texture,
        ));
        let mut b = SceneBuilder::new(settings);
        let material = b.material(material);
        let corners = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]].map(glam::Vec2::from);
        let v = corners.map(|p| b.vertex(p.extend(0.0)));
        for [i, j, k] in [[0, 1, 2], [0, 2, 3]] {
            let uv = [i, j, k].map(|c| corners[c] * 8.0 + 0.25);
            b.textured_triangle([v[i], v[j], v[k]], material, uv);
        }
        let scene = Arc::new(b.build().expect("valid test scene"));
        let mut mesh = SubdivisionMesh::new(&scene.mesh, MeshParams::default());
        // Two levels of red splits: 1 m leaves, each over 128 texels.
        for _ in 0..2 {
            let leaves: Vec<NodeId> = mesh.leaves().collect();
            mesh.split_red_all(&leaves);
        }
        (scene, mesh)
    }

    const BLACK: [u8; 3] = [0; 3];
    const WHITE: [u8; 3] = [255; 3];

    /// DESIGN.md §5, "Parts, and textures": on a black-and-white checker far finer than the
    /// leaves, every vertex is judged with the mean albedo around it, about one half, although
    /// the texel at each vertex is black (the albedo a single texel would give is 0).
    #[test]
    fn a_checker_finer_than_the_leaves_is_judged_by_its_mean() {
        let (scene, mesh) = square_textured_with([WHITE, BLACK, BLACK, WHITE]);
        let mut cache = ShadingCache::new(usize::MAX).with_albedos_of(Arc::clone(&scene));
        cache.cover_albedos(&mesh);
        assert!(mesh.vertex_count() > 20);
        for vertex in 0..mesh.vertex_count() as VertexId {
            let v = mesh.vertex(vertex);
            assert_eq!(
                scene.albedo_at(v.base_triangle as usize, v.bary),
                Vec3::ZERO,
                "vertex {vertex} sits on a black texel"
            );
            let albedo = cache.albedos.at(vertex);
            assert!(
                albedo.iter().all(|c| (c - 0.5).abs() < 0.12),
                "vertex {vertex}: {albedo:?}"
            );
        }
    }

    /// A texture dark but for the texels under the vertices (one bright texel in four, mean
    /// 0.26) shows its illumination, and its uncertainty, as dark: what the criteria, L_white
    /// and the stopping rule read (DESIGN.md §6) is near a quarter of a uniformly bright
    /// texture's under the same illumination, not equal to it as the texels at the vertices
    /// would make it, so it draws no samples for detail no one could see.
    #[test]
    fn a_dark_texture_shows_its_illumination_and_its_uncertainty_dark() {
        const DARK: [u8; 3] = [10; 3];
        let shown = |texels| {
            let (scene, mesh) = square_textured_with(texels);
            let mut cache = ShadingCache::new(usize::MAX).with_albedos_of(scene);
            cache.cover_albedos(&mesh);
            let key = SampleKey {
                vertex: 0,
                side: Side::Front,
            };
            cache.insert(key, diffuse_sample(SampleParts::direct_only([2.0; 3], 0.5)));
            cache.estimate(key, None).expect("cached")
        };
        let bright = shown([WHITE; 4]);
        let dark = shown([DARK, DARK, WHITE, DARK]);
        let ratio = dark.rgb()[0] / bright.rgb()[0];
        assert!((0.2..0.35).contains(&ratio), "luminance ratio {ratio}");
        let error_ratio = (dark.luminance_variance() / bright.luminance_variance()).sqrt();
        assert!(
            (0.2..0.35).contains(&error_ratio),
            "standard error ratio {error_ratio}"
        );
    }
}
