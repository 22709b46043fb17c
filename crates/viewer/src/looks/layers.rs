//! The texture array's contents, made on the CPU (DESIGN.md §5): every drawn texture resampled
//! to one square side (an array's layers share their size), with its full mip chain, each level
//! the mean of four texels of the one above *in linear light* (averaging sRGB codes would darken
//! every fine pattern seen from afar). Layer 0 is white: an untextured material's texel.

use std::sync::Arc;

use super::TextureTexels;

/// Texels of every layer, level by level: `levels[layer][mip]`, RGBA8 sRGB rows from the top.
pub struct Layers {
    pub side: u32,
    pub levels: Vec<Vec<Vec<[u8; 4]>>>,
}

/// The side of the array's layers for `drawn`: the largest texture's longest side, up to a
/// power of two, at most `max_side`, halved until `layers` layers of it with their mips fit in
/// `budget_bytes`.
pub fn layer_side(drawn: &[Arc<TextureTexels>], max_side: u32, budget_bytes: u64) -> u32 {
    let longest = drawn
        .iter()
        .map(|t| t.width.max(t.height))
        .max()
        .unwrap_or(1);
    let mut side = longest.next_power_of_two().min(max_side.max(1));
    let layers = drawn.len() as u64 + 1;
    while side > 1 && layers * chain_bytes(side) > budget_bytes {
        side /= 2;
    }
    side
}

/// Bytes of a square RGBA8 layer of `side` with its mip chain.
pub fn chain_bytes(side: u32) -> u64 {
    let mut bytes = 0;
    let mut s = u64::from(side);
    loop {
        bytes += 4 * s * s;
        if s == 1 {
            return bytes;
        }
        s = (s / 2).max(1);
    }
}

/// Mip levels of a square of `side` (a power of two): down to 1×1.
pub fn mip_levels(side: u32) -> u32 {
    side.max(1).ilog2() + 1
}

impl Layers {
    /// White, then each of `drawn`, at `side` (a power of two).
    pub fn build(drawn: &[Arc<TextureTexels>], side: u32) -> Layers {
        let white = vec![[1.0f32; 3]; (side * side) as usize];
        let levels = std::iter::once(chain(white, side))
            .chain(drawn.iter().map(|t| chain(resampled(t, side), side)))
            .collect();
        Layers { side, levels }
    }
}

/// `texture` in linear values at `side × side`: each axis box-filtered where it shrinks,
/// interpolated (repeating, texel centres at half-integers) where it grows.
fn resampled(texture: &TextureTexels, side: u32) -> Vec<[f32; 3]> {
    let lut: [f32; 256] =
        std::array::from_fn(|code| conventions::tone_map::srgb_decode(code as f32 / 255.0));
    let linear: Vec<[f32; 3]> = texture
        .srgb
        .iter()
        .map(|t| t.map(|c| lut[c as usize]))
        .collect();
    let (w, h) = (texture.width as usize, texture.height as usize);
    let side = side as usize;
    // Rows first: w -> side, then columns: h -> side.
    let mut rows = vec![[0.0f32; 3]; side * h];
    for y in 0..h {
        resample_line(
            &linear[y * w..(y + 1) * w],
            &mut rows[y * side..(y + 1) * side],
        );
    }
    let mut out = vec![[0.0f32; 3]; side * side];
    for x in 0..side {
        let column: Vec<[f32; 3]> = (0..h).map(|y| rows[y * side + x]).collect();
        let mut target = vec![[0.0f32; 3]; side];
        resample_line(&column, &mut target);
        for (y, t) in target.into_iter().enumerate() {
            out[y * side + x] = t;
        }
    }
    out
}

/// `source` resampled into `target` (lengths as given).
fn resample_line(source: &[[f32; 3]], target: &mut [[f32; 3]]) {
    let (n, m) = (source.len(), target.len());
    if n >= m {
        for (i, t) in target.iter_mut().enumerate() {
            let (start, end) = (i * n / m, ((i + 1) * n / m).max(i * n / m + 1));
            let mut sum = [0.0f32; 3];
            for s in &source[start..end] {
                for c in 0..3 {
                    sum[c] += s[c];
                }
            }
            *t = sum.map(|c| c / (end - start) as f32);
        }
    } else {
        for (i, t) in target.iter_mut().enumerate() {
            let x = (i as f32 + 0.5) * n as f32 / m as f32 - 0.5;
            let base = x.floor();
            let f = x - base;
            let i0 = (base as i64).rem_euclid(n as i64) as usize;
            let i1 = (i0 + 1) % n;
            *t = std::array::from_fn(|c| source[i0][c] * (1.0 - f) + source[i1][c] * f);
        }
    }
}

/// The mip chain of a square of `side` linear texels, each level encoded as sRGB.
fn chain(mut level: Vec<[f32; 3]>, side: u32) -> Vec<Vec<[u8; 4]>> {
    let mut levels = Vec::with_capacity(mip_levels(side) as usize);
    let mut s = side as usize;
    loop {
        levels.push(
            level
                .iter()
                .map(|t| {
                    let [r, g, b] = t.map(conventions::tone_map::srgb8);
                    [r, g, b, 255]
                })
                .collect(),
        );
        if s == 1 {
            return levels;
        }
        let half = s / 2;
        level = (0..half * half)
            .map(|i| {
                let (x, y) = (2 * (i % half), 2 * (i / half));
                let texel = |dx: usize, dy: usize| level[(y + dy) * s + x + dx];
                std::array::from_fn(|c| {
                    0.25 * (texel(0, 0)[c] + texel(1, 0)[c] + texel(0, 1)[c] + texel(1, 1)[c])
                })
            })
            .collect();
        s = half;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn texels(width: u32, height: u32, f: impl Fn(u32, u32) -> [u8; 3]) -> Arc<TextureTexels> {
        Arc::new(TextureTexels {
            width,
            height,
            srgb: (0..height)
                .flat_map(|y| (0..width).map(move |x| (x, y)))
                .map(|(x, y)| f(x, y))
                .collect(),
        })
    }

    /// A black-and-white checker's smallest level is the linear mean, mid grey (188 in sRGB),
    /// not the codes' mean (128), which would darken every pattern seen from afar.
    #[test]
    fn mips_average_in_linear_light() {
        let checker = texels(4, 4, |x, y| {
            if (x + y).is_multiple_of(2) {
                [255; 3]
            } else {
                [0; 3]
            }
        });
        let layers = Layers::build(&[checker], 4);
        assert_eq!(layers.levels.len(), 2);
        let chain = &layers.levels[1];
        assert_eq!(chain.len(), 3);
        assert_eq!(chain[0][0], [255, 255, 255, 255]);
        assert_eq!(chain[2], vec![[188, 188, 188, 255]]);
        assert!(layers.levels[0].iter().flatten().all(|t| *t == [255; 4]));
    }

    #[test]
    fn a_smaller_texture_is_stretched_over_the_layer_and_keeps_its_colours() {
        let one = texels(1, 1, |_, _| [200, 100, 50]);
        let two = texels(2, 1, |x, _| if x == 0 { [255, 0, 0] } else { [0, 0, 255] });
        let layers = Layers::build(&[one, two], 8);
        assert!(
            layers.levels[1][0]
                .iter()
                .all(|t| *t == [200, 100, 50, 255])
        );
        let top = &layers.levels[2][0];
        assert_eq!(top.len(), 64);
        // Each half mostly its texel's colour (interpolation blends them at the edges).
        let [r, _, b, _] = top[2];
        assert!(r > 200 && b < 128, "{:?}", top[2]);
        let [r, _, b, _] = top[6];
        assert!(b > 200 && r < 128, "{:?}", top[6]);
    }

    #[test]
    fn the_side_fits_the_largest_texture_and_the_budget() {
        let big = [texels(300, 200, |_, _| [1; 3])];
        assert_eq!(layer_side(&big, 1024, u64::MAX), 512);
        assert_eq!(layer_side(&big, 256, u64::MAX), 256);
        // Two layers of 512² with mips are about 2.8 MB: a 1 MB budget takes 256².
        assert_eq!(layer_side(&big, 1024, 1 << 20), 256);
        assert_eq!(chain_bytes(2), 4 * 4 + 4);
        assert_eq!(mip_levels(8), 4);
    }
}
