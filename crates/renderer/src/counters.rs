//! Ray counters by kind, so a test can see which effects were simulated (DESIGN.md §7: simulate only
//! the effects a scene calls for) and a benchmark can report rays per second.

use std::ops::AddAssign;

/// What a ray was traced for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RayKind {
    /// From the eye through a pixel (reference images).
    Camera,
    /// Diffuse bounce of a path.
    Bounce,
    /// Glossy-lobe bounce of a path.
    Glossy,
    /// Perfect-mirror reflection.
    Mirror,
    ShadowSun,
    ShadowSky,
    ShadowArea,
    /// Short probe rays of the hidden-point test (`point.rs`).
    Probe,
}

/// Rays traced, per kind. Plain counters, one set per worker, summed afterwards.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    pub camera: u64,
    pub bounce: u64,
    pub glossy: u64,
    pub mirror: u64,
    pub shadow_sun: u64,
    pub shadow_sky: u64,
    pub shadow_area: u64,
    pub probe: u64,
}

impl RayCounts {
    pub fn count(&mut self, kind: RayKind) {
        *self.slot(kind) += 1;
    }

    pub fn get(&self, kind: RayKind) -> u64 {
        let mut copy = *self;
        *copy.slot(kind)
    }

    pub fn total(&self) -> u64 {
        self.camera
            + self.bounce
            + self.glossy
            + self.mirror
            + self.shadow_sun
            + self.shadow_sky
            + self.shadow_area
            + self.probe
    }

    fn slot(&mut self, kind: RayKind) -> &mut u64 {
        match kind {
            RayKind::Camera => &mut self.camera,
            RayKind::Bounce => &mut self.bounce,
            RayKind::Glossy => &mut self.glossy,
            RayKind::Mirror => &mut self.mirror,
            RayKind::ShadowSun => &mut self.shadow_sun,
            RayKind::ShadowSky => &mut self.shadow_sky,
            RayKind::ShadowArea => &mut self.shadow_area,
            RayKind::Probe => &mut self.probe,
        }
    }
}

impl AddAssign for RayCounts {
    fn add_assign(&mut self, o: RayCounts) {
        self.camera += o.camera;
        self.bounce += o.bounce;
        self.glossy += o.glossy;
        self.mirror += o.mirror;
        self.shadow_sun += o.shadow_sun;
        self.shadow_sky += o.shadow_sky;
        self.shadow_area += o.shadow_area;
        self.probe += o.probe;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_land_in_their_own_slot_and_sum() {
        let mut a = RayCounts::default();
        a.count(RayKind::Mirror);
        a.count(RayKind::ShadowSky);
        a.count(RayKind::ShadowSky);
        let mut b = RayCounts::default();
        b.count(RayKind::Mirror);
        a += b;
        assert_eq!(a.get(RayKind::Mirror), 2);
        assert_eq!(a.get(RayKind::ShadowSky), 2);
        assert_eq!(a.get(RayKind::Glossy), 0);
        assert_eq!(a.total(), 4);
    }
}
