//! Mirrors and glossy lobes in scenes, and the effects counters (DESIGN.md §7): a scene traces
//! only the rays its effects call for, and positive controls show the counters do count.

mod common;

use common::*;
use glam::Vec3;
use protocol::renderer_link::{Quality, ShadePoint};
use renderer::sampling::stream;
use renderer::{RayCounts, World, shade_point};
use scene::{Material, SceneBuilder, Sky};

const INTERACTIVE: Quality = Quality {
    paths: 64,
    bounces: Some(2),
};

/// The rays `points` take at `q`, under each estimator in turn.
fn counts_for(w: World, points: &[ShadePoint], q: Quality) -> Vec<RayCounts> {
    let mut each = Vec::new();
    with_each_estimator(w, |w| {
        let mut counts = RayCounts::default();
        for (i, p) in points.iter().enumerate() {
            let shaded = shade_point(w, p, q, &mut stream(3, i as u64), &mut counts);
            assert!(shaded.rgb.is_finite() && shaded.rgb.min_element() >= 0.0);
        }
        each.push(counts);
    });
    each
}

/// A floor with a box on it and a roof beam, under the given lights; `extra` is the material of
/// the box.
fn scene_with(
    sun: Option<scene::Sun>,
    sky: Sky,
    box_material: Material,
    emitter: bool,
) -> (World, Vec<ShadePoint>) {
    let mut b = SceneBuilder::new(settings(sun, sky));
    let g = b.material(grey(0.5));
    let m = b.material(box_material);
    floor(&mut b, Vec3::ZERO, 5.0, g);
    cube(
        &mut b,
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(1.0, 1.0, 1.0),
        false,
        m,
    );
    if emitter {
        let e = b.material(Material::emitter("lamp", Vec3::ZERO, Vec3::splat(5.0)));
        // Facing down.
        let c = |x: f32, z: f32| Vec3::new(x, 3.0, z);
        quad(
            &mut b,
            [c(-1.0, -1.0), c(1.0, -1.0), c(1.0, 1.0), c(-1.0, 1.0)],
            e,
        );
    }
    let w = world(b);
    let mut points = vec![
        point_hit_by(&w, Vec3::new(2.5, 2.0, 0.3), Vec3::NEG_Y),
        point_hit_by(&w, Vec3::new(0.2, 2.0, 0.3), Vec3::NEG_Y),
        point_hit_by(&w, Vec3::new(3.0, 0.5, 0.2), Vec3::NEG_X),
    ];
    for p in &mut points {
        p.eye = Some([4.0, 2.0, 1.0]);
    }
    (w, points)
}

fn sun_above() -> Option<scene::Sun> {
    Some(sun(Vec3::new(0.3, 1.0, 0.2), 1.0e5))
}

#[test]
fn diffuse_sunlit_scene_traces_no_specular_no_sky_no_area_rays() {
    let (w, points) = scene_with(sun_above(), Sky::None, grey(0.7), false);
    for c in counts_for(w, &points, INTERACTIVE) {
        assert!(c.shadow_sun > 0 && c.bounce > 0, "{c:?}");
        assert_eq!(
            (c.glossy, c.mirror, c.shadow_sky, c.shadow_area),
            (0, 0, 0, 0),
            "{c:?}"
        );
    }
}

#[test]
fn direct_quality_traces_no_bounce_rays() {
    let (w, points) = scene_with(sun_above(), Sky::None, grey(0.7), false);
    let direct = Quality {
        paths: 16,
        bounces: Some(0),
    };
    for c in counts_for(w, &points, direct) {
        assert!(c.shadow_sun > 0);
        assert_eq!(c.bounce, 0, "{c:?}");
    }
}

#[test]
fn positive_controls_count_each_kind() {
    let (w, points) = scene_with(
        sun_above(),
        Sky::None,
        Material::mirror("m", Vec3::ZERO, Vec3::splat(0.9)),
        false,
    );
    for c in counts_for(w, &points, INTERACTIVE) {
        assert!(c.mirror > 0, "{c:?}");
    }
    let glossy = Material::from_mtl("g", Vec3::splat(0.3), Vec3::ZERO, Vec3::splat(0.5), 50.0, 2);
    let (w, points) = scene_with(sun_above(), Sky::None, glossy, false);
    for c in counts_for(w, &points, INTERACTIVE) {
        assert!(c.glossy > 0, "{c:?}");
    }
    let (w, points) = scene_with(None, Sky::Uniform { radiance: [1.0; 3] }, grey(0.7), false);
    for c in counts_for(w, &points, INTERACTIVE) {
        assert!(
            c.shadow_sky > 0 && c.shadow_sun == 0 && c.shadow_area == 0,
            "{c:?}"
        );
    }
    let (w, points) = scene_with(None, Sky::None, grey(0.7), true);
    for c in counts_for(w, &points, INTERACTIVE) {
        assert!(
            c.shadow_area > 0 && c.shadow_sun == 0 && c.shadow_sky == 0,
            "{c:?}"
        );
    }
}

#[test]
fn unlit_scene_traces_nothing_but_probes_and_is_black() {
    let (w, points) = scene_with(None, Sky::None, grey(0.7), false);
    with_each_estimator(w, |w| {
        let mut counts = RayCounts::default();
        for p in &points {
            let s = shade_point(w, p, INTERACTIVE, &mut stream(0, 0), &mut counts);
            assert_eq!(s.rgb, Vec3::ZERO);
        }
        assert_eq!(counts.total(), counts.probe, "{counts:?}");
    });
}

#[test]
fn mirror_facing_an_emitter_returns_its_radiance() {
    let ke = Vec3::new(2.0, 3.0, 4.0);
    let mut b = SceneBuilder::new(settings(None, Sky::None));
    let mirror = b.material(Material::mirror("mirror", Vec3::ZERO, Vec3::ONE));
    let lamp = b.material(Material::emitter("lamp", Vec3::ZERO, ke));
    floor(&mut b, Vec3::ZERO, 1.0, mirror);
    // A large emitter 1 above, facing down (clockwise seen from above = counter-clockwise below).
    let c = |x: f32, z: f32| Vec3::new(x, 1.0, z);
    quad(
        &mut b,
        [
            c(-20.0, -20.0),
            c(20.0, -20.0),
            c(20.0, 20.0),
            c(-20.0, 20.0),
        ],
        lamp,
    );
    with_each_estimator(world(b), |w| {
        let mut p = point_hit_by(w, Vec3::new(0.1, 0.5, 0.2), Vec3::NEG_Y);
        p.eye = Some([0.6, 0.8, -0.3]);
        for bounces in [Some(0), Some(2), None] {
            let mut counts = RayCounts::default();
            let s = shade_point(
                w,
                &p,
                Quality { paths: 8, bounces },
                &mut stream(1, 0),
                &mut counts,
            );
            assert!(s.rgb.abs_diff_eq(ke, 1e-5), "{bounces:?}: {}", s.rgb);
            // What a mirror reflects is view-dependent radiance, never illumination.
            let reflected = Vec3::from(s.parts.view_dependent.rgb);
            assert!(reflected.abs_diff_eq(ke, 1e-5), "{reflected}");
            assert_eq!(s.parts.direct.rgb, [0.0; 3]);
            assert_eq!(s.parts.indirect.rgb, [0.0; 3]);
            assert_eq!(
                s.flags & protocol::renderer_link::point_flags::VIEW_DEPENDENT,
                protocol::renderer_link::point_flags::VIEW_DEPENDENT
            );
            assert!(counts.mirror >= 8);
        }
        // Seen from below the mirror (the back side of the emitter faces away): the lamp's back is
        // dark, so a mirror under it looking up at its back sees nothing.
        let back = with_side_facing(w, p, Vec3::NEG_Y);
        let mut counts = RayCounts::default();
        let s = shade_point(
            w,
            &ShadePoint {
                eye: Some([0.3, -1.0, 0.1]),
                ..back
            },
            Quality {
                paths: 4,
                bounces: Some(0),
            },
            &mut stream(1, 0),
            &mut counts,
        );
        assert_eq!(s.rgb, Vec3::ZERO);
    });
}

#[test]
fn glossy_surface_in_a_furnace_reflects_no_more_than_it_receives() {
    // Inside a closed box emitting Le everywhere, a lossless surface would return exactly Le;
    // a glossy lobe of ks <= 1 (and kd = 0) must return at most Le, and close to ks Le when the
    // lobe stays above the horizon.
    let le = 1.0f32;
    let mut b = SceneBuilder::new(settings(None, Sky::None));
    let wall = b.material(Material::emitter("wall", Vec3::ZERO, Vec3::splat(le)));
    let glossy = b.material(Material::from_mtl(
        "g",
        Vec3::ZERO,
        Vec3::ZERO,
        Vec3::ONE,
        20.0,
        2,
    ));
    cube(&mut b, Vec3::ZERO, Vec3::splat(2.0), true, wall);
    floor(&mut b, Vec3::new(1.0, 0.5, 1.0), 0.5, glossy);
    with_each_estimator(world(b), |w| {
        let mut p = point_hit_by(w, Vec3::new(1.05, 1.5, 0.95), Vec3::NEG_Y);
        // Near-normal view: the lobe stays above the horizon; grazing views lose part of it below.
        for (eye, at_least) in [
            ([1.0, 1.9, 1.0], 0.8),
            ([1.9, 0.9, 1.0], 0.2),
            ([1.98, 0.55, 1.0], 0.0),
        ] {
            p.eye = Some(eye);
            let mut counts = RayCounts::default();
            let s = shade_point(
                w,
                &p,
                Quality {
                    paths: 20_000,
                    bounces: Some(0),
                },
                &mut stream(4, 0),
                &mut counts,
            );
            assert!(s.rgb.x <= le * 1.01, "eye {eye:?}: {}", s.rgb);
            assert!(s.rgb.x > at_least * le, "eye {eye:?}: {}", s.rgb);
        }
    });
}
