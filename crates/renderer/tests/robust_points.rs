//! Robust shading points (DESIGN.md §7, robust ray offsets): no light leaks at concave corners, points
//! hidden inside geometry are moved to the visible part of their face and flagged, bad requests
//! are flagged instead of failing.

mod common;

use common::*;
use glam::Vec3;
use protocol::Side;
use protocol::renderer_link::{Quality, SampleKey, ShadePoint, point_flags};
use renderer::sampling::stream;
use renderer::{RayCounts, World, shade_point};
use scene::{SceneBuilder, Sky};

const DIRECT: Quality = Quality {
    paths: 512,
    bounces: Some(0),
};

fn vertex_points(w: &World) -> Vec<ShadePoint> {
    (0..w.triangle_count() as u32)
        .flat_map(|t| {
            [
                [0.0, 0.0],
                [1.0, 0.0],
                [0.0, 1.0],
                [0.5, 0.0],
                [0.5, 0.5],
                [0.0, 0.5],
            ]
            .into_iter()
            .flat_map(move |bary| {
                [Side::Front, Side::Back].map(|side| ShadePoint {
                    key: SampleKey { vertex: 0, side },
                    base_triangle: t,
                    bary,
                    side,
                    eye: None,
                })
            })
        })
        .collect()
}

/// A closed room of single-sided-thickness walls with the sun and sky outside: every point on
/// the inner side of a wall, corners and edges included, must be exactly dark at direct quality.
fn check_closed_room_is_dark(offset: Vec3) {
    let mut b = SceneBuilder::new(settings(
        Some(sun(Vec3::new(0.4, 1.0, 0.3), 1.0e5)),
        Sky::Uniform { radiance: [1.0; 3] },
    ));
    let m = b.material(grey(0.7));
    cube(&mut b, offset, offset + Vec3::new(3.0, 2.5, 4.0), true, m);
    with_each_estimator(world(b), |w| {
        // Shading points are in the world's local frame.
        let centre = w.to_local(offset + Vec3::new(1.5, 1.25, 2.0));
        let mut counts = RayCounts::default();
        let mut inside = 0;
        for p in vertex_points(w) {
            let s = renderer::point::surface_of(w, &p).unwrap();
            if s.normal.dot(centre - s.position) <= 0.0 {
                continue; // the outer side
            }
            inside += 1;
            let shaded = shade_point(w, &p, DIRECT, &mut stream(7, inside), &mut counts);
            assert_eq!(shaded.rgb, Vec3::ZERO, "light leaks in at {p:?}");
        }
        assert_eq!(inside, 12 * 6);
        assert!(counts.shadow_sun > 0 && counts.shadow_sky > 0);
    });
}

#[test]
fn no_leak_at_concave_corners() {
    check_closed_room_is_dark(Vec3::ZERO);
}

#[test]
fn no_leak_at_concave_corners_far_from_the_origin() {
    check_closed_room_is_dark(Vec3::new(-1.0e5, 5.0e4, 1.0e5));
}

/// A floor of two large triangles with a closed box standing on one of its vertices: that
/// vertex is inside the box.
fn floor_with_box_on_a_vertex() -> World {
    let mut b = SceneBuilder::new(settings(
        Some(sun(Vec3::new(0.3, 1.0, 0.2), 1.0e5)),
        Sky::None,
    ));
    let m = b.material(grey(0.5));
    floor(&mut b, Vec3::ZERO, 10.0, m);
    cube(
        &mut b,
        Vec3::new(-10.5, 0.0, -10.5),
        Vec3::new(-9.0, 1.0, -9.0),
        false,
        m,
    );
    world(b)
}

#[test]
fn hidden_vertex_is_moved_and_flagged_and_lit() {
    with_each_estimator(floor_with_box_on_a_vertex(), |w| {
        let corner = Vec3::new(-10.0, 0.0, -10.0);
        let mut found = 0;
        for p in vertex_points(w) {
            let s = renderer::point::surface_of(w, &p).unwrap();
            let at_corner = s.position.distance(corner) < 0.05;
            if !at_corner || s.normal.y <= 0.0 {
                continue;
            }
            found += 1;
            let shaded = shade_point(
                w,
                &p,
                DIRECT,
                &mut stream(1, found),
                &mut RayCounts::default(),
            );
            assert_eq!(
                shaded.flags & point_flags::MOVED_OFF_HIDDEN,
                point_flags::MOVED_OFF_HIDDEN,
                "{p:?}"
            );
            assert!(
                shaded.rgb.x > 0.5,
                "moved into the sunlit part: {}",
                shaded.rgb
            );
        }
        assert!(found > 0, "the corner vertex is on the floor");
    });
}

#[test]
fn open_points_and_room_corners_are_not_moved() {
    let w = floor_with_box_on_a_vertex();
    let p = point_hit_by(&w, Vec3::new(3.0, 1.0, 2.0), Vec3::NEG_Y);
    let mut open_counts = RayCounts::default();
    let shaded = shade_point(&w, &p, DIRECT, &mut stream(1, 0), &mut open_counts);
    assert_eq!(shaded.flags, 0);
    // Under an open sky the verdict is known after two unblocked probes.
    assert_eq!(open_counts.probe, 2);
    // Corners of a room (three quarters of the hemisphere close to walls) are visible, not hidden.
    let mut b = SceneBuilder::new(settings(None, Sky::Uniform { radiance: [1.0; 3] }));
    let m = b.material(grey(0.5));
    cube(&mut b, Vec3::ZERO, Vec3::new(3.0, 2.5, 4.0), true, m);
    let w = world(b);
    let mut counts = RayCounts::default();
    for p in vertex_points(&w) {
        let s = renderer::point::surface_of(&w, &p).unwrap();
        if s.normal.dot(Vec3::new(1.5, 1.25, 2.0) - s.position) > 0.0 {
            let shaded = shade_point(
                &w,
                &p,
                Quality {
                    paths: 1,
                    bounces: Some(0),
                },
                &mut stream(1, 0),
                &mut counts,
            );
            assert_eq!(shaded.flags & point_flags::MOVED_OFF_HIDDEN, 0, "{p:?}");
        }
    }
}

#[test]
fn invalid_requests_are_flagged_not_fatal() {
    let w = floor_with_box_on_a_vertex();
    let good = point_hit_by(&w, Vec3::new(3.0, 1.0, 2.0), Vec3::NEG_Y);
    let bad = [
        ShadePoint {
            base_triangle: 1_000_000,
            ..good
        },
        ShadePoint {
            bary: [f32::NAN, 0.2],
            ..good
        },
        ShadePoint {
            bary: [0.9, 0.9],
            ..good
        },
        ShadePoint {
            bary: [-0.5, 0.2],
            ..good
        },
    ];
    for p in bad {
        let s = shade_point(&w, &p, DIRECT, &mut stream(1, 0), &mut RayCounts::default());
        assert_eq!(
            (s.rgb, s.flags),
            (Vec3::ZERO, point_flags::INVALID_POINT),
            "{p:?}"
        );
    }
    // A non-finite eye is ignored rather than poisoning the answer.
    let p = ShadePoint {
        eye: Some([f32::NAN, f32::INFINITY, 0.0]),
        ..good
    };
    let s = shade_point(&w, &p, DIRECT, &mut stream(1, 0), &mut RayCounts::default());
    assert!(s.rgb.is_finite() && s.rgb.x > 0.0);
}
