//! Rec. 709 luminance of linear RGB (DESIGN.md §6).

/// The Rec. 709 weights of R, G and B.
pub const REC709: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// Rec. 709 luminance of linear RGB. Inlined across crates: the renderer calls it at every path
/// vertex (choosing a lobe), where a call cost more than the arithmetic.
#[inline]
pub fn luminance(rgb: [f32; 3]) -> f32 {
    REC709[0] * rgb[0] + REC709[1] * rgb[1] + REC709[2] * rgb[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_sum_to_one() {
        assert!((luminance([1.0; 3]) - 1.0).abs() < 1e-6);
        assert_eq!(luminance([0.0, 1.0, 0.0]), REC709[1]);
    }
}
