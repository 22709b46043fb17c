//! The visible set V_t (DESIGN.md §3 steps 2–3): leaves seen from the camera, each with the side
//! facing the eye (DESIGN.md §5) and its projected pixel count; after them the guard leaves,
//! shown with them though seen at no pixel (`visibility::guards`).

use protocol::Side;

use crate::mesh::NodeId;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VisibleLeaf {
    pub leaf: NodeId,
    pub side: Side,
    /// Pixels of the ID buffer showing this leaf (0 for a guard).
    pub pixels: u32,
}

#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VisibleSet {
    pub leaves: Vec<VisibleLeaf>,
    /// Size of the image the pixel counts come from.
    pub width: u32,
    pub height: u32,
}

impl VisibleSet {
    pub fn image_pixels(&self) -> u64 {
        u64::from(self.width) * u64::from(self.height)
    }
}

/// The viewer's `TriangleId` of a shown leaf: `(leaf << 1) | side`, back = 1.
pub fn shown_id(leaf: NodeId, side: Side) -> u64 {
    (u64::from(leaf) << 1) | u64::from(side == Side::Back)
}

/// Inverse of [`shown_id`].
pub fn split_shown_id(id: u64) -> (NodeId, Side) {
    let side = if id & 1 == 1 { Side::Back } else { Side::Front };
    ((id >> 1) as NodeId, side)
}

#[cfg(test)]
impl VisibleSet {
    /// The front faces of `leaves`, 10 pixels each in an 8×8 image: a view for the schedule's
    /// tests.
    pub(crate) fn of_front_leaves(leaves: &[NodeId]) -> VisibleSet {
        VisibleSet {
            leaves: leaves
                .iter()
                .map(|&leaf| VisibleLeaf {
                    leaf,
                    side: Side::Front,
                    pixels: 10,
                })
                .collect(),
            width: 8,
            height: 8,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shown_ids_round_trip_and_differ_by_side() {
        for leaf in [0, 1, 7, u32::MAX] {
            for side in [Side::Front, Side::Back] {
                assert_eq!(split_shown_id(shown_id(leaf, side)), (leaf, side));
            }
            assert_ne!(shown_id(leaf, Side::Front), shown_id(leaf, Side::Back));
        }
    }
}
