//! Solids for the built-in scenes, added to a [`SceneBuilder`]. Every face is wound
//! counter-clockwise seen from outside, so emitters built from them shine outward.

use std::f32::consts::TAU;

use glam::{Vec3, vec3};

use crate::builder::SceneBuilder;

/// A planar quad `a b c d` (counter-clockwise from the side it faces) as two triangles.
pub fn quad(b: &mut SceneBuilder, corners: [Vec3; 4], material: u32) {
    let [p, q, r, s] = corners.map(|c| b.vertex(c));
    b.triangle([p, q, r], material);
    b.triangle([p, r, s], material);
}

/// A convex planar polygon, counter-clockwise from the side it faces, as a fan.
pub fn polygon(b: &mut SceneBuilder, corners: &[Vec3], material: u32) {
    let v: Vec<u32> = corners.iter().map(|c| b.vertex(*c)).collect();
    for pair in v[1..].windows(2) {
        b.triangle([v[0], pair[0], pair[1]], material);
    }
}

/// A vertical prism over a convex footprint of (x, z) points, counter-clockwise seen from above
/// (from +y): top and sides, no bottom.
pub fn prism(b: &mut SceneBuilder, footprint: &[(f32, f32)], y0: f32, y1: f32, material: u32) {
    let at = |i: usize, y: f32| {
        vec3(
            footprint[i % footprint.len()].0,
            y,
            footprint[i % footprint.len()].1,
        )
    };
    let top: Vec<Vec3> = (0..footprint.len()).map(|i| at(i, y1)).collect();
    polygon(b, &top, material);
    for i in 0..footprint.len() {
        quad(
            b,
            [at(i + 1, y0), at(i + 1, y1), at(i, y1), at(i, y0)],
            material,
        );
    }
}

/// An axis-aligned box; `with_bottom` false leaves out the face on the ground.
pub fn cuboid(b: &mut SceneBuilder, min: Vec3, max: Vec3, with_bottom: bool, material: u32) {
    let corner = |[x, y, z]: [bool; 3]| {
        vec3(
            if x { max.x } else { min.x },
            if y { max.y } else { min.y },
            if z { max.z } else { min.z },
        )
    };
    let (f, t) = (false, true);
    let mut faces = vec![
        [[f, t, f], [f, t, t], [t, t, t], [t, t, f]], // top (+y)
        [[f, f, t], [t, f, t], [t, t, t], [f, t, t]], // +z
        [[t, f, f], [f, f, f], [f, t, f], [t, t, f]], // -z
        [[t, f, t], [t, f, f], [t, t, f], [t, t, t]], // +x
        [[f, f, f], [f, f, t], [f, t, t], [f, t, f]], // -x
    ];
    if with_bottom {
        faces.push([[f, f, f], [t, f, f], [t, f, t], [f, f, t]]);
    }
    for face in faces {
        quad(b, face.map(corner), material);
    }
}

/// An open vertical cylinder (no caps: columns carry a capital and stand on a base), finely
/// tessellated: `segments` around, `rings` bands up.
pub fn cylinder(
    b: &mut SceneBuilder,
    base: Vec3,
    radius: f32,
    height: f32,
    segments: u32,
    rings: u32,
    material: u32,
) {
    let ring = |j: u32| -> Vec<u32> {
        let y = base.y + height * j as f32 / rings as f32;
        (0..segments)
            .map(|i| {
                let a = TAU * i as f32 / segments as f32;
                vec3(base.x + radius * a.cos(), y, base.z - radius * a.sin())
            })
            .map(|p| b.vertex(p))
            .collect()
    };
    let rows: Vec<Vec<u32>> = (0..=rings).map(ring).collect();
    for pair in rows.windows(2) {
        let (lo, hi) = (&pair[0], &pair[1]);
        for i in 0..segments as usize {
            let n = (i + 1) % segments as usize;
            b.triangle([lo[i], lo[n], hi[n]], material);
            b.triangle([lo[i], hi[n], hi[i]], material);
        }
    }
}

/// A gabled roof over the rectangle `min.xz`–`max.xz` whose ridge runs along z at `ridge_y`,
/// eaves at `min.y`: two sloping quads and the two gable triangles.
pub fn gable_roof(b: &mut SceneBuilder, min: Vec3, max: Vec3, ridge_y: f32, roof: u32, gable: u32) {
    let mid = 0.5 * (min.x + max.x);
    let (y, (z0, z1)) = (min.y, (min.z, max.z));
    for (x, [za, zb]) in [(max.x, [z1, z0]), (min.x, [z0, z1])] {
        let eave_to_ridge = [
            vec3(x, y, za),
            vec3(x, y, zb),
            vec3(mid, ridge_y, zb),
            vec3(mid, ridge_y, za),
        ];
        quad(b, eave_to_ridge, roof);
    }
    for (z, [l, r]) in [(z1, [min.x, max.x]), (z0, [max.x, min.x])] {
        let v = [vec3(l, y, z), vec3(r, y, z), vec3(mid, ridge_y, z)].map(|p| b.vertex(p));
        b.triangle(v, gable);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Material;
    use crate::settings::SceneSettings;

    fn build(add: impl FnOnce(&mut SceneBuilder, u32)) -> crate::Scene {
        let settings: SceneSettings = toml::from_str("name = \"shape\"").expect("settings");
        let mut b = SceneBuilder::new(settings);
        let m = b.material(Material::diffuse("m", Vec3::splat(0.5)));
        add(&mut b, m);
        b.build().expect("shape builds")
    }

    /// Every face's counter-clockwise normal points away from the solid's centre.
    fn assert_outward(scene: &crate::Scene, centre: Vec3) {
        for t in 0..scene.mesh.triangles.len() {
            let [a, b, c] = scene.mesh.triangle_positions(t);
            let n = scene.mesh.face_normal(t);
            assert!(
                n.dot((a + b + c) / 3.0 - centre) > 0.0,
                "triangle {t} faces inward"
            );
        }
    }

    #[test]
    fn cuboid_faces_outward_and_splits_at_every_edge() {
        let s = build(|b, m| cuboid(b, Vec3::ZERO, Vec3::ONE, true, m));
        assert_eq!(s.mesh.triangles.len(), 12);
        assert_outward(&s, Vec3::splat(0.5));
        // 8 corners × 3 faces: each corner splits into one vertex per face (90° creases).
        assert_eq!(s.mesh.positions.len(), 24);
        assert_eq!(s.report.crease_split_vertices, 16);
    }

    #[test]
    fn cylinder_is_smooth_and_faces_outward() {
        let s = build(|b, m| cylinder(b, Vec3::ZERO, 1.0, 2.0, 24, 3, m));
        assert_eq!(s.mesh.triangles.len(), 24 * 3 * 2);
        assert_eq!(s.mesh.positions.len(), 24 * 4);
        assert_eq!(s.report.crease_split_vertices, 0);
        assert_outward(&s, vec3(0.0, 1.0, 0.0));
        let (lo, hi) = s.mesh.bounds();
        assert!(
            lo.abs_diff_eq(vec3(-1.0, 0.0, -1.0), 1e-5)
                && hi.abs_diff_eq(vec3(1.0, 2.0, 1.0), 1e-5)
        );
    }

    #[test]
    fn prism_faces_outward() {
        // Counter-clockwise seen from +y: x right, z toward the viewer's bottom.
        let footprint = [(0.0, 0.0), (0.0, 2.0), (2.0, 2.0), (3.0, 1.0), (2.0, 0.0)];
        let s = build(|b, m| prism(b, &footprint, 0.0, 1.0, m));
        assert_eq!(s.mesh.triangles.len(), 3 + 5 * 2);
        assert_outward(&s, vec3(1.4, 0.5, 1.0));
    }

    #[test]
    fn gable_roof_faces_outward() {
        let s = build(|b, m| gable_roof(b, vec3(0.0, 3.0, 0.0), vec3(4.0, 3.0, 6.0), 5.0, m, m));
        assert_eq!(s.mesh.triangles.len(), 6);
        assert_outward(&s, vec3(2.0, 3.5, 3.0));
    }
}
