//! The two visibility levels of DESIGN.md §3 (thesis §4.1, "segundo nível de visibilidade"):
//! level 1 renders the base mesh (uploaded once) and finds the visible base triangles; level 2
//! renders only the leaves of those (and of their neighbours) and yields the visible set V_t keyed
//! by (leaf, side), with pixel counts and centroids, then its guard leaves (`guards`), and the
//! leaf under every pixel.

use glam::Vec3;
use protocol::Side;
use protocol::viewer_link::Camera;

use super::gpu::{Gpu, GpuError};
use super::guards::add_guards;
use super::id_pass::{Coverage, IdPass, TriangleBuffer};
use super::pixel_leaves::PixelLeaves;
use super::view::View;
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::visible_set::{VisibleLeaf, VisibleSet};

/// The result of one two-level pass for one camera.
#[derive(Clone, Debug, Default)]
pub struct LeafView {
    pub visible: VisibleSet,
    /// Pixel centroid of each entry of `visible.leaves`, same order.
    pub centroids: Vec<(f32, f32)>,
    /// The leaf seen at each pixel, row-major from the top-left; `None` for background.
    pub pixel_leaves: PixelLeaves,
    /// The camera it was seen from: the view can be carried over to a changed mesh
    /// (`carry_over`) only for that camera.
    pub camera: Option<Camera>,
    /// Base triangles visible at level 1, and leaves submitted at level 2 (for benchmarks).
    pub visible_bases: usize,
    pub submitted_leaves: usize,
}

impl LeafView {
    /// Heap bytes by capacity: the visible leaves, their centroids and the per-pixel leaves.
    pub fn heap_bytes(&self) -> usize {
        self.visible.leaves.capacity() * size_of::<crate::visible_set::VisibleLeaf>()
            + self.centroids.capacity() * size_of::<(f32, f32)>()
            + self.pixel_leaves.heap_bytes()
    }
}

/// Cameras whose level-1 result is kept: one per viewer resting while another walks.
const KEPT_LEVEL1: usize = 8;

/// Owns the device, the ID pipeline and the uploaded base mesh.
pub struct Visibility {
    gpu: Gpu,
    pass: IdPass,
    /// Relative to the centre of the scene's bounds: uploaded once for every camera, and as
    /// precise as a centred scene's wherever the scene lies (`view`).
    base: TriangleBuffer,
    leaves: TriangleBuffer,
    /// Scene bounds, for near and far planes that hold the whole scene.
    bounds: (Vec3, Vec3),
    /// The visible base triangles of the latest cameras, latest first. The base mesh never
    /// changes, so level 1 depends on the camera alone: a pass that follows a refinement round
    /// (the leaves changed, the camera did not) renders level 2 only. On Sponza level 1 was
    /// about a third of a pass, and the passes most of the SMA's time.
    level1: Vec<(Camera, Vec<u32>)>,
}

impl Visibility {
    pub fn new(gpu: Gpu, mesh: &SubdivisionMesh, bounds: (Vec3, Vec3)) -> Self {
        let pass = IdPass::new(&gpu);
        let mut base = TriangleBuffer::default();
        let base_triangles: Vec<[Vec3; 3]> = (0..mesh.base_count() as NodeId)
            .map(|b| mesh.leaf_positions(b))
            .collect();
        base.upload(
            &gpu,
            &base_triangles,
            (0.5 * (bounds.0 + bounds.1)).as_dvec3(),
        );
        Visibility {
            gpu,
            pass,
            base,
            leaves: TriangleBuffer::default(),
            bounds,
            level1: Vec::new(),
        }
    }

    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    pub fn view(&self, camera: &Camera) -> View {
        scene_view(camera, self.bounds)
    }

    /// Levels 1 and 2 for one camera, and the guards of what level 2 sees.
    pub fn leaf_view(
        &mut self,
        mesh: &SubdivisionMesh,
        camera: &Camera,
    ) -> Result<LeafView, GpuError> {
        let view = self.view(camera);
        let (w, h) = (camera.width, camera.height);
        let bases = self.visible_bases(mesh, camera, &view)?;
        let submitted: Vec<NodeId> = with_neighbours(mesh, &bases)
            .into_iter()
            .flat_map(|b| mesh.leaves_of_base(b))
            .collect();
        let positions: Vec<[Vec3; 3]> = submitted.iter().map(|&l| mesh.leaf_positions(l)).collect();
        self.leaves.upload(&self.gpu, &positions, view.eye());
        let level2 = self.pass.render(&self.gpu, &self.leaves, &view)?;
        let coverage = level2.coverage(submitted.len());
        let eye = camera.eye_vec();
        let (mut leaves, mut centroids) = (Vec::new(), Vec::new());
        for (i, c) in coverage.iter().enumerate().filter(|(_, c)| c.pixels > 0) {
            let leaf = submitted[i];
            leaves.push(VisibleLeaf {
                leaf,
                side: side_facing(mesh, leaf, eye),
                pixels: c.pixels,
            });
            centroids.push(Coverage::centroid(c));
        }
        let pixel_leaves = level2
            .ids
            .iter()
            .map(|&id| id.checked_sub(1).map(|i| submitted[i as usize]))
            .collect();
        let mut view = LeafView {
            visible: VisibleSet {
                leaves,
                width: w,
                height: h,
            },
            centroids,
            pixel_leaves,
            camera: Some(camera.clone()),
            visible_bases: bases.len(),
            submitted_leaves: submitted.len(),
        };
        add_guards(&mut view, mesh, camera);
        Ok(view)
    }
}

impl Visibility {
    /// Level 1: the base triangles `camera` sees, rendered unless kept from an earlier pass.
    fn visible_bases(
        &mut self,
        mesh: &SubdivisionMesh,
        camera: &Camera,
        view: &View,
    ) -> Result<Vec<u32>, GpuError> {
        if let Some(at) = self.level1.iter().position(|(c, _)| c == camera) {
            let kept = self.level1.remove(at);
            self.level1.insert(0, kept);
            return Ok(self.level1[0].1.clone());
        }
        let level1 = self.pass.render(&self.gpu, &self.base, view)?;
        let bases: Vec<u32> = level1
            .coverage(mesh.base_count())
            .iter()
            .enumerate()
            .filter(|(_, c)| c.pixels > 0)
            .map(|(b, _)| b as u32)
            .collect();
        self.level1.insert(0, (camera.clone(), bases.clone()));
        self.level1.truncate(KEPT_LEVEL1);
        Ok(bases)
    }
}

/// `bases` and the base triangles that share an edge with one of them, in order. Level 1 gives a
/// pixel centre lying within a rounding of a base edge to either side, and level 2, drawing
/// other vertices along that edge (the leaves' midpoints), may give it to the other side: were
/// that base left out, level 2 would see the background there, a crack no leaf of either base
/// fills (a needle of a base triangle on Sponza beside its neighbour, DESIGN.md §3 step 3).
fn with_neighbours(mesh: &SubdivisionMesh, bases: &[u32]) -> Vec<u32> {
    let mut all: Vec<u32> = bases
        .iter()
        .flat_map(|&b| std::iter::once(b).chain(mesh.base_neighbours(b)))
        .collect();
    all.sort_unstable();
    all.dedup();
    all
}

/// The view of a scene with `bounds`: far reaches the farthest corner of the bounds; near is a
/// small fraction of it (depth is reversed-Z float, so the ratio costs no precision).
pub fn scene_view(camera: &Camera, (lo, hi): (Vec3, Vec3)) -> View {
    let eye = camera.eye_vec();
    let far = (eye - lo).abs().max((eye - hi).abs()).length().max(1e-3) * 1.01;
    View {
        camera: camera.pinhole(),
        near: far * 1e-5,
        far,
    }
}

/// The side of `node` that faces `eye`, relative to its vertices' canonical normals
/// (DESIGN.md §5). A pinhole camera sees a flat triangle from exactly the side of its plane the eye
/// is on, so this is exact for every pixel of the triangle.
pub fn side_facing(mesh: &SubdivisionMesh, node: NodeId, eye: Vec3) -> Side {
    let [a, b, c] = mesh.leaf_positions(node);
    let face = (b - a).cross(c - a);
    let canonical: Vec3 = mesh
        .node(node)
        .vertices
        .iter()
        .map(|&v| mesh.vertex(v).normal)
        .sum();
    let toward_eye = face.dot(eye - (a + b + c) / 3.0);
    if toward_eye * face.dot(canonical) >= 0.0 {
        Side::Front
    } else {
        Side::Back
    }
}
