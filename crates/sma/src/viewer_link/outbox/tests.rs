use std::collections::HashMap;

use proptest::prelude::*;

use super::*;

fn triangle(id: TriangleId, value: f32) -> ShownTriangle {
    ShownTriangle {
        id,
        positions: [[value, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        material: 0,
        texcoords: Default::default(),
        shading: lit(value),
    }
}

fn lit(value: f32) -> CornerShading {
    CornerShading {
        illumination: [[value; 3]; 3],
        ..CornerShading::default()
    }
}

fn epoch(inserted: u64, removed: u64, shown: u64) -> Epoch {
    Epoch {
        inserted,
        removed,
        shown,
        ..Epoch::default()
    }
}

/// A viewer's table, refusing what the probe viewer refuses (DESIGN.md §8): a duplicate insert, a
/// remove or update of an id it does not hold.
#[derive(Debug, Default, PartialEq)]
struct Table {
    triangles: HashMap<TriangleId, ShownTriangle>,
    last_epoch: Option<Epoch>,
}

impl Table {
    fn apply(&mut self, message: &SmaToViewer) {
        match message {
            SmaToViewer::Insert { triangles } => {
                for t in triangles {
                    assert!(
                        self.triangles.insert(t.id, t.clone()).is_none(),
                        "duplicate {}",
                        t.id
                    );
                }
            }
            SmaToViewer::Remove { ids } => {
                for id in ids {
                    assert!(
                        self.triangles.remove(id).is_some(),
                        "remove of unknown {id}"
                    );
                }
            }
            SmaToViewer::Update { triangles } => {
                for r in triangles {
                    let t = self.triangles.get_mut(&r.id).expect("update of a shown id");
                    t.shading = r.shading.clone();
                }
            }
            SmaToViewer::Epoch(e) => {
                assert_eq!(e.shown, self.triangles.len() as u64, "epoch disagrees");
                self.last_epoch = Some(*e);
            }
            _ => {}
        }
    }
}

/// A valid stream of single-triangle messages over ids 0..16, each step (kind, id, value, flush).
fn stream(steps: &[(u8, u8, f32, bool)]) -> Vec<(SmaToViewer, bool)> {
    let mut shown: HashMap<TriangleId, ()> = HashMap::new();
    let mut out = Vec::new();
    for &(kind, id, value, flush) in steps {
        let id = TriangleId::from(id % 16);
        let present = shown.contains_key(&id);
        let message = match (kind % 3, present) {
            (0, true) => SmaToViewer::Update {
                triangles: vec![Recolour {
                    id,
                    shading: lit(value),
                }],
            },
            (1, true) => {
                shown.remove(&id);
                SmaToViewer::Remove { ids: vec![id] }
            }
            (0 | 1, false) => {
                shown.insert(id, ());
                SmaToViewer::Insert {
                    triangles: vec![triangle(id, value)],
                }
            }
            _ => SmaToViewer::Epoch(epoch(1, 0, shown.len() as u64)),
        };
        out.push((message, flush));
    }
    out
}

proptest! {
    /// However the writer's takes fall, a viewer applying what it is sent ends with the table it
    /// would have had from every message in order, and never sees an invalid step.
    #[test]
    fn coalesced_messages_leave_the_viewer_with_the_same_table(
        steps in prop::collection::vec((0u8..3, 0u8..32, 0.0f32..4.0, any::<bool>()), 0..200)
    ) {
        let messages = stream(&steps);
        let mut every = Table::default();
        let mut coalesced = Table::default();
        let mut pending = Pending::default();
        for (message, flush) in messages {
            every.apply(&message);
            pending.add(message);
            if flush {
                for m in pending.take_closed() {
                    coalesced.apply(&m);
                }
            }
        }
        pending.add(SmaToViewer::Epoch(epoch(0, 0, every.triangles.len() as u64)));
        every.apply(&SmaToViewer::Epoch(epoch(0, 0, every.triangles.len() as u64)));
        for m in pending.take_closed() {
            coalesced.apply(&m);
        }
        prop_assert_eq!(&every.triangles, &coalesced.triangles);
        prop_assert_eq!(every.last_epoch.map(|e| e.shown), coalesced.last_epoch.map(|e| e.shown));
    }
}

#[test]
fn a_viewer_that_does_not_read_holds_at_most_the_latest_state_of_each_triangle() {
    let mut pending = Pending::default();
    pending.add(SmaToViewer::Insert {
        triangles: (0..100).map(|id| triangle(id, 0.0)).collect(),
    });
    let after_insert = pending.bytes();
    for step in 1..1000 {
        pending.add(SmaToViewer::Update {
            triangles: (0..100)
                .map(|id| Recolour {
                    id,
                    shading: lit(step as f32),
                })
                .collect(),
        });
        pending.add(SmaToViewer::Epoch(epoch(0, 0, 100)));
        pending.add(SmaToViewer::Stats(Stats::default()));
    }
    assert_eq!(
        pending.bytes(),
        after_insert + STATS_KEPT * NOTE_BYTES,
        "updates of inserted triangles fold into them; the last statistics are kept"
    );
    let messages = pending.take_closed();
    assert_eq!(
        messages.len(),
        2 + STATS_KEPT,
        "one insert, one epoch, the last statistics: {messages:?}"
    );
    let SmaToViewer::Insert { triangles } = &messages[0] else {
        panic!("insert first, got {:?}", messages[0]);
    };
    assert!(
        triangles
            .iter()
            .all(|t| t.shading.illumination == [[999.0; 3]; 3])
    );
}

#[test]
fn waiting_epochs_add_their_counts_and_keep_the_newest_state() {
    let mut pending = Pending::default();
    pending.add(SmaToViewer::Epoch(Epoch {
        camera_seq: 1,
        ..epoch(5, 2, 3)
    }));
    pending.add(SmaToViewer::Epoch(Epoch {
        camera_seq: 2,
        ..epoch(1, 4, 0)
    }));
    let messages = pending.take_closed();
    assert_eq!(
        messages,
        [SmaToViewer::Epoch(Epoch {
            camera_seq: 2,
            ..epoch(6, 6, 0)
        })]
    );
}

#[test]
fn a_triangle_inserted_and_removed_before_it_is_written_is_never_sent() {
    let mut pending = Pending::default();
    pending.add(SmaToViewer::Insert {
        triangles: vec![triangle(7, 1.0)],
    });
    pending.add(SmaToViewer::Remove { ids: vec![7] });
    pending.add(SmaToViewer::Epoch(epoch(1, 1, 0)));
    assert_eq!(pending.bytes(), 0);
    assert_eq!(pending.take_closed(), [SmaToViewer::Epoch(epoch(1, 1, 0))]);
}

#[test]
fn a_triangle_removed_and_inserted_again_is_replaced() {
    let mut pending = Pending::default();
    pending.add(SmaToViewer::Remove { ids: vec![3] });
    pending.add(SmaToViewer::Insert {
        triangles: vec![triangle(3, 2.0)],
    });
    pending.add(SmaToViewer::Epoch(epoch(1, 1, 1)));
    assert_eq!(
        pending.take_closed(),
        [
            SmaToViewer::Remove { ids: vec![3] },
            SmaToViewer::Insert {
                triangles: vec![triangle(3, 2.0)]
            },
            SmaToViewer::Epoch(epoch(1, 1, 1)),
        ]
    );
}

#[test]
fn changes_after_the_last_epoch_wait_for_theirs() {
    let mut pending = Pending::default();
    pending.add(SmaToViewer::Insert {
        triangles: vec![triangle(1, 1.0)],
    });
    pending.add(SmaToViewer::Epoch(epoch(1, 0, 1)));
    pending.add(SmaToViewer::Insert {
        triangles: vec![triangle(2, 1.0)],
    });
    pending.add(SmaToViewer::ToneMap { l_white: 2.0 });
    let first = pending.take_closed();
    assert_eq!(first.len(), 2, "the first insert and its epoch: {first:?}");
    assert!(
        pending.take_closed().is_empty(),
        "the second waits for its epoch"
    );
    pending.add(SmaToViewer::Epoch(epoch(1, 0, 2)));
    assert_eq!(
        pending.take_closed(),
        [
            SmaToViewer::Insert {
                triangles: vec![triangle(2, 1.0)]
            },
            SmaToViewer::ToneMap { l_white: 2.0 },
            SmaToViewer::Epoch(epoch(1, 0, 2)),
        ]
    );
}

#[tokio::test]
async fn past_its_bound_a_viewer_is_cut_off_and_later_messages_are_dropped() {
    let (outbox, outgoing) = outbox(10 * TRIANGLE_BYTES);
    outbox.send(SmaToViewer::Insert {
        triangles: (0..5).map(|id| triangle(id, 0.0)).collect(),
    });
    outbox.send(SmaToViewer::Epoch(epoch(5, 0, 5)));
    assert_eq!(outgoing.next().await.len(), 2, "under the bound: written");
    outbox.send(SmaToViewer::Insert {
        triangles: (0..11).map(|id| triangle(id + 100, 0.0)).collect(),
    });
    tokio::time::timeout(std::time::Duration::from_secs(5), outbox.overflowed())
        .await
        .expect("the overflow is signalled");
    let before = outbox.shared.pending().bytes();
    outbox.send(SmaToViewer::Remove { ids: vec![0] });
    assert_eq!(
        outbox.shared.pending().bytes(),
        before,
        "dropped once cut off"
    );
}

#[tokio::test]
async fn the_writer_records_when_a_ping_went_out() {
    let (outbox, outgoing) = outbox(1 << 20);
    outbox.send(SmaToViewer::Ping { nonce: 9 });
    let messages = outgoing.next().await;
    assert_eq!(outbox.ping_written(9), None, "taken, not yet written");
    outgoing.written(&messages[0]);
    assert!(outbox.ping_written(9).is_some());
    assert_eq!(outbox.ping_written(8), None);
}
