//! NLD_IS (thesis §1.4, §4.3.3; DESIGN.md §6): image space. The luminance image is cut into
//! quadrants recursively, breadth first (coarse regions before fine ones); for each quadrant cut
//! into four, the child with the largest S over its four corners (eq. 4.5) has the leaf under its
//! centre selected if that leaf covers at least `min_leaf_pixels` and S is above its floor (0 for
//! eq. 4.5, one display step for the noise-aware metric, as NLD_OS and NLD_PX: DESIGN.md §5–§6;
//! a smaller difference cannot change the picture); every child is still descended,
//! so no region is skipped. A pass ends at 1-pixel quadrants. A call that reaches R selections
//! resumes there next time, on whatever image it is then given; a pass that selected something
//! is followed by another on the image of that time (refinement has changed it), one that
//! selected nothing ends the criterion's work for the camera. A pass starts only on an image
//! that shows something: the SMA paces its viewer syncs, so a round may come before the first
//! triangles are shown, and a pass over that blank image would find nothing and end the work
//! before the picture exists. At most `nld_is_fraction` × width ×
//! height leaves are selected per camera. With `Passes::One` (the thesis profile) the first pass
//! ends the work for the camera, as §4.3.3 ends it; the leaf minimum is then the thesis's 6
//! pixels (`CriterionSettings::nld_is_min_leaf_pixels`).

use std::collections::{HashMap, VecDeque};

use super::{
    Criterion, CriterionInput, CriterionKind, CriterionSettings, LuminanceImage, Metric, Offered,
    Passes, leaf_display_error, nld_mm,
};
use crate::mesh::NodeId;
use crate::mesh::fast_hash::FastHash;
use crate::nld::{nld_metric, noise_aware_nld};
use crate::sample::display;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Quad {
    x: u32,
    y: u32,
    w: u32,
    h: u32,
}

impl Quad {
    /// The four (or, at odd or unit sizes, fewer) quadrants.
    fn children(self) -> impl Iterator<Item = Quad> {
        let (w0, h0) = (self.w.div_ceil(2), self.h.div_ceil(2));
        [
            (0, 0, w0, h0),
            (w0, 0, self.w - w0, h0),
            (0, h0, w0, self.h - h0),
            (w0, h0, self.w - w0, self.h - h0),
        ]
        .into_iter()
        .filter(|&(_, _, w, h)| w > 0 && h > 0)
        .map(move |(dx, dy, w, h)| Quad {
            x: self.x + dx,
            y: self.y + dy,
            w,
            h,
        })
    }

    /// S of eq. 4.5 over the corners that see geometry, by `metric`; `error` gives the
    /// displayed standard error of the leaf seen at a corner.
    fn nld(
        self,
        image: &LuminanceImage,
        l_white: f32,
        metric: Metric,
        error: &dyn Fn(NodeId) -> f32,
    ) -> f32 {
        let (x1, y1) = (self.x + self.w - 1, self.y + self.h - 1);
        let corners = [(self.x, self.y), (x1, self.y), (self.x, y1), (x1, y1)]
            .into_iter()
            .map(|(x, y)| image.index(x, y))
            .filter(|&i| image.ids[i] != LuminanceImage::NONE);
        match metric {
            Metric::Thesis => {
                let lum: Vec<f32> = corners.map(|i| image.luminance[i]).collect();
                nld_metric(&lum, l_white)
            }
            Metric::MaxMin => {
                let lum: Vec<f32> = corners.map(|i| image.luminance[i]).collect();
                nld_mm(&lum, l_white)
            }
            Metric::NoiseAware => {
                let values: Vec<(f32, f32)> = corners
                    .map(|i| (display(image.luminance[i], l_white), error(image.ids[i])))
                    .collect();
                noise_aware_nld(&values)
            }
        }
    }

    fn centre_id(self, image: &LuminanceImage) -> u32 {
        image.ids[image.index(self.x + self.w / 2, self.y + self.h / 2)]
    }
}

pub struct NldIs {
    metric: Metric,
    /// S a quadrant must exceed to select its leaf: above 0 for eq. 4.5 as the thesis has it,
    /// one display step for the noise-aware metric (`CriterionSettings::significance_floor`).
    floor: f32,
    fraction: f32,
    min_leaf_pixels: u32,
    passes: Passes,
    queue: VecDeque<Quad>,
    /// Whether another pass may start: at first, and after a pass that selected something.
    pass_due: bool,
    /// A pass is under way (its quadrants are in `queue`).
    in_pass: bool,
    /// The pass under way has selected something.
    found: bool,
    selected: Offered,
}

impl NldIs {
    /// # Panics
    ///
    /// With [`Metric::MaxMin`]: NLD_MM is the object-space criterion [`CriterionKind::NldMm`]
    /// (eq. 4.4 over a leaf's vertices), and there is no image-space kind to report.
    pub fn new(settings: &CriterionSettings, metric: Metric) -> Self {
        assert!(
            metric != Metric::MaxMin,
            "NLD_MM is an object-space criterion"
        );
        NldIs {
            metric,
            floor: settings.significance_floor(metric, 0.0),
            fraction: settings.nld_is_fraction,
            min_leaf_pixels: settings
                .nld_is_min_leaf_pixels
                .unwrap_or(settings.min_leaf_pixels),
            passes: settings.passes,
            queue: VecDeque::new(),
            pass_due: true,
            in_pass: false,
            found: false,
            selected: Offered::default(),
        }
    }
}

impl Criterion for NldIs {
    fn kind(&self) -> CriterionKind {
        match self.metric {
            Metric::NoiseAware => CriterionKind::NldIs,
            Metric::Thesis => CriterionKind::NldIsThesis,
            Metric::MaxMin => unreachable!("refused by NldIs::new"),
        }
    }

    fn needs_image(&self) -> bool {
        true
    }

    fn select(&mut self, input: &CriterionInput, max: usize) -> Vec<NodeId> {
        let Some(image) = input.image else {
            return Vec::new();
        };
        if image.width == 0 || image.height == 0 {
            return Vec::new();
        }
        self.selected.follow(input.mesh);
        let pixels: HashMap<NodeId, u32, FastHash> = input
            .visible
            .leaves
            .iter()
            .map(|v| (v.leaf, v.pixels))
            .collect();
        let sides: HashMap<NodeId, protocol::Side, FastHash> = input
            .visible
            .leaves
            .iter()
            .map(|v| (v.leaf, v.side))
            .collect();
        let error = |leaf: NodeId| {
            sides
                .get(&leaf)
                .map_or(0.0, |&side| leaf_display_error(input, leaf, side))
        };
        let budget =
            (f64::from(self.fraction) * f64::from(image.width) * f64::from(image.height)) as usize;
        let mut out = Vec::new();
        // One new pass per call at most: the next one should see the image refined meanwhile.
        let mut may_start = true;
        while out.len() < max && self.selected.returned() < budget {
            if self.queue.is_empty() {
                if !may_start || !self.start_pass(image) {
                    break;
                }
                may_start = false;
            }
            let quad = self.queue.pop_front().expect("a pass is under way");
            // The image may have shrunk since the quad was queued.
            if quad.x + quad.w > image.width || quad.y + quad.h > image.height {
                continue;
            }
            let children: Vec<Quad> = quad
                .children()
                .filter(|c| c.w * c.h < quad.w * quad.h)
                .collect();
            let best = children
                .iter()
                .map(|&c| (c, c.nld(image, input.l_white, self.metric, &error)))
                .fold(None, |best: Option<(Quad, f32)>, (c, s)| match best {
                    Some((_, b)) if b >= s => best,
                    _ => Some((c, s)),
                });
            if let Some((child, s)) = best
                && s > self.floor
            {
                let leaf = child.centre_id(image);
                let big_enough = pixels
                    .get(&leaf)
                    .is_some_and(|&p| p >= self.min_leaf_pixels);
                if big_enough && input.mesh.is_leaf(leaf) && self.selected.insert(leaf) {
                    self.found = true;
                    out.push(leaf);
                }
            }
            self.queue.extend(children);
        }
        out
    }

    fn reset(&mut self) {
        self.queue = VecDeque::new();
        self.pass_due = true;
        self.in_pass = false;
        self.found = false;
        self.selected.reset();
    }

    fn heap_bytes(&self) -> usize {
        self.selected.heap_bytes() + self.queue.capacity() * size_of::<Quad>()
    }
}

impl NldIs {
    /// With the queue empty: ends the pass under way, if any (another is due only if it
    /// selected something), and starts the next over the whole image if one is due.
    fn start_pass(&mut self, image: &LuminanceImage) -> bool {
        if !shows_anything(image) {
            return false;
        }
        if self.in_pass {
            self.in_pass = false;
            self.pass_due = self.found && self.passes == Passes::UntilDry;
        }
        if !self.pass_due {
            return false;
        }
        self.in_pass = true;
        self.found = false;
        self.queue.push_back(Quad {
            x: 0,
            y: 0,
            w: image.width,
            h: image.height,
        });
        true
    }
}

/// Whether any pixel that sees geometry is lit: a luminance image of a view whose triangles are
/// not shown yet is black wherever it sees geometry.
fn shows_anything(image: &LuminanceImage) -> bool {
    image
        .ids
        .iter()
        .zip(&image.luminance)
        .any(|(&id, &l)| id != LuminanceImage::NONE && l > 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::criteria::synthetic::{Shading, Synthetic};

    #[test]
    fn a_flat_image_selects_nothing_and_an_edge_is_found() {
        let flat = Synthetic::new(4, 64, Shading::Flat);
        let mut is = NldIs::new(&CriterionSettings::default(), Metric::Thesis);
        assert!(is.select(&flat.input(), 50).is_empty());

        // On an 8-wide grid leaves lie up to 7 units from the line; quadrant centres of the
        // first levels up to 2.9 (half the diagonal of a 4-unit quadrant).
        let edge = Synthetic::new(8, 128, Shading::ShadowEdge);
        is.reset();
        let picked = is.select(&edge.input(), 8);
        assert_eq!(picked.len(), 8);
        assert!(
            picked.iter().all(|&l| edge.distance_to_shadow(l) < 3.0),
            "only leaves near the shadow edge"
        );
    }

    /// A pass that selected something is followed by one over the refined image, which finds
    /// the new leaves along the edge; a pass that selects nothing ends the work for the camera.
    #[test]
    fn passes_go_on_while_they_find_something() {
        let mut edge = Synthetic::new(4, 64, Shading::ShadowEdge);
        let mut is = NldIs::new(&CriterionSettings::default(), Metric::Thesis);
        let first = is.select(&edge.input(), usize::MAX);
        assert!(!first.is_empty());
        edge.refine_and_shade(&first);
        let second = is.select(&edge.input(), usize::MAX);
        assert!(!second.is_empty(), "the refined image has more to give");
        assert!(second.iter().all(|l| !first.contains(l)));
        // Without refinement in between the next pass finds nothing, and none follows it.
        assert!(is.select(&edge.input(), usize::MAX).is_empty());
        assert!(is.select(&edge.input(), usize::MAX).is_empty());
        assert!(is.queue.is_empty() && !is.pass_due);
        is.reset();
        assert!(!is.select(&edge.input(), usize::MAX).is_empty());
    }

    /// §4.3.3: one hierarchical pass per camera, however much it found.
    #[test]
    fn one_pass_ends_the_work_for_the_camera() {
        let mut edge = Synthetic::new(4, 64, Shading::ShadowEdge);
        let one = CriterionSettings {
            passes: Passes::One,
            ..Default::default()
        };
        let mut is = NldIs::new(&one, Metric::Thesis);
        let first = is.select(&edge.input(), usize::MAX);
        assert!(!first.is_empty());
        edge.refine_and_shade(&first);
        assert!(
            is.select(&edge.input(), usize::MAX).is_empty(),
            "no second pass"
        );
        is.reset();
        assert!(
            !is.select(&edge.input(), usize::MAX).is_empty(),
            "a new camera"
        );
    }

    /// §4.3.3's 6 pixels, NLD_IS's own minimum when set, in place of every criterion's.
    #[test]
    fn the_thesis_minimum_of_six_pixels_holds_for_nld_is() {
        let mut edge = Synthetic::new(4, 64, Shading::ShadowEdge);
        let thesis = CriterionSettings {
            nld_is_min_leaf_pixels: Some(6),
            ..Default::default()
        };
        let select = |edge: &Synthetic, settings: &CriterionSettings| {
            NldIs::new(settings, Metric::Thesis).select(&edge.input(), usize::MAX)
        };
        edge.visible.leaves.iter_mut().for_each(|v| v.pixels = 5);
        assert!(select(&edge, &thesis).is_empty(), "5 pixels are too few");
        assert!(!select(&edge, &CriterionSettings::default()).is_empty());
        edge.visible.leaves.iter_mut().for_each(|v| v.pixels = 6);
        assert!(!select(&edge, &thesis).is_empty(), "6 pixels are enough");
    }

    /// A round before the first triangles are shown sees a blank image: it selects nothing and
    /// does not end the work, so the picture, once shown, is refined.
    #[test]
    fn a_blank_image_neither_selects_nor_ends_the_work() {
        let mut edge = Synthetic::new(4, 64, Shading::ShadowEdge);
        let shown = edge.image.luminance.clone();
        edge.image.luminance.fill(0.0);
        let mut is = NldIs::new(&CriterionSettings::default(), Metric::Thesis);
        assert!(is.select(&edge.input(), usize::MAX).is_empty());
        assert!(is.select(&edge.input(), usize::MAX).is_empty());
        edge.image.luminance = shown;
        assert!(!is.select(&edge.input(), usize::MAX).is_empty());
    }

    #[test]
    fn calls_resume_where_the_last_one_stopped() {
        let edge = Synthetic::new(4, 64, Shading::ShadowEdge);
        let mut whole = NldIs::new(&CriterionSettings::default(), Metric::Thesis);
        let all = whole.select(&edge.input(), usize::MAX);
        let mut parts = NldIs::new(&CriterionSettings::default(), Metric::Thesis);
        let mut resumed = Vec::new();
        loop {
            let part = parts.select(&edge.input(), 3);
            if part.is_empty() {
                break;
            }
            resumed.extend(part);
        }
        assert_eq!(resumed, all);
    }
}
