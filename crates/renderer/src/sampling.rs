//! Sampling routines shared by lights, materials and the estimator.

use std::f32::consts::{FRAC_1_PI, PI};

use glam::Vec3;
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;

/// The random stream of one shading point or pixel.
pub type Rng = Pcg64Mcg;

/// The stream for item `index` of a job seeded with `seed`. Depends on nothing else, so an answer
/// does not depend on thread scheduling (the service test compares it with in-process shading).
pub fn stream(seed: u64, index: u64) -> Rng {
    Pcg64Mcg::seed_from_u64(splitmix(
        seed ^ splitmix(index.wrapping_add(0x9E37_79B9_7F4A_7C15)),
    ))
}

/// SplitMix64 finaliser: decorrelates nearby seeds.
fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

pub fn uniform2(rng: &mut Rng) -> [f32; 2] {
    [rng.random::<f32>(), rng.random::<f32>()]
}

pub fn uniform3(rng: &mut Rng) -> [f32; 3] {
    [
        rng.random::<f32>(),
        rng.random::<f32>(),
        rng.random::<f32>(),
    ]
}

/// An orthonormal frame (t, b, n) around unit `n` (Duff et al. 2017, branchless).
pub fn frame(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// Local (x, y, z = along `n`) to world.
pub fn to_world(n: Vec3, local: Vec3) -> Vec3 {
    let (t, b) = frame(n);
    t * local.x + b * local.y + n * local.z
}

/// Cosine-weighted direction about `n`; pdf = cos / pi.
pub fn cosine_hemisphere(n: Vec3, u: [f32; 2]) -> Vec3 {
    let r = u[0].sqrt();
    let phi = 2.0 * PI * u[1];
    let z = (1.0 - u[0]).max(0.0).sqrt();
    to_world(n, Vec3::new(r * phi.cos(), r * phi.sin(), z))
}

pub fn cosine_pdf(cos: f32) -> f32 {
    cos.max(0.0) * FRAC_1_PI
}

/// Uniform direction in the cone of half-angle with `one_minus_cos` = 1 - cos(half-angle) about
/// `axis`; pdf = 1 / (2 pi one_minus_cos). Written with 1 - cos so a 0.27° sun keeps its precision.
pub fn uniform_cone(axis: Vec3, one_minus_cos: f32, u: [f32; 2]) -> Vec3 {
    let h = u[0] * one_minus_cos; // 1 - cos(theta)
    let cos = 1.0 - h;
    let sin = (h * (2.0 - h)).max(0.0).sqrt();
    let phi = 2.0 * PI * u[1];
    to_world(axis, Vec3::new(sin * phi.cos(), sin * phi.sin(), cos))
}

/// Uniform barycentrics on a triangle (Heitz 2019 low-distortion map would also do; this is the
/// classic square-root warp).
pub fn uniform_triangle(u: [f32; 2]) -> [f32; 2] {
    let s = u[0].sqrt();
    [s * (1.0 - u[1]), s * u[1]]
}

/// Rec. 709 luminance (DESIGN.md §6, `conventions::luminance`) of a radiance vector.
pub fn luminance(c: Vec3) -> f32 {
    conventions::luminance(c.to_array())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthonormal() {
        for n in [
            Vec3::X,
            Vec3::NEG_Z,
            Vec3::new(0.3, -0.4, 0.5).normalize(),
            Vec3::Z,
        ] {
            let (t, b) = frame(n);
            assert!(t.dot(b).abs() < 1e-5 && t.dot(n).abs() < 1e-5 && b.dot(n).abs() < 1e-5);
            assert!((t.length() - 1.0).abs() < 1e-5 && (b.length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn cosine_samples_have_mean_cos_two_thirds() {
        let n = Vec3::new(1.0, 2.0, -0.5).normalize();
        let mut rng = stream(1, 2);
        let k = 20_000;
        let mean: f32 = (0..k)
            .map(|_| cosine_hemisphere(n, uniform2(&mut rng)).dot(n))
            .sum::<f32>()
            / k as f32;
        // E[cos] under pdf cos/pi is 2/3; standard deviation of cos is sqrt(1/2 - 4/9) = 0.236.
        assert!(
            (mean - 2.0 / 3.0).abs() < 4.0 * 0.236 / (k as f32).sqrt(),
            "{mean}"
        );
    }

    #[test]
    fn cone_samples_stay_in_the_cone() {
        let axis = Vec3::new(0.2, 1.0, 0.1).normalize();
        let half = 0.53f32.to_radians() / 2.0;
        let omc = 2.0 * (half / 2.0).sin().powi(2);
        let mut rng = stream(3, 4);
        for _ in 0..1000 {
            let d = uniform_cone(axis, omc, uniform2(&mut rng));
            assert!((d.length() - 1.0).abs() < 1e-5);
            assert!(d.dot(axis) >= half.cos() - 1e-6);
        }
    }

    #[test]
    fn streams_differ_by_index_and_seed() {
        let a: f32 = stream(1, 0).random();
        let b: f32 = stream(1, 1).random();
        let c: f32 = stream(2, 0).random();
        let a2: f32 = stream(1, 0).random();
        assert_eq!(a, a2);
        assert!(a != b && a != c);
    }
}
