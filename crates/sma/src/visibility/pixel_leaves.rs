//! The leaf seen at each pixel of a view, kept between passes as runs (DESIGN.md §3 step 3, §4):
//! the carry-over re-assigns the pixels whose leaf is gone, `nld-is` reads it as its ID image, the
//! plan looks at the centre pixel. Neighbouring pixels mostly show one leaf, so runs along the
//! rows hold it in a fraction of one id per pixel, and the coarser the mesh (as under a tight
//! `--memory-mib`), the fewer the runs: at 512×384 a flat `Option<NodeId>` per pixel took 1.6 MB
//! of every viewer's state.

use std::ops::Range;

use crate::mesh::NodeId;

/// Marks a run of background pixels.
const NO_LEAF: u32 = u32::MAX;

/// One leaf over consecutive pixels, row-major (a run may go on into the next row).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Run {
    leaf: u32,
    /// One past its last pixel.
    end: u32,
}

/// The leaf under every pixel, row-major from the top-left; `None` for background. Runs of equal
/// pixels are always merged, so two equal images compare equal.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PixelLeaves {
    runs: Vec<Run>,
}

impl PixelLeaves {
    /// Pixels covered by the runs.
    pub fn len(&self) -> usize {
        self.runs.last().map_or(0, |r| r.end as usize)
    }

    pub fn is_empty(&self) -> bool {
        self.runs.is_empty()
    }

    /// The leaf at pixel `i`; `None` for background or past the end.
    pub fn get(&self, i: usize) -> Option<NodeId> {
        let run = self.runs.partition_point(|r| r.end as usize <= i);
        self.runs.get(run).and_then(|r| leaf(r.leaf))
    }

    /// Every pixel's leaf, in order.
    pub fn iter(&self) -> impl Iterator<Item = Option<NodeId>> + '_ {
        self.runs()
            .flat_map(|(pixels, leaf)| std::iter::repeat_n(leaf, pixels.len()))
    }

    /// The runs: pixels and their leaf.
    pub fn runs(&self) -> impl Iterator<Item = (Range<u32>, Option<NodeId>)> + '_ {
        let starts = std::iter::once(0).chain(self.runs.iter().map(|r| r.end));
        starts
            .zip(&self.runs)
            .map(|(start, r)| (start..r.end, leaf(r.leaf)))
    }

    /// Appends `count` pixels showing `leaf`.
    pub fn push(&mut self, leaf: Option<NodeId>, count: u32) {
        if count == 0 {
            return;
        }
        let leaf = leaf.unwrap_or(NO_LEAF);
        let end = self.len() as u32 + count;
        match self.runs.last_mut() {
            Some(last) if last.leaf == leaf => last.end = end,
            _ => self.runs.push(Run { leaf, end }),
        }
    }

    /// Gives back what the runs' growth reserved beyond them: the view is kept between passes.
    pub fn shrink_to_fit(&mut self) {
        self.runs.shrink_to_fit();
    }

    /// Heap bytes by capacity.
    pub fn heap_bytes(&self) -> usize {
        self.runs.capacity() * size_of::<Run>()
    }
}

fn leaf(id: u32) -> Option<NodeId> {
    (id != NO_LEAF).then_some(id)
}

impl FromIterator<Option<NodeId>> for PixelLeaves {
    fn from_iter<I: IntoIterator<Item = Option<NodeId>>>(pixels: I) -> Self {
        let mut leaves = PixelLeaves::default();
        for pixel in pixels {
            leaves.push(pixel, 1);
        }
        leaves.shrink_to_fit();
        leaves
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_give_back_every_pixel_and_merge_equal_neighbours() {
        let pixels = [
            None,
            Some(3),
            Some(3),
            Some(3),
            Some(7),
            None,
            None,
            Some(3),
        ];
        let leaves: PixelLeaves = pixels.into_iter().collect();
        assert_eq!(leaves.len(), pixels.len());
        assert_eq!(leaves.iter().collect::<Vec<_>>(), pixels);
        assert_eq!(leaves.runs().count(), 5);
        for (i, &p) in pixels.iter().enumerate() {
            assert_eq!(leaves.get(i), p, "pixel {i}");
        }
        assert_eq!(leaves.get(pixels.len()), None);
        assert_eq!(leaves.heap_bytes(), 5 * size_of::<Run>());
        // Built run by run, with a split run, the image is the same and compares equal.
        let mut by_runs = PixelLeaves::default();
        for (leaf, count) in [(None, 1), (Some(3), 2), (Some(3), 1), (Some(7), 1)] {
            by_runs.push(leaf, count);
        }
        by_runs.push(Some(9), 0);
        for (leaf, count) in [(None, 2), (Some(3), 1)] {
            by_runs.push(leaf, count);
        }
        assert_eq!(by_runs, leaves);
        assert!(PixelLeaves::default().is_empty());
    }
}
