//! Object-space shading points (DESIGN.md §5, §8): a base triangle, barycentric coordinates and a
//! side become a position and the normal of the shaded side; a point hidden inside geometry is
//! moved into the visible part of its face.
//!
//! The thesis's vertices hidden inside geometry came back black (§5.2.2, "black walls"): a floor
//! vertex under a wall or a column base sees only the inside of the solid. Such a point is found
//! with a few short probe rays over its side's hemisphere: when nearly all of them are blocked at
//! once (by geometry very close, or by a back face nearby: the inside of a closed solid), the point
//! is hidden, and the nearest visible spot among a fixed pattern of points on the same triangle is
//! shaded instead.

use glam::Vec3;
use protocol::renderer_link::{SampleKey, ShadePoint};
use protocol::{Side, Vec3f};

use crate::counters::{RayCounts, RayKind};
use crate::world::{Surface, World};

/// Probe rays of the hidden test (a fixed, cosine-distributed pattern).
const PROBES: usize = 16;
/// A point is hidden when at least this many probes are blocked. A point in a room's corner has
/// three quarters of its hemisphere close to the walls: 12 of 16, below the threshold.
const HIDDEN_WHEN_BLOCKED: usize = 15;
/// "Very close" as a fraction of the scene's extent. With 0.02 (and 0.25 below), 1.7 % of the
/// visible points of bracara's street view VR were judged hidden (its streets are narrow); with
/// these values 0.13 %, and none of Sponza's views S1 and S2 (160×120 pixels each).
const CLOSE_OF_EXTENT: f32 = 0.005;
/// How far a back face still counts as the inside of a solid around the point.
const BACK_FACE_OF_EXTENT: f32 = 0.1;
/// Candidate spots on a triangle: centroids of a 1:N² split (N = 5: 25 candidates).
const CANDIDATE_GRID: u32 = 5;
/// Barycentric coordinates may stray this far outside the triangle (rounding in the SMA).
const BARY_TOLERANCE: f32 = 1e-3;

/// A shading point ready to shade.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Located {
    pub surface: Surface,
    /// The point was hidden and moved (reply flag `MOVED_OFF_HIDDEN`).
    pub moved: bool,
}

/// Why a request names no usable point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InvalidPoint {
    NoSuchTriangle,
    BadBarycentrics,
    DegenerateTriangle,
}

/// The front-side shading point where the ray from world position `origin` along `dir` first
/// hits, `None` where it hits nothing. Its key names vertex 0: it stands for no mesh vertex
/// (benchmarks, tests).
pub fn front_point_hit_by(
    world: &World,
    origin: Vec3,
    dir: Vec3,
    eye: Option<Vec3f>,
) -> Option<ShadePoint> {
    let origin = world.to_local(origin);
    let hit = world.bvh.closest_hit(origin, dir, f32::INFINITY)?;
    let q = origin + dir * hit.t;
    let [a, b, c] = world.scene.mesh.triangle_positions(hit.triangle as usize);
    Some(ShadePoint {
        key: SampleKey {
            vertex: 0,
            side: Side::Front,
        },
        base_triangle: hit.triangle,
        bary: barycentrics(q, a, b, c),
        side: Side::Front,
        eye,
    })
}

/// Barycentric weights of vertices 1 and 2 for `q` in the plane of (a, b, c).
pub(crate) fn barycentrics(q: Vec3, a: Vec3, b: Vec3, c: Vec3) -> [f32; 2] {
    let (e1, e2, d) = (b - a, c - a, q - a);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let det = (d11 * d22 - d12 * d12).max(f32::MIN_POSITIVE);
    [(d22 * d1 - d12 * d2) / det, (d11 * d2 - d12 * d1) / det]
}

/// Position and side normal of `p` (before the hidden-point check).
pub fn surface_of(world: &World, p: &ShadePoint) -> Result<Surface, InvalidPoint> {
    let t = p.base_triangle as usize;
    if t >= world.triangle_count() {
        return Err(InvalidPoint::NoSuchTriangle);
    }
    let [u, v] = p.bary;
    let valid = u.is_finite()
        && v.is_finite()
        && u >= -BARY_TOLERANCE
        && v >= -BARY_TOLERANCE
        && u + v <= 1.0 + BARY_TOLERANCE;
    if !valid {
        return Err(InvalidPoint::BadBarycentrics);
    }
    let ng = world.face_normal(p.base_triangle);
    if ng == Vec3::ZERO {
        return Err(InvalidPoint::DegenerateTriangle);
    }
    let (u, v) = (u.clamp(0.0, 1.0), v.clamp(0.0, 1.0));
    let (u, v) = if u + v > 1.0 {
        (u / (u + v), v / (u + v))
    } else {
        (u, v)
    };
    let mesh = &world.scene.mesh;
    let corners = mesh.triangle_positions(t);
    let weights = [1.0 - u - v, u, v];
    let blend = |f: &dyn Fn(usize) -> Vec3| (0..3).map(|i| f(i) * weights[i]).sum::<Vec3>();
    let position = blend(&|i| corners[i]);
    let vertices = mesh.triangles[t].vertices;
    let canonical = blend(&|i| {
        mesh.normals
            .get(vertices[i] as usize)
            .copied()
            .unwrap_or(Vec3::ZERO)
    });
    // The side is relative to the vertex's canonical normal (DESIGN.md §5); the geometric normal,
    // flipped into that hemisphere, is the normal of the shaded side.
    let toward = if canonical.dot(ng).abs() > 1e-6 {
        canonical * p.side.sign()
    } else {
        ng * p.side.sign()
    };
    let normal = if ng.dot(toward) >= 0.0 { ng } else { -ng };
    let position = world.offset.inset(position, corners);
    Ok(Surface {
        position,
        normal,
        triangle: p.base_triangle,
    })
}

/// The point of a request, moved off a hidden spot when needed.
pub fn locate(
    world: &World,
    p: &ShadePoint,
    counts: &mut RayCounts,
) -> Result<Located, InvalidPoint> {
    let surface = surface_of(world, p)?;
    if !is_hidden(world, &surface, counts) {
        return Ok(Located {
            surface,
            moved: false,
        });
    }
    Ok(match nearest_visible_spot(world, &surface, counts) {
        Some(visible) => Located {
            surface: visible,
            moved: true,
        },
        None => Located {
            surface,
            moved: false,
        },
    })
}

/// Whether nearly every probe ray from `s` is blocked at once.
pub fn is_hidden(world: &World, s: &Surface, counts: &mut RayCounts) -> bool {
    let origin = world.offset.origin(s.position, s.normal);
    let close = CLOSE_OF_EXTENT * world.extent;
    let back_face_range = BACK_FACE_OF_EXTENT * world.extent;
    let mut blocked = 0;
    for (i, local) in probe_pattern().enumerate() {
        let dir = crate::sampling::to_world(s.normal, local);
        let hit = world.trace_within(origin, dir, back_face_range, RayKind::Probe, counts);
        let is_blocked = hit.is_some_and(|hit| {
            let back_face = world.face_normal(hit.triangle).dot(dir) > 0.0;
            hit.t < close || back_face
        });
        blocked += is_blocked as usize;
        // Stop as soon as the verdict cannot change.
        if blocked >= HIDDEN_WHEN_BLOCKED || (i + 1 - blocked) > PROBES - HIDDEN_WHEN_BLOCKED {
            break;
        }
    }
    blocked >= HIDDEN_WHEN_BLOCKED
}

/// A fixed cosine-weighted pattern (Hammersley points), in the local frame (z = normal).
fn probe_pattern() -> impl Iterator<Item = Vec3> {
    (0..PROBES).map(|i| {
        let u0 = (i as f32 + 0.5) / PROBES as f32;
        let u1 = (i as u32).reverse_bits() as f32 / 4_294_967_296.0;
        let r = u0.sqrt();
        let phi = 2.0 * std::f32::consts::PI * u1;
        Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u0).max(0.0).sqrt())
    })
}

/// The visible candidate spot of `s`'s triangle nearest to `s`.
fn nearest_visible_spot(world: &World, s: &Surface, counts: &mut RayCounts) -> Option<Surface> {
    let corners = world.scene.mesh.triangle_positions(s.triangle as usize);
    let mut spots: Vec<Vec3> = candidate_barycentrics()
        .map(|[u, v]| corners[0] * (1.0 - u - v) + corners[1] * u + corners[2] * v)
        .collect();
    spots.sort_by(|a, b| {
        a.distance_squared(s.position)
            .total_cmp(&b.distance_squared(s.position))
    });
    spots
        .into_iter()
        .map(|position| Surface { position, ..*s })
        .find(|candidate| !is_hidden(world, candidate, counts))
}

/// Centroids of the N² sub-triangles of a regular 1:N² split, as barycentrics (u, v).
fn candidate_barycentrics() -> impl Iterator<Item = [f32; 2]> {
    let n = CANDIDATE_GRID;
    let k = n as f32;
    (0..n).flat_map(move |i| {
        (0..n - i).flat_map(move |j| {
            let (i, j) = (i as f32, j as f32);
            // Upward sub-triangle (i, j), (i+1, j), (i, j+1) and, when it exists, the downward one.
            let up = [(3.0 * i + 1.0) / (3.0 * k), (3.0 * j + 1.0) / (3.0 * k)];
            let down = [(3.0 * i + 2.0) / (3.0 * k), (3.0 * j + 2.0) / (3.0 * k)];
            let has_down = i + j + 2.0 <= k;
            std::iter::once(up).chain(has_down.then_some(down))
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_cover_the_triangle_once_each() {
        let c: Vec<[f32; 2]> = candidate_barycentrics().collect();
        assert_eq!(c.len(), (CANDIDATE_GRID * CANDIDATE_GRID) as usize);
        for [u, v] in &c {
            assert!(*u > 0.0 && *v > 0.0 && u + v < 1.0);
        }
        let mean_u = c.iter().map(|b| b[0]).sum::<f32>() / c.len() as f32;
        assert!((mean_u - 1.0 / 3.0).abs() < 1e-5, "{mean_u}");
    }

    #[test]
    fn probe_pattern_is_unit_and_upward() {
        let dirs: Vec<Vec3> = probe_pattern().collect();
        assert_eq!(dirs.len(), PROBES);
        for d in dirs {
            assert!((d.length() - 1.0).abs() < 1e-5 && d.z > 0.0);
        }
    }
}
