//! Scattering of the scene's materials (DESIGN.md §7): two-sided Lambertian by default, plus a
//! normalised Blinn–Phong glossy lobe (MTL `Ks`/`Ns`) or a perfect mirror (MTL `illum` 3/5) where a
//! material asks for one. Directions are unit vectors pointing away from the surface; `n` is the
//! normal of the side being shaded (surfaces are two-sided, the estimator picks the side).

use std::f32::consts::{FRAC_1_PI, PI};

use glam::Vec3;
use scene::{Material, Scattering};

use crate::counters::RayKind;
use crate::sampling::{cosine_hemisphere, luminance, to_world};

/// The view-dependent part of a material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Specular {
    None,
    /// Blinn–Phong: half-vector density D(h) = (ns + 1) / (2 pi) cos^ns(theta_h) and
    /// f = ks D(h) / (4 (wo . h)). Sampling h from D gives the weight f cos / pdf = ks cos(theta_i)
    /// <= ks, so the lobe never reflects more than ks of what it receives.
    Glossy {
        ks: Vec3,
        ns: f32,
    },
    Mirror {
        ks: Vec3,
    },
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bsdf {
    pub kd: Vec3,
    pub specular: Specular,
}

/// What a material reflects from one direction, lobe by lobe: the diffuse lobe's share, which at
/// a point's first vertex is illumination (DESIGN.md §5, "Parts, and textures"), and the glossy
/// lobe's, which stays view-dependent radiance.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Lobes {
    pub diffuse: Vec3,
    pub specular: Vec3,
}

impl Lobes {
    pub fn total(&self) -> Vec3 {
        self.diffuse + self.specular
    }

    /// Both lobes scaled by `w` (a path's throughput, a light's radiance over its density).
    pub fn scaled(&self, w: Vec3) -> Lobes {
        Lobes {
            diffuse: self.diffuse * w,
            specular: self.specular * w,
        }
    }
}

impl std::ops::AddAssign for Lobes {
    fn add_assign(&mut self, other: Lobes) {
        self.diffuse += other.diffuse;
        self.specular += other.specular;
    }
}

/// A sampled scattering direction with its throughput weight f cos / pdf.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    pub dir: Vec3,
    pub weight: Vec3,
    /// The kind of ray that will follow `dir` (for the counters).
    pub kind: RayKind,
}

impl Bsdf {
    pub fn from_material(m: &Material) -> Bsdf {
        let specular = match m.scattering {
            Scattering::Diffuse => Specular::None,
            Scattering::Glossy => Specular::Glossy {
                ks: m.ks,
                ns: m.ns.max(0.0),
            },
            Scattering::Mirror => Specular::Mirror { ks: m.ks },
        };
        Bsdf { kd: m.kd, specular }
    }

    fn ks(&self) -> Vec3 {
        match self.specular {
            Specular::None => Vec3::ZERO,
            Specular::Glossy { ks, .. } | Specular::Mirror { ks } => ks,
        }
    }

    /// Probability of sampling the diffuse lobe (by luminance of the lobes' albedos).
    fn diffuse_probability(&self) -> f32 {
        let d = luminance(self.kd).max(0.0);
        let s = luminance(self.ks()).max(0.0);
        if d + s > 0.0 { d / (d + s) } else { 0.0 }
    }

    /// f(wo, wi) of the non-delta lobes, lobe by lobe (a mirror's delta lobe is reached by
    /// sampling only).
    pub fn eval_lobes(&self, n: Vec3, wo: Vec3, wi: Vec3) -> Lobes {
        if n.dot(wi) <= 0.0 || n.dot(wo) <= 0.0 {
            return Lobes::default();
        }
        let specular = match self.specular {
            Specular::Glossy { ks, ns } => ks * blinn_phong(n, wo, wi, ns),
            Specular::None | Specular::Mirror { .. } => Vec3::ZERO,
        };
        Lobes {
            diffuse: self.kd * FRAC_1_PI,
            specular,
        }
    }

    /// Samples a direction: one lobe chosen by `u[2]`, then a direction in it.
    pub fn sample(&self, n: Vec3, wo: Vec3, u: [f32; 3]) -> Option<BsdfSample> {
        let p_diffuse = self.diffuse_probability();
        if u[2] < p_diffuse {
            let dir = cosine_hemisphere(n, [u[0], u[1]]);
            return Some(BsdfSample {
                dir,
                weight: self.kd / p_diffuse,
                kind: RayKind::Bounce,
            });
        }
        let p_specular = 1.0 - p_diffuse;
        if p_specular <= 0.0 {
            return None;
        }
        match self.specular {
            Specular::None => None,
            Specular::Mirror { ks } => {
                let dir = reflect(wo, n);
                Some(BsdfSample {
                    dir,
                    weight: ks / p_specular,
                    kind: RayKind::Mirror,
                })
            }
            Specular::Glossy { ks, ns } => {
                let h = sample_blinn_half_vector(n, ns, [u[0], u[1]]);
                let dir = reflect(wo, h);
                let cos_i = n.dot(dir);
                (cos_i > 0.0).then(|| BsdfSample {
                    dir,
                    weight: ks * (cos_i / p_specular),
                    kind: RayKind::Glossy,
                })
            }
        }
    }
}

/// Mirror image of `w` about unit `n`.
pub fn reflect(w: Vec3, n: Vec3) -> Vec3 {
    2.0 * w.dot(n) * n - w
}

/// The glossy lobe's f / ks for unit `wo`, `wi` above `n`.
fn blinn_phong(n: Vec3, wo: Vec3, wi: Vec3, ns: f32) -> f32 {
    let h = (wo + wi).normalize_or_zero();
    let cos_h = n.dot(h).max(0.0);
    let wo_h = wo.dot(h).max(1e-6);
    (ns + 1.0) / (2.0 * PI) * cos_h.powf(ns) / (4.0 * wo_h)
}

/// Half vector with density (ns + 1) / (2 pi) cos^ns(theta_h) over the hemisphere.
fn sample_blinn_half_vector(n: Vec3, ns: f32, u: [f32; 2]) -> Vec3 {
    let cos = u[0].powf(1.0 / (ns + 1.0));
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = 2.0 * PI * u[1];
    to_world(n, Vec3::new(sin * phi.cos(), sin * phi.sin(), cos))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{stream, uniform2, uniform3};

    fn glossy(kd: f32, ks: f32, ns: f32) -> Bsdf {
        Bsdf {
            kd: Vec3::splat(kd),
            specular: Specular::Glossy {
                ks: Vec3::splat(ks),
                ns,
            },
        }
    }

    /// Albedo for outgoing `wo`, integrated by uniform hemisphere sampling of f cos (independent
    /// of the lobe's own sampler).
    fn albedo_uniform(b: &Bsdf, n: Vec3, wo: Vec3, k: usize, seed: u64) -> f32 {
        let mut rng = stream(seed, 0);
        let mut sum = 0.0f64;
        for _ in 0..k {
            let [u0, u1] = uniform2(&mut rng);
            let z = u0;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = 2.0 * PI * u1;
            let wi = to_world(n, Vec3::new(r * phi.cos(), r * phi.sin(), z));
            sum += (b.eval_lobes(n, wo, wi).total().x * z * 2.0 * PI) as f64;
        }
        (sum / k as f64) as f32
    }

    #[test]
    fn glossy_lobe_never_reflects_more_than_it_receives() {
        let n = Vec3::Y;
        for ns in [1.0, 10.0, 100.0] {
            for theta_deg in [0.0f32, 30.0, 60.0, 80.0, 89.0] {
                let t = theta_deg.to_radians();
                let wo = Vec3::new(t.sin(), t.cos(), 0.0);
                let b = glossy(0.0, 1.0, ns);
                // Sampled weights are ks cos <= 1 each; their mean is the albedo.
                let mut rng = stream(7, theta_deg as u64);
                let k = 20_000;
                let sampled: f32 = (0..k)
                    .map(|_| {
                        let [u0, u1] = uniform2(&mut rng);
                        // kd = 0: any lobe-choice value picks the glossy lobe.
                        b.sample(n, wo, [u0, u1, 0.5])
                    })
                    .map(|s| s.map_or(0.0, |s| s.weight.x))
                    .sum::<f32>()
                    / k as f32;
                assert!(sampled <= 1.0, "ns {ns} theta {theta_deg}: {sampled}");
                // An independent estimate of the same integral agrees (within Monte Carlo noise
                // for the broad lobes, where uniform sampling is efficient).
                if ns <= 10.0 {
                    let uniform = albedo_uniform(&b, n, wo, 200_000, 11);
                    assert!(uniform <= 1.02, "ns {ns} theta {theta_deg}: {uniform}");
                    assert!((uniform - sampled).abs() < 0.03, "{uniform} vs {sampled}");
                }
            }
        }
    }

    #[test]
    fn diffuse_plus_glossy_albedo_stays_below_one() {
        let n = Vec3::Z;
        let b = glossy(0.5, 0.5, 20.0);
        let mut rng = stream(3, 3);
        for theta_deg in [0.0f32, 45.0, 85.0] {
            let t = theta_deg.to_radians();
            let wo = Vec3::new(0.0, t.sin(), t.cos());
            let k = 20_000;
            let mean: f32 = (0..k)
                .map(|_| {
                    b.sample(n, wo, uniform3(&mut rng))
                        .map_or(0.0, |s| s.weight.x)
                })
                .sum::<f32>()
                / k as f32;
            assert!(mean <= 1.0 && mean > 0.5, "{theta_deg}: {mean}");
        }
    }

    #[test]
    fn mirror_reflects_about_the_normal_with_weight_ks() {
        let b = Bsdf {
            kd: Vec3::ZERO,
            specular: Specular::Mirror {
                ks: Vec3::splat(0.9),
            },
        };
        let wo = Vec3::new(1.0, 1.0, 0.0).normalize();
        let s = b.sample(Vec3::Y, wo, [0.3, 0.3, 0.3]).unwrap();
        assert!(
            s.dir
                .abs_diff_eq(Vec3::new(-1.0, 1.0, 0.0).normalize(), 1e-6)
        );
        assert_eq!(s.weight, Vec3::splat(0.9));
        assert_eq!(s.kind, RayKind::Mirror);
        assert_eq!(b.eval_lobes(Vec3::Y, wo, s.dir), Lobes::default());
    }

    #[test]
    fn lambert_eval_is_kd_over_pi_above_and_zero_below() {
        let b = Bsdf {
            kd: Vec3::splat(0.6),
            specular: Specular::None,
        };
        let f = b.eval_lobes(Vec3::Y, Vec3::Y, Vec3::new(0.0, 1.0, 1.0).normalize());
        assert!((f.diffuse.x - 0.6 / PI).abs() < 1e-7);
        assert_eq!(
            b.eval_lobes(Vec3::Y, Vec3::Y, Vec3::NEG_Y),
            Lobes::default()
        );
        let s = b.sample(Vec3::Y, Vec3::Y, [0.2, 0.7, 0.0]).unwrap();
        assert_eq!(s.kind, RayKind::Bounce);
        assert!(s.dir.y > 0.0);
    }
}
