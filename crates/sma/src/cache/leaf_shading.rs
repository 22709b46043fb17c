//! What a viewer is sent of a shown leaf (DESIGN.md §5, "Parts, and textures"): per corner the
//! illumination, its direct share and the view-dependent radiance, which the viewer combines
//! with the albedo of each pixel; and beside them the radiance the SMA itself judges, with the
//! mean albedo around each vertex (`albedo`), as the criteria, L_white and the stopping rule read it.

use glam::Vec3;
use protocol::Side;
use protocol::renderer_link::SampleKey;
use protocol::texture::Texcoords;
use protocol::viewer_link::{CornerShading, DirectShare};

use super::{ShadingCache, slot_index};
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::sample::Estimate;

/// One shown leaf's corners, as seen from one eye.
#[derive(Clone, Debug, PartialEq)]
pub struct LeafShading {
    /// Per vertex the displayed radiance with the mean albedo around the vertex: what the luminance
    /// image of `nld-is` draws.
    pub radiance: [[f32; 3]; 3],
    /// What the viewer is sent.
    pub shading: CornerShading,
}

impl ShadingCache {
    /// The estimate of `key` a viewer is shown, before the albedo multiplies it, with its slot:
    /// for a view-dependent sample, that of the kept eye nearest `eye`.
    pub(super) fn stored_seen_from(
        &self,
        key: SampleKey,
        eye: Option<Vec3>,
    ) -> Option<(usize, Estimate)> {
        let slot = slot_index(key);
        let p = self.packed(slot)?;
        let nearest = eye
            .filter(|_| p.view_dependent())
            .and_then(|eye| self.nearest_eye(slot, eye));
        Some((slot, nearest.map_or_else(|| p.estimate(), |v| v.estimate)))
    }

    /// A leaf's corners as a viewer at `eye` is shown them, if all are cached (a failed vertex
    /// takes the mean of the others).
    pub fn leaf_shading_from(
        &self,
        mesh: &SubdivisionMesh,
        leaf: NodeId,
        side: Side,
        eye: Vec3,
    ) -> Option<LeafShading> {
        let corners = self.leaf_radiance_with(mesh, leaf, side, |key| {
            let (slot, stored) = self.stored_seen_from(key, Some(eye))?;
            let [r, g, b] = self.displayed(slot, &stored).rgb();
            let parts = &stored.parts;
            let illumination: [f32; 3] =
                std::array::from_fn(|c| parts.direct.rgb[c] + parts.indirect.rgb[c]);
            let share = DirectShare::of(parts.direct.rgb, illumination).fraction();
            let [ir, ig, ib] = illumination;
            let [vr, vg, vb] = parts.view_dependent.rgb;
            Some([r, g, b, ir, ig, ib, vr, vg, vb, share])
        })?;
        let view_dependent = corners.map(|c| [c[6], c[7], c[8]]);
        Some(LeafShading {
            radiance: corners.map(|c| [c[0], c[1], c[2]]),
            shading: CornerShading {
                illumination: corners.map(|c| [c[3], c[4], c[5]]),
                direct_share: corners.map(|c| DirectShare((c[9] * 255.0).round() as u8)),
                view_dependent: view_dependent
                    .iter()
                    .flatten()
                    .any(|&v| v != 0.0)
                    .then_some(view_dependent),
            },
        })
    }

    /// The material of a leaf's scene triangle and its corners' texture coordinates (DESIGN.md
    /// §5): material 0 and no coordinates without a scene.
    pub fn leaf_surface(&self, mesh: &SubdivisionMesh, leaf: NodeId) -> (u16, Texcoords) {
        self.albedos.leaf_surface(mesh, leaf)
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use protocol::{PartEstimate, SampleParts};

    use super::*;
    use crate::cache::CachedSample;
    use crate::mesh::MeshParams;

    /// On a leaf of bracara's textured paving: the viewer is sent the illumination, its direct
    /// share and no view-dependent part, while the SMA judges the mean albedo around each vertex times
    /// it; the leaf's material is its scene triangle's, its coordinates the scene's at its
    /// corners, whole periods off.
    #[test]
    fn a_leaf_is_sent_its_illumination_material_and_coordinates() {
        let scene = Arc::new(scene::load("bracara-textured").expect("built-in"));
        let mesh = SubdivisionMesh::new(&scene.mesh, MeshParams::default());
        let mut cache = ShadingCache::new(usize::MAX).with_albedos_of(Arc::clone(&scene));
        cache.cover_albedos(&mesh);
        let leaf = (0..mesh.base_count() as NodeId)
            .find(|&t| {
                scene.material_of(t as usize).name == "ground"
                    && scene.material_of(t as usize).diffuse_map.is_some()
            })
            .expect("a textured ground triangle");
        let part = |rgb| PartEstimate {
            rgb,
            luminance_variance: 0.0,
        };
        for vertex in mesh.node(leaf).vertices {
            let parts = SampleParts {
                direct: part([2.0, 3.0, 4.0]),
                indirect: part([1.0; 3]),
                view_dependent: part([0.0; 3]),
            };
            let sample = CachedSample::diffuse(parts);
            cache.insert(
                SampleKey {
                    vertex,
                    side: Side::Front,
                },
                sample,
            );
        }
        let shown = cache
            .leaf_shading_from(&mesh, leaf, Side::Front, Vec3::ZERO)
            .expect("all cached");
        let want = [3.0, 4.0, 5.0];
        for (k, vertex) in mesh.node(leaf).vertices.into_iter().enumerate() {
            let illumination = shown.shading.illumination[k];
            assert!(
                illumination
                    .iter()
                    .zip(want)
                    .all(|(a, b)| (a - b).abs() <= 0.02),
                "{illumination:?}"
            );
            let albedo = Vec3::from(cache.albedos.at(vertex));
            let radiance = Vec3::from(shown.radiance[k]);
            assert!((radiance - albedo * Vec3::from(want)).abs().max_element() <= 0.05);
        }
        let share = shown.shading.direct_share[0].fraction();
        let expected = conventions::luminance([2.0, 3.0, 4.0]) / conventions::luminance(want);
        assert!(
            (share - expected).abs() <= 1.0 / 255.0,
            "{share} vs {expected}"
        );
        assert_eq!(shown.shading.view_dependent, None);

        let (material, texcoords) = cache.leaf_surface(&mesh, leaf);
        let (t, corners) = mesh.leaf_in_scene_triangle(leaf);
        let t = t as usize;
        assert_eq!(u32::from(material), scene.mesh.triangles[t].material);
        let map = scene.material_of(t).diffuse_map.as_ref().expect("textured");
        for (uv, bary) in texcoords.decode().into_iter().zip(corners) {
            let want = scene.texcoord_at(t, bary) * map.scale + map.offset;
            let off = want - glam::Vec2::from(uv);
            assert!(
                (off - off.round()).abs().max_element() < 1e-3,
                "{uv:?} vs {want}"
            );
        }
    }
}
