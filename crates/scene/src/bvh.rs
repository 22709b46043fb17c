//! The one CWBVH builder of the system (obvhs, DESIGN.md §7): the scene's triangles in the form
//! obvhs builds from, and the build itself, used by the renderer's tracer and by the CPU
//! visibility estimate here.

use std::time::Duration;

use obvhs::BvhBuildParams;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::triangle::Triangle as BvhTriangle;

use crate::model::Mesh;

/// BVH build presets of obvhs. `Slow` splits large triangles (spatial pre-splits); on Sponza it
/// traced fastest with obvhs's own traversal (DEPENDENCY-NOTES.md). `VerySlow` adds to the splits
/// a reinsertion pass over every node (obvhs's best tree): on Sponza it builds in about 2.5× the
/// time of `Slow` (160 against 65 ms, once per scene load; BENCHMARKS.md, "Renderer") and the
/// renderer's wide traversal ran its path tracing about 6 % faster on it (Sponza S1, the two
/// trees timed in turn).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildPreset {
    Fast,
    Medium,
    Slow,
    VerySlow,
}

impl BuildPreset {
    pub fn params(self) -> BvhBuildParams {
        match self {
            BuildPreset::Fast => BvhBuildParams::fast_build(),
            BuildPreset::Medium => BvhBuildParams::medium_build(),
            BuildPreset::Slow => BvhBuildParams::slow_build(),
            BuildPreset::VerySlow => BvhBuildParams::very_slow_build(),
        }
    }
}

/// The mesh's triangles in the form obvhs builds from.
pub fn bvh_triangles(mesh: &Mesh) -> Vec<BvhTriangle> {
    (0..mesh.triangles.len())
        .map(|t| {
            let [a, b, c] = mesh.triangle_positions(t);
            BvhTriangle {
                v0: a.into(),
                v1: b.into(),
                v2: c.into(),
            }
        })
        .collect()
}

/// The CWBVH over `triangles`. A split triangle appears once per reference: map hits back through
/// `primitive_indices`. obvhs' builder expects at least one primitive, so no triangles give an
/// empty BVH, which its traversal treats as "no nodes".
pub fn build_cwbvh(triangles: &[BvhTriangle], preset: BuildPreset) -> CwBvh {
    if triangles.is_empty() {
        return CwBvh::default();
    }
    build_cwbvh_from_tris(triangles, preset.params(), &mut Duration::default())
}
