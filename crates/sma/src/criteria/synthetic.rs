//! A synthetic walkthrough state for tests and for choosing criterion defaults: a flat grid of
//! `n` × `n` unit squares seen from above on a `res` × `res` image, shaded by a known function,
//! so the error of the Gouraud image against the truth is exact and cheap.

use glam::{Vec2, Vec3};
use protocol::renderer_link::{Quality, SampleKey};
use protocol::{SampleParts, Side};

use crate::cache::{CachedSample, ShadingCache};
use crate::criteria::{CriterionInput, LuminanceImage};
use crate::mesh::{MeshParams, NodeId, SubdivisionMesh};
use crate::visible_set::{VisibleLeaf, VisibleSet};

/// The shading functions of the experiments, luminance over the plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shading {
    Flat,
    /// A hard shadow line `x + 0.3 y = 0.41 n` (lit 1.0, shadow 0.1) across the grid.
    ShadowEdge,
    /// A smooth gradient with ripples.
    Smooth,
    /// A small shadow disc inside a grid square, touching no vertex (thesis fig. 4.10).
    Blob,
    /// A faint smooth ripple: neighbouring vertices differ by a few 8-bit display steps, more
    /// than one and less than eq. 4.3's S_min, the interpolation error left in a view that
    /// reads as converged.
    Faint,
}

impl Shading {
    fn shadow_line(n: u32) -> (Vec2, f32) {
        (
            Vec2::new(1.0, 0.3).normalize(),
            0.41 * n as f32 / Vec2::new(1.0, 0.3).length(),
        )
    }

    pub fn luminance(self, p: Vec2, n: u32) -> f32 {
        match self {
            Shading::Flat => 0.5,
            Shading::ShadowEdge => {
                let (normal, offset) = Self::shadow_line(n);
                if p.dot(normal) > offset { 1.0 } else { 0.1 }
            }
            Shading::Smooth => 0.5 + 0.3 * (p.x * 1.3).sin() * (p.y * 0.9).cos() + 0.05 * p.x,
            Shading::Blob => {
                let centre = Vec2::splat(n as f32 / 2.0 - 0.5);
                if p.distance(centre) < 0.3 { 0.05 } else { 0.8 }
            }
            Shading::Faint => 0.5 + 0.02 * (p.x * 0.7).sin(),
        }
    }
}

pub struct Synthetic {
    pub mesh: SubdivisionMesh,
    pub cache: ShadingCache,
    pub visible: VisibleSet,
    pub image: LuminanceImage,
    pub shading: Shading,
    n: u32,
    res: u32,
}

impl Synthetic {
    pub fn new(n: u32, res: u32, shading: Shading) -> Self {
        let mesh = SubdivisionMesh::new(
            &crate::mesh::grid_mesh(n),
            MeshParams {
                min_edge_length: 0.0,
                ..Default::default()
            },
        );
        let mut s = Synthetic {
            mesh,
            cache: ShadingCache::new(usize::MAX),
            visible: VisibleSet::default(),
            image: LuminanceImage::default(),
            shading,
            n,
            res,
        };
        s.shade(
            (0..s.mesh.vertex_count() as u32)
                .collect::<Vec<_>>()
                .as_slice(),
        );
        s.project();
        s
    }

    pub fn input(&self) -> CriterionInput<'_> {
        CriterionInput {
            mesh: &self.mesh,
            cache: &self.cache,
            visible: &self.visible,
            l_white: self.cache.l_white(&self.mesh, &self.visible),
            image: Some(&self.image),
        }
    }

    /// As [`Synthetic::new`], but every sample is a 64-path estimate whose paths scatter by
    /// `relative_noise` of the luminance: its mean carries the noise of those paths, and its
    /// variance says how much (DESIGN.md §5).
    pub fn noisy(n: u32, res: u32, shading: Shading, relative_noise: f32, seed: u64) -> Self {
        use rand::{RngExt, SeedableRng};
        let mut s = Synthetic::new(n, res, shading);
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        let paths = Quality::INTERACTIVE.paths;
        s.cache = ShadingCache::new(usize::MAX);
        for vertex in 0..s.mesh.vertex_count() as u32 {
            let l = shading.luminance(s.mesh.vertex(vertex).position.truncate(), n);
            let per_path = relative_noise * l;
            // Uniform noise of the mean's standard deviation: half-width sqrt(3) of it.
            let half = 3f32.sqrt() * per_path / (paths as f32).sqrt();
            let mean = l + rng.random_range(-half..=half);
            let sample = CachedSample {
                parts: SampleParts::direct_only([mean; 3], per_path * per_path),
                quality: Quality::INTERACTIVE,
                view_dependent: false,
                eye: None,
                last_seen: 0,
            };
            s.cache.insert(
                SampleKey {
                    vertex,
                    side: Side::Front,
                },
                sample,
            );
        }
        s
    }

    /// Refines the leaves (none below one pixel), shades the new vertices, re-projects.
    pub fn refine_and_shade(&mut self, leaves: &[NodeId]) {
        let world_per_pixel = self.n as f32 / self.res as f32;
        // `too_small` cannot look at the mesh while it is being refined: decide beforehand.
        let small: Vec<NodeId> = leaves
            .iter()
            .copied()
            .filter(|&id| {
                let [a, b, c] = self.mesh.leaf_positions(id);
                0.5 * (b - a).cross(c - a).length() < 2.0 * world_per_pixel * world_per_pixel
            })
            .collect();
        let steps = self.mesh.refine(leaves, &|id| small.contains(&id));
        let new: Vec<u32> = steps.into_iter().flat_map(|s| s.new_vertices).collect();
        self.shade(&new);
        self.project();
    }

    /// Samples computed so far.
    pub fn samples(&self) -> usize {
        self.cache.len()
    }

    /// Mean absolute luminance error of the Gouraud image against the shading function.
    pub fn error(&self) -> f64 {
        let total: f64 = (0..self.res * self.res)
            .map(|i| {
                let truth = self
                    .shading
                    .luminance(self.pixel_centre(i % self.res, i / self.res), self.n);
                f64::from((self.image.luminance[i as usize] - truth).abs())
            })
            .sum();
        total / f64::from(self.res * self.res)
    }

    /// Whether the leaf's vertices lie on both sides of the shadow line.
    pub fn straddles_shadow(&self, leaf: NodeId) -> bool {
        let lit = self
            .mesh
            .leaf_positions(leaf)
            .map(|p| self.shading.luminance(p.truncate(), self.n) > 0.5);
        lit.contains(&true) && lit.contains(&false)
    }

    /// Distance from the leaf's centroid to the shadow line.
    pub fn distance_to_shadow(&self, leaf: NodeId) -> f32 {
        let [a, b, c] = self.mesh.leaf_positions(leaf);
        let (normal, offset) = Shading::shadow_line(self.n);
        (((a + b + c) / 3.0).truncate().dot(normal) - offset).abs()
    }

    fn shade(&mut self, vertices: &[u32]) {
        for &vertex in vertices {
            let l = self
                .shading
                .luminance(self.mesh.vertex(vertex).position.truncate(), self.n);
            let sample = CachedSample {
                parts: SampleParts::direct_only([l; 3], 0.0),
                quality: Quality::INTERACTIVE,
                view_dependent: false,
                eye: None,
                last_seen: 0,
            };
            self.cache.insert(
                SampleKey {
                    vertex,
                    side: Side::Front,
                },
                sample,
            );
        }
    }

    fn pixel_centre(&self, x: u32, y: u32) -> Vec2 {
        (Vec2::new(x as f32, y as f32) + 0.5) * (self.n as f32 / self.res as f32)
    }

    /// Rasterises the leaves from above: the ID image, the Gouraud luminance, the visible set.
    fn project(&mut self) {
        let pixels = (self.res * self.res) as usize;
        let mut image = LuminanceImage {
            width: self.res,
            height: self.res,
            luminance: vec![0.0; pixels],
            ids: vec![LuminanceImage::NONE; pixels],
        };
        let scale = self.res as f32 / self.n as f32;
        for leaf in self.mesh.leaves() {
            let p = self.mesh.leaf_positions(leaf).map(Vec3::truncate);
            let lum = self
                .cache
                .leaf_radiance(&self.mesh, leaf, Side::Front)
                .map(|rgb| rgb.map(conventions::luminance));
            let lo = (p[0].min(p[1]).min(p[2]) * scale).floor().max(Vec2::ZERO);
            let hi = (p[0].max(p[1]).max(p[2]) * scale)
                .ceil()
                .min(Vec2::splat(self.res as f32));
            for y in lo.y as u32..hi.y as u32 {
                for x in lo.x as u32..hi.x as u32 {
                    let i = (y * self.res + x) as usize;
                    if image.ids[i] != LuminanceImage::NONE {
                        continue;
                    }
                    if let Some(w) = barycentric(p, self.pixel_centre(x, y)) {
                        image.ids[i] = leaf;
                        image.luminance[i] =
                            lum.map_or(0.0, |l| w[0] * l[0] + w[1] * l[1] + w[2] * l[2]);
                    }
                }
            }
        }
        let mut counts = std::collections::BTreeMap::<NodeId, u32>::new();
        for &id in image.ids.iter().filter(|&&id| id != LuminanceImage::NONE) {
            *counts.entry(id).or_default() += 1;
        }
        self.visible = VisibleSet {
            leaves: counts
                .into_iter()
                .map(|(leaf, pixels)| VisibleLeaf {
                    leaf,
                    side: Side::Front,
                    pixels,
                })
                .collect(),
            width: self.res,
            height: self.res,
        };
        self.image = image;
    }
}

/// Barycentric weights of `q` in triangle `p` (either winding), if inside.
fn barycentric(p: [Vec2; 3], q: Vec2) -> Option<[f32; 3]> {
    let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
    if area == 0.0 {
        return None;
    }
    let w1 = (q - p[0]).perp_dot(p[2] - p[0]) / area;
    let w2 = (p[1] - p[0]).perp_dot(q - p[0]) / area;
    let w0 = 1.0 - w1 - w2;
    let eps = -1e-6;
    (w0 >= eps && w1 >= eps && w2 >= eps).then_some([w0, w1, w2])
}
