//! Holding back the SMA's changes until their `Epoch` (DESIGN.md §3 step 6, §8): a refinement step
//! arrives as several messages (children in, parent out, green neighbours), and drawing any prefix
//! of it would show a hole or a T-junction. Messages are staged here and released as one
//! [`EpochUpdate`] when the epoch that closes them arrives.

use protocol::viewer_link::{Epoch, Recolour, ShownTriangle, SmaToViewer, TriangleId};

/// One table operation, in the order the SMA sent it.
#[derive(Clone, Debug, PartialEq)]
pub enum TableOp {
    Insert(Vec<ShownTriangle>),
    Remove(Vec<TriangleId>),
    Recolour(Vec<Recolour>),
}

/// Everything one epoch closed.
#[derive(Clone, Debug, PartialEq)]
pub struct EpochUpdate {
    pub ops: Vec<TableOp>,
    /// A new L_white sent within this update (thesis §2.3: sent whenever the maximum changes).
    pub l_white: Option<f32>,
    pub epoch: Epoch,
}

/// What staging one message gave.
#[derive(Debug, PartialEq)]
pub enum Staged {
    /// Held until the next epoch.
    Held,
    /// An epoch closed these changes: they may be drawn now.
    Closed(EpochUpdate),
    /// A message that is not part of an update (scene info, stats, refinement state, errors).
    Other(SmaToViewer),
}

#[derive(Default)]
pub struct Staging {
    ops: Vec<TableOp>,
    l_white: Option<f32>,
}

impl Staging {
    pub fn stage(&mut self, msg: SmaToViewer) -> Staged {
        match msg {
            SmaToViewer::Insert { triangles } => self.ops.push(TableOp::Insert(triangles)),
            SmaToViewer::Remove { ids } => self.ops.push(TableOp::Remove(ids)),
            SmaToViewer::Update { triangles } => self.ops.push(TableOp::Recolour(triangles)),
            // A non-positive or non-finite L_white cannot normalise anything: keep the last one.
            SmaToViewer::ToneMap { l_white } if l_white.is_finite() && l_white > 0.0 => {
                self.l_white = Some(l_white)
            }
            SmaToViewer::ToneMap { .. } => {}
            SmaToViewer::Epoch(epoch) => {
                return Staged::Closed(EpochUpdate {
                    ops: std::mem::take(&mut self.ops),
                    l_white: self.l_white.take(),
                    epoch,
                });
            }
            other => return Staged::Other(other),
        }
        Staged::Held
    }

    /// Drops what a lost connection left half sent.
    pub fn clear(&mut self) {
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn changes_are_released_only_by_their_epoch_in_order() {
        let mut s = Staging::default();
        let t = ShownTriangle {
            id: 5,
            positions: [[0.0; 3]; 3],
            material: 0,
            texcoords: Default::default(),
            shading: Default::default(),
        };
        assert_eq!(
            s.stage(SmaToViewer::Insert {
                triangles: vec![t.clone()]
            }),
            Staged::Held
        );
        assert_eq!(s.stage(SmaToViewer::Remove { ids: vec![4] }), Staged::Held);
        assert_eq!(
            s.stage(SmaToViewer::ToneMap { l_white: -1.0 }),
            Staged::Held
        );
        assert_eq!(s.stage(SmaToViewer::ToneMap { l_white: 3.0 }), Staged::Held);
        let epoch = Epoch {
            camera_seq: 2,
            shown: 1,
            ..Epoch::default()
        };
        let Staged::Closed(update) = s.stage(SmaToViewer::Epoch(epoch)) else {
            panic!("an epoch must close the update")
        };
        assert_eq!(
            update.ops,
            vec![TableOp::Insert(vec![t]), TableOp::Remove(vec![4])]
        );
        assert_eq!((update.l_white, update.epoch), (Some(3.0), epoch));
        let Staged::Closed(empty) = s.stage(SmaToViewer::Epoch(epoch)) else {
            panic!()
        };
        assert!(empty.ops.is_empty() && empty.l_white.is_none());
    }
}
