//! Which effects a scene calls for, so the renderer simulates only those (DESIGN.md §7): a
//! diffuse-only scene traces no specular rays and its cache never ages.

use crate::model::{Effects, Material, Mesh, Scattering};
use crate::settings::{SceneSettings, Sky};

/// Looks only at materials some triangle uses: an unused mirror in the MTL calls for nothing.
pub fn analyse_effects(settings: &SceneSettings, materials: &[Material], mesh: &Mesh) -> Effects {
    let mut used = vec![false; materials.len()];
    for t in &mesh.triangles {
        used[t.material as usize] = true;
    }
    let used: Vec<&Material> = materials
        .iter()
        .zip(used)
        .filter_map(|(m, u)| u.then_some(m))
        .collect();
    let sun = settings
        .sun
        .as_ref()
        .is_some_and(|s| s.radiance.iter().any(|c| *c > 0.0) && s.is_above_horizon());
    let sky =
        matches!(&settings.sky, Sky::Uniform { radiance } if radiance.iter().any(|c| *c > 0.0));
    let area_lights = used.iter().any(|m| m.is_emitter());
    Effects {
        sun,
        sky,
        area_lights,
        interreflection: (sun || sky || area_lights) && used.iter().any(|m| m.reflects_diffusely()),
        glossy: used.iter().any(|m| m.scattering == Scattering::Glossy),
        mirror: used.iter().any(|m| m.scattering == Scattering::Mirror),
    }
}

impl std::fmt::Display for Effects {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let names = [
            (self.sun, "sun"),
            (self.sky, "sky"),
            (self.area_lights, "area lights"),
            (self.interreflection, "diffuse interreflection"),
            (self.glossy, "glossy"),
            (self.mirror, "mirror"),
        ];
        let on: Vec<&str> = names
            .iter()
            .filter_map(|(on, name)| on.then_some(*name))
            .collect();
        if on.is_empty() {
            f.write_str("none")
        } else {
            f.write_str(&on.join(", "))
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::model::Triangle;

    fn mesh_using(materials: &[u32]) -> Mesh {
        let triangles = materials
            .iter()
            .map(|&material| Triangle {
                vertices: [0, 1, 2],
                material,
            })
            .collect();
        Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: vec![Vec3::Z; 3],
            triangles,
        }
    }

    fn settings(extra: &str) -> SceneSettings {
        toml::from_str(&format!("name = \"t\"\n{extra}")).expect("settings parse")
    }

    #[test]
    fn unlit_scene_calls_for_nothing_even_with_a_mirror_in_the_mtl() {
        let materials = [
            Material::diffuse("d", Vec3::splat(0.5)),
            Material::mirror("m", Vec3::ZERO, Vec3::ONE),
        ];
        assert_eq!(
            analyse_effects(&settings(""), &materials, &mesh_using(&[0])),
            Effects::default()
        );
    }

    #[test]
    fn sun_sky_lights_and_specular_are_each_detected() {
        let materials = [
            Material::diffuse("d", Vec3::splat(0.5)),
            Material::emitter("e", Vec3::ZERO, Vec3::ONE),
            Material::from_mtl("g", Vec3::splat(0.3), Vec3::ZERO, Vec3::splat(0.2), 50.0, 2),
            Material::mirror("m", Vec3::ZERO, Vec3::ONE),
        ];
        let sun = "[sun]\ndirection = [0, 1, 0]\nradiance = [1, 1, 1]\nangular_diameter_deg = 0.5";
        let e = analyse_effects(&settings(sun), &materials, &mesh_using(&[0]));
        assert_eq!(
            e,
            Effects {
                sun: true,
                interreflection: true,
                ..Effects::default()
            }
        );
        let sky = "[sky]\nkind = \"uniform\"\nradiance = [0.1, 0.2, 0.3]";
        let e = analyse_effects(&settings(sky), &materials, &mesh_using(&[1, 2, 3]));
        assert_eq!(
            e,
            Effects {
                sky: true,
                area_lights: true,
                interreflection: true,
                glossy: true,
                mirror: true,
                sun: false
            }
        );
        assert_eq!(
            e.to_string(),
            "sky, area lights, diffuse interreflection, glossy, mirror"
        );
    }

    /// The sun lights nothing from below the horizon (DESIGN.md §7), so a sun wholly under it
    /// calls for no sun rays; one on the horizon, half above it, does.
    #[test]
    fn a_sun_below_the_horizon_calls_for_no_sun() {
        let materials = [Material::diffuse("d", Vec3::splat(0.5))];
        let sun_toward = |dir: &str| {
            let toml = format!(
                "[sun]\ndirection = {dir}\nradiance = [1, 1, 1]\nangular_diameter_deg = 0.5"
            );
            analyse_effects(&settings(&toml), &materials, &mesh_using(&[0])).sun
        };
        assert!(!sun_toward("[0.3, -1, 0.2]"), "below the horizon");
        assert!(!sun_toward("[1, -0.01, 0]"), "the disc's top just under it");
        assert!(sun_toward("[1, 0, 0]"), "on the horizon");
        assert!(sun_toward("[1, -0.004, 0]"), "the disc's top just over it");
    }

    #[test]
    fn black_surfaces_pass_no_light_on() {
        let materials = [Material::emitter("e", Vec3::ZERO, Vec3::ONE)];
        let e = analyse_effects(&settings(""), &materials, &mesh_using(&[0]));
        assert_eq!(
            e,
            Effects {
                area_lights: true,
                ..Effects::default()
            }
        );
    }
}
