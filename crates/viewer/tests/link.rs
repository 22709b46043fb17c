//! The SMA link against the scripted stand-in over loopback: the table follows random sequences of
//! inserts, removes and recolours; nothing is drawn before its epoch; a dropped link reconnects and
//! the viewer restarts from an empty table.

mod common;

use std::collections::HashMap;
use std::sync::mpsc;

use common::{Seen, StandIn, scene};
use proptest::prelude::*;
use protocol::texture::Texcoords;
use protocol::viewer_link::{
    CornerShading, DirectShare, Epoch, Recolour, ShownTriangle, SmaToViewer, Stats, ViewerToSma,
};
use testkit::fake_sma::WAIT;
use viewer::link::{Link, LinkEvent};
use viewer::view_state::{Reaction, ViewState};

struct Viewer {
    link: Link,
    events: mpsc::Receiver<LinkEvent>,
    state: ViewState,
}

impl Viewer {
    fn connect(addr: &str) -> Viewer {
        let (tx, events) = mpsc::channel();
        let link = Link::spawn(addr.to_string(), move |e| {
            let _ = tx.send(e);
        })
        .unwrap();
        Viewer {
            link,
            events,
            state: ViewState::default(),
        }
    }

    /// Handles events until one gives a reaction `want` accepts.
    fn until<T>(&mut self, what: &str, mut want: impl FnMut(&LinkEvent) -> Option<T>) -> T {
        loop {
            let event = self
                .events
                .recv_timeout(WAIT)
                .unwrap_or_else(|_| panic!("no {what}"));
            let found = want(&event);
            self.state.handle(event);
            if let Some(found) = found {
                return found;
            }
        }
    }

    fn until_epoch(&mut self, seq: u64) {
        self.until("epoch", |e| match e {
            LinkEvent::Update(u) if u.epoch.camera_seq == seq => Some(()),
            _ => None,
        })
    }
}

fn triangle(id: u64, shade: f32) -> ShownTriangle {
    let x = id as f32;
    ShownTriangle {
        id,
        positions: [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, shade]],
        material: id as u16,
        texcoords: Texcoords::encode(
            [[x, shade], [x + shade, 0.5], [0.25, x]],
            id.is_multiple_of(2),
        ),
        shading: shading(shade),
    }
}

fn shading(shade: f32) -> CornerShading {
    CornerShading {
        illumination: [[shade, 1.0, 2.0], [0.5, shade, 0.25], [1.0, 1.0, shade]],
        direct_share: [DirectShare((shade * 30.0) as u8); 3],
        view_dependent: (shade > 4.0).then_some([[shade; 3], [0.0; 3], [1.0, 0.0, 0.5]]),
    }
}

#[derive(Clone, Debug)]
enum Op {
    Insert(Vec<(u64, f32)>),
    Remove(Vec<u64>),
    Recolour(Vec<(u64, f32)>),
}

fn op() -> impl Strategy<Value = Op> {
    let ids = || prop::collection::vec((0u64..48, 0.01f32..8.0), 0..24);
    prop_oneof![
        3 => ids().prop_map(Op::Insert),
        2 => prop::collection::vec(0u64..60, 0..24).prop_map(Op::Remove),
        1 => ids().prop_map(Op::Recolour),
    ]
}

/// The message an op becomes, and its effect on the model of what the viewer should hold.
fn send_and_model(op: &Op, model: &mut HashMap<u64, ShownTriangle>) -> SmaToViewer {
    match op {
        Op::Insert(list) => {
            let triangles: Vec<_> = list.iter().map(|&(id, s)| triangle(id, s)).collect();
            for t in &triangles {
                model.insert(t.id, t.clone());
            }
            SmaToViewer::Insert { triangles }
        }
        Op::Remove(ids) => {
            for id in ids {
                model.remove(id);
            }
            SmaToViewer::Remove { ids: ids.clone() }
        }
        Op::Recolour(list) => {
            let triangles: Vec<_> = list
                .iter()
                .map(|&(id, s)| Recolour {
                    id,
                    shading: shading(s),
                })
                .collect();
            for r in &triangles {
                if let Some(t) = model.get_mut(&r.id) {
                    t.shading = r.shading.clone();
                }
            }
            SmaToViewer::Update { triangles }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    #[test]
    fn table_matches_random_update_sequences(epochs in prop::collection::vec(prop::collection::vec(op(), 0..6), 1..6)) {
        let sma = StandIn::start(scene());
        let mut viewer = Viewer::connect(&sma.addr);
        viewer.until("connection", |e| matches!(e, LinkEvent::Connected(_)).then_some(()));
        let mut model = HashMap::new();
        for (n, ops) in epochs.iter().enumerate() {
            for op in ops {
                sma.send(send_and_model(op, &mut model));
            }
            sma.send(SmaToViewer::Epoch(Epoch { camera_seq: n as u64 + 1, shown: model.len() as u64, ..Epoch::default() }));
            viewer.until_epoch(n as u64 + 1);
            let table = &viewer.state.table;
            prop_assert_eq!(table.len(), model.len());
            for (id, t) in &model {
                prop_assert_eq!(table.get(*id), Some(t.clone()));
            }
        }
    }
}

#[test]
fn an_update_is_not_drawn_before_its_epoch() {
    let sma = StandIn::start(scene());
    let mut viewer = Viewer::connect(&sma.addr);
    viewer.until("connection", |e| {
        matches!(e, LinkEvent::Connected(_)).then_some(())
    });
    sma.send(SmaToViewer::Insert {
        triangles: vec![triangle(1, 1.0)],
    });
    sma.send(SmaToViewer::Epoch(Epoch {
        camera_seq: 1,
        ..Epoch::default()
    }));
    sma.send(SmaToViewer::Insert {
        triangles: vec![triangle(2, 1.0)],
    });
    sma.send(SmaToViewer::Remove { ids: vec![1] });
    // Stats travel after the half-sent update on the same stream: once they are handled, the link
    // has read the insert and the remove, and must still be holding them back.
    sma.send(SmaToViewer::Stats(Stats {
        samples_per_sec: 5.0,
        ..Stats::default()
    }));
    viewer.until("stats", |e| matches!(e, LinkEvent::Stats(_)).then_some(()));
    assert_eq!(viewer.state.table.ids(), &[1]);
    sma.send(SmaToViewer::ToneMap { l_white: 6.5 });
    sma.send(SmaToViewer::Epoch(Epoch {
        camera_seq: 2,
        ..Epoch::default()
    }));
    viewer.until_epoch(2);
    assert_eq!(viewer.state.table.ids(), &[2]);
    assert_eq!(viewer.state.l_white, 6.5);
}

#[test]
fn a_dropped_link_reconnects_and_starts_from_an_empty_table() {
    let sma = StandIn::start(scene());
    let mut viewer = Viewer::connect(&sma.addr);
    viewer.until("connection", |e| {
        matches!(e, LinkEvent::Connected(_)).then_some(())
    });
    sma.expect("first session", |s| {
        matches!(s, Seen::Session(1)).then_some(())
    });
    sma.send(SmaToViewer::Insert {
        triangles: vec![triangle(1, 1.0)],
    });
    sma.send(SmaToViewer::Epoch(Epoch {
        camera_seq: 1,
        ..Epoch::default()
    }));
    viewer.until_epoch(1);
    assert_eq!(viewer.state.table.len(), 1);

    sma.drop_session();
    viewer.until("disconnection", |e| {
        matches!(e, LinkEvent::Disconnected(_)).then_some(())
    });
    viewer.until("reconnection", |e| {
        matches!(e, LinkEvent::Connected(_)).then_some(())
    });
    sma.expect("second session", |s| {
        matches!(s, Seen::Session(2)).then_some(())
    });
    assert!(
        viewer.state.table.is_empty(),
        "a new session starts from nothing"
    );

    // The new session works both ways.
    viewer.link.send(ViewerToSma::Pause);
    sma.expect("pause", |s| {
        matches!(s, Seen::Message(ViewerToSma::Pause)).then_some(())
    });
    viewer.link.close();
    sma.expect("bye", |s| {
        matches!(s, Seen::Message(ViewerToSma::Bye)).then_some(())
    });
}

#[test]
fn the_link_answers_heartbeats_and_leaves_an_sma_that_falls_silent() {
    let sma = StandIn::start(scene());
    let mut viewer = Viewer::connect(&sma.addr);
    sma.expect("first session", |s| {
        matches!(s, Seen::Session(1)).then_some(())
    });
    sma.expect("an answer to a ping", |s| {
        matches!(s, Seen::Message(ViewerToSma::Pong { nonce: 1 })).then_some(())
    });
    // Pings stop and nothing else comes: the SMA hangs with its socket open.
    sma.mute();
    let muted = std::time::Instant::now();
    let why = viewer.until("disconnection", |e| match e {
        LinkEvent::Disconnected(why) => Some(why.clone()),
        _ => None,
    });
    assert!(why.contains("sent nothing"), "{why}");
    assert!(
        muted.elapsed() >= viewer::link::SMA_SILENCE / 2,
        "lost {:?} after the SMA fell silent",
        muted.elapsed()
    );
    sma.expect("second session", |s| {
        matches!(s, Seen::Session(2)).then_some(())
    });
    viewer.link.close();
}

#[test]
fn closing_while_connecting_to_an_sma_that_never_answers_does_not_wait_for_it() {
    // A port that takes the TCP connection and says nothing: an SMA shutting down, or hung.
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let (accepted_tx, accepted) = mpsc::channel();
    std::thread::spawn(move || {
        let held = listener.accept();
        let _ = accepted_tx.send(());
        std::thread::sleep(2 * viewer::link::CONNECT_TIMEOUT);
        drop(held);
    });
    let viewer = Viewer::connect(&addr);
    accepted.recv_timeout(WAIT).expect("the link connects");
    let closing = std::time::Instant::now();
    viewer.link.close();
    assert!(
        closing.elapsed() < viewer::link::CONNECT_TIMEOUT,
        "close waited {:?} for a handshake that never came",
        closing.elapsed()
    );
}

#[test]
fn view_state_asks_to_restate_on_every_new_session() {
    let mut state = ViewState::default();
    assert_eq!(
        state.handle(LinkEvent::Connected(scene())),
        Reaction::Resend
    );
    assert_eq!(state.refinement, Some(("nld_os".to_string(), false)));
    assert!(state.connected);
}
