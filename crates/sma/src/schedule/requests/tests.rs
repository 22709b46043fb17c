//! The request queue: its order, its batches and what it counts as outstanding.

use super::*;
use crate::cache::CachedSample;
use protocol::{SampleParts, Side};

fn need(vertex: u32, quality: Quality, urgency: Urgency, priority: f32) -> Need {
    let key = SampleKey {
        vertex,
        side: Side::Front,
    };
    let point = ShadePoint {
        key,
        base_triangle: 0,
        bary: [0.0; 2],
        side: Side::Front,
        eye: None,
    };
    Need {
        point,
        quality,
        target: quality,
        urgency,
        priority,
        new_eye: false,
    }
}

/// At most `n` points, whatever their paths.
fn points(n: usize) -> BatchLimit {
    BatchLimit {
        points: n,
        paths: u64::MAX,
    }
}

#[test]
fn a_batch_of_many_paths_per_point_carries_fewer_points() {
    let cache = ShadingCache::new(1 << 20);
    let mut r = Requests::new(7, 0.0);
    let rung = Quality {
        paths: 256,
        ..Quality::INTERACTIVE
    };
    r.replan(
        (0..10)
            .map(|v| need(v, rung, Urgency::Paths, 1.0))
            .chain((10..20).map(|v| need(v, Quality::DIRECT, Urgency::Paths, 0.5)))
            .collect(),
    );
    let limit = BatchLimit {
        points: 8,
        paths: 1000,
    };
    let sizes = |r: &mut Requests, limit| {
        let b: ShadeBatch = r.next_batch(limit, &cache).unwrap();
        (b.quality.paths, b.points.len())
    };
    assert_eq!(sizes(&mut r, limit), (256, 3), "1000 / 256 paths");
    assert_eq!(sizes(&mut r, limit), (256, 3));
    let tight = BatchLimit { paths: 1, ..limit };
    assert_eq!(sizes(&mut r, tight), (256, 1), "never empty");
    assert_eq!(sizes(&mut r, limit), (256, 3));
    assert_eq!(sizes(&mut r, limit), (16, 8), "points bound cheap ones");
}

#[test]
fn batches_follow_urgency_then_priority_and_never_repeat_a_key_in_flight() {
    let cache = ShadingCache::new(1 << 20);
    let mut r = Requests::new(7, 0.0);
    r.replan(vec![
        need(1, Quality::INTERACTIVE, Urgency::Better, 100.0),
        need(2, Quality::DIRECT, Urgency::Missing, 1.0),
        need(3, Quality::DIRECT, Urgency::Missing, 50.0),
        need(3, Quality::DIRECT, Urgency::Missing, 10.0),
    ]);
    assert_eq!(r.outstanding(), 3);
    let b = r.next_batch(points(8), &cache).unwrap();
    assert_eq!(b.quality, Quality::DIRECT);
    assert_eq!(
        b.points.iter().map(|p| p.key.vertex).collect::<Vec<_>>(),
        vec![3, 2]
    );
    // Re-planning the same needs while they fly asks nothing twice.
    r.replan(vec![need(3, Quality::DIRECT, Urgency::Missing, 50.0)]);
    assert!(r.next_batch(points(8), &cache).is_none());
    r.finished(&b);
    assert_eq!(r.in_flight_keys(), 0);
    assert_eq!(r.batches_in_flight(), 0);
}

#[test]
fn the_queue_orders_by_urgency_then_larger_priority_and_keeps_equals_in_order() {
    let cache = ShadingCache::new(1 << 20);
    let mut r = Requests::new(7, 0.0);
    let priorities = [
        0.5,
        -3.0,
        f32::INFINITY,
        0.0,
        -0.0,
        7.25,
        1e-30,
        -1e-30,
        7.25,
    ];
    let mut needs: Vec<Need> = priorities
        .iter()
        .enumerate()
        .map(|(i, &p)| need(i as u32, Quality::DIRECT, Urgency::Better, p))
        .collect();
    needs.push(need(100, Quality::DIRECT, Urgency::Missing, -1e9));
    r.replan(needs);
    let batch = r.next_batch(points(16), &cache).unwrap();
    let order: Vec<u32> = batch.points.iter().map(|p| p.key.vertex).collect();
    // Missing before Better whatever the priority; then descending `total_cmp` (0.0 above
    // -0.0), the two 7.25 in the order given.
    assert_eq!(order, vec![100, 2, 5, 8, 0, 6, 3, 4, 7, 1]);
}

#[test]
fn alternating_rungs_of_the_ladder_still_fill_whole_batches_in_order() {
    let cache = ShadingCache::new(1 << 20);
    let mut r = Requests::new(7, 0.0);
    let rung = |i: u32| Quality {
        paths: if i.is_multiple_of(2) { 192 } else { 768 },
        bounces: Some(2),
    };
    r.replan(
        (0..40)
            .map(|i| need(i, rung(i), Urgency::Paths, 100.0 - i as f32))
            .collect(),
    );
    let first = r.next_batch(points(8), &cache).unwrap();
    assert_eq!(first.quality.paths, 192);
    let vertices: Vec<u32> = first.points.iter().map(|p| p.key.vertex).collect();
    assert_eq!(vertices, vec![0, 2, 4, 6, 8, 10, 12, 14]);
    let second = r.next_batch(points(8), &cache).unwrap();
    assert_eq!(
        second.quality.paths, 768,
        "the skipped needs kept their place"
    );
    assert_eq!(second.points[0].key.vertex, 1);
    assert_eq!(second.points.len(), 8);
}

#[test]
fn more_paths_fill_their_own_batches_and_never_hold_refinement_back() {
    let cache = ShadingCache::new(1 << 20);
    let mut r = Requests::new(7, 0.0);
    r.replan(vec![
        need(1, Quality::INTERACTIVE, Urgency::Paths, 9.0),
        need(2, Quality::INTERACTIVE, Urgency::Paths, 8.0),
        need(3, Quality::INTERACTIVE, Urgency::Refinement, 1.0),
    ]);
    assert_eq!((r.outstanding(), r.outstanding_before_paths()), (3, 1));
    let refinement = r.next_batch(points(8), &cache).unwrap();
    assert_eq!(refinement.points.len(), 1, "a batch holds one kind of need");
    assert_eq!(r.outstanding_before_paths(), 1, "in flight, still awaited");
    let paths = r.next_batch(points(8), &cache).unwrap();
    assert_eq!(paths.points.len(), 2);
    r.finished(&refinement);
    assert_eq!((r.outstanding(), r.outstanding_before_paths()), (2, 0));
    r.finished(&paths);
    assert_eq!(r.outstanding(), 0);
}

#[test]
fn top_ups_get_their_share_of_the_paths_while_refinement_waits_and_are_not_awaited() {
    let cache = ShadingCache::new(1 << 20);
    let early = Quality {
        paths: 16,
        bounces: Some(2),
    };
    let top_up = Quality {
        paths: 48,
        bounces: Some(2),
    };
    let queue = || {
        let refinement = (0..64).map(|i| need(i, early, Urgency::Refinement, 1.0));
        let top_ups = (100..164).map(|i| need(i, top_up, Urgency::TopUp, 1.0));
        refinement.chain(top_ups).collect::<Vec<_>>()
    };
    // Share 0: refinement's eight batches first, then the top-ups.
    let mut r = Requests::new(7, 0.0);
    r.replan(queue());
    let kinds: Vec<u32> = (0..16)
        .map(|_| r.next_batch(points(8), &cache).unwrap().quality.paths)
        .collect();
    assert_eq!(kinds, [[16; 8], [48; 8]].concat());
    // Share 1/2: top-up batches cost three times the paths, so about one in four batches.
    let mut r = Requests::new(7, 0.5);
    r.replan(queue());
    let mut taken = Vec::new();
    while r.queue.front().is_some_and(|n| awaited(n.urgency)) {
        let batch = r.next_batch(points(8), &cache).unwrap();
        assert!(
            r.is_urgent(batch.batch_id),
            "top-ups go out with refinement"
        );
        taken.push(batch);
    }
    let paths = |q: u32| -> u32 {
        let of = taken.iter().filter(|b| b.quality.paths == q);
        of.map(|b| b.points.len() as u32 * q).sum()
    };
    let share = f64::from(paths(48)) / f64::from(paths(16) + paths(48));
    assert!((0.4..=0.6).contains(&share), "top-ups took {share:.2}");
    // Top-ups in flight hold no refinement back.
    let refinement: usize = taken.iter().filter(|b| b.quality.paths == 16).count();
    assert_eq!(refinement, 8);
    for b in taken.iter().filter(|b| b.quality.paths == 16) {
        r.finished(b);
    }
    assert_eq!(r.outstanding_before_paths(), 0);
}

#[test]
fn a_pictures_missing_samples_go_out_before_any_top_up_whatever_its_share() {
    let cache = ShadingCache::new(1 << 20);
    let early = Quality {
        paths: 16,
        bounces: Some(2),
    };
    let top_up = Quality {
        paths: 48,
        bounces: Some(2),
    };
    let mut r = Requests::new(7, 0.5);
    r.replan(
        (0..32)
            .map(|i| need(i, Quality::DIRECT, Urgency::Missing, 1.0))
            .chain((50..66).map(|i| need(i, early, Urgency::Refinement, 1.0)))
            .chain((100..164).map(|i| need(i, top_up, Urgency::TopUp, 1.0)))
            .collect(),
    );
    let paths: Vec<u32> = (0..8)
        .map(|_| r.next_batch(points(8), &cache).unwrap().quality.paths)
        .collect();
    assert_eq!(&paths[..4], [Quality::DIRECT.paths; 4], "the picture first");
    assert!(
        paths[4..].contains(&48),
        "then top-ups share with refinement"
    );
}

#[test]
fn needs_satisfied_while_queued_leave_nothing_outstanding_once_submission_passes() {
    // The schedule counts `outstanding` after submitting: a queue whose needs were all
    // answered meanwhile must drain to zero then, or an epoch would never report completion.
    let mut cache = ShadingCache::new(1 << 20);
    let mut r = Requests::new(7, 0.0);
    r.replan(vec![
        need(1, Quality::DIRECT, Urgency::Missing, 1.0),
        need(2, Quality::DIRECT, Urgency::Missing, 1.0),
    ]);
    for vertex in [1, 2] {
        let key = SampleKey {
            vertex,
            side: Side::Front,
        };
        let sample = CachedSample {
            parts: SampleParts::direct_only([1.0; 3], 0.0),
            quality: Quality::INTERACTIVE,
            view_dependent: false,
            eye: None,
            last_seen: 0,
        };
        cache.insert(key, sample);
    }
    assert_eq!(r.outstanding(), 2);
    assert!(r.next_batch(points(8), &cache).is_none());
    assert_eq!(r.outstanding(), 0);
}
