//! Tone mapping (DESIGN.md §9, thesis §4.1): an operator maps luminance to display luminance, and
//! the colour is scaled by the ratio, so hues are kept; then sRGB encoding.

use crate::luminance::luminance;

/// A tone-mapping operator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ToneMap {
    /// Drago's logarithmic mapping, eq. 4.2: L_d = log(1 + L) / log(1 + L_white).
    #[default]
    Drago,
    /// Reinhard's global operator, eq. 4.1: L_d = L (1 + L / L_white²) / (1 + L).
    Reinhard,
}

impl ToneMap {
    /// The operator's name, as the viewer's panel and flags spell it.
    pub fn name(self) -> &'static str {
        match self {
            ToneMap::Drago => "drago",
            ToneMap::Reinhard => "reinhard",
        }
    }

    /// The other operator (the window's key toggles between them).
    pub fn next(self) -> ToneMap {
        match self {
            ToneMap::Drago => ToneMap::Reinhard,
            ToneMap::Reinhard => ToneMap::Drago,
        }
    }

    /// Display luminance of luminance `l` with white point `l_white`.
    pub fn display_luminance(self, l: f32, l_white: f32) -> f32 {
        match self {
            ToneMap::Drago => (1.0 + l).ln() / (1.0 + l_white).ln(),
            ToneMap::Reinhard => l * (1.0 + l / (l_white * l_white)) / (1.0 + l),
        }
    }

    /// Display RGB of linear `rgb`: its luminance mapped, its colour kept, clamped to 0..1. Black
    /// where the luminance or `l_white` is not positive (NaN included).
    pub fn display_rgb(self, rgb: [f32; 3], l_white: f32) -> [f32; 3] {
        let l = luminance(rgb);
        // Comparisons with NaN are false, so NaN is rejected too.
        if !(l > 0.0 && l_white > 0.0) {
            return [0.0; 3];
        }
        let scale = self.display_luminance(l, l_white) / l;
        rgb.map(|c| (c * scale).clamp(0.0, 1.0))
    }
}

/// sRGB transfer function of a linear value, clamped to 0..1.
pub fn srgb_encode(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear value of an sRGB-encoded one in 0..1 (clamped): the inverse of [`srgb_encode`], for
/// texels, which image files store encoded (DESIGN.md §5).
pub fn srgb_decode(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.040_45 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

/// 8-bit sRGB of a display value in 0..1, rounded.
pub fn srgb8(x: f32) -> u8 {
    (srgb_encode(x) * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_decode_inverts_the_8_bit_encoding() {
        for code in 0..=255u8 {
            assert_eq!(srgb8(srgb_decode(f32::from(code) / 255.0)), code);
        }
        assert_eq!(srgb_decode(0.0), 0.0);
        assert!((srgb_decode(1.0) - 1.0).abs() < 1e-6);
        // Mid-grey as stored (128) is about a fifth of white in linear terms.
        assert!((srgb_decode(128.0 / 255.0) - 0.2158605).abs() < 1e-6);
    }

    #[test]
    fn white_maps_to_one_and_colour_ratios_are_kept() {
        for op in [ToneMap::Drago, ToneMap::Reinhard] {
            let white = op.display_rgb([5.0; 3], 5.0);
            assert!(
                white.iter().all(|c| (c - 1.0).abs() < 1e-5),
                "{op:?} {white:?}"
            );
            let c = op.display_rgb([2.0, 1.0, 0.5], 10.0);
            assert!((c[0] / c[1] - 2.0).abs() < 1e-4 && (c[1] / c[2] - 2.0).abs() < 1e-4);
            assert_eq!(op.display_rgb([0.0; 3], 1.0), [0.0; 3]);
            assert_eq!(op.display_rgb([f32::NAN; 3], 1.0), [0.0; 3]);
        }
    }

    #[test]
    fn srgb_is_linear_near_black_and_ends_at_one() {
        assert!((srgb_encode(0.001) - 0.012_92).abs() < 1e-7);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-6);
        assert_eq!(srgb8(1.0), 255);
        assert_eq!(srgb8(-1.0), 0);
    }
}
