use std::io::Cursor;

use super::*;

/// Linear value of an 8-bit sRGB code.
fn lin(code: u8) -> f32 {
    conventions::tone_map::srgb_decode(f32::from(code) / 255.0)
}

/// 2 × 2: red, green on the top row; blue, grey 128 below.
fn quadrants() -> Texture {
    Texture::from_srgb8(
        2,
        2,
        &[[255, 0, 0], [0, 255, 0], [0, 0, 255], [128, 128, 128]],
    )
}

fn encoded(texture: &[[u8; 3]], width: u32, height: u32, format: image::ImageFormat) -> Vec<u8> {
    let image = image::RgbImage::from_raw(width, height, texture.concat()).expect("sizes match");
    let mut bytes = Cursor::new(Vec::new());
    image.write_to(&mut bytes, format).expect("encodes");
    bytes.into_inner()
}

#[test]
fn texels_are_read_as_linear_values() {
    let t = quadrants();
    assert_eq!(t.texel(0, 0), Vec3::X);
    assert_eq!(t.texel(1, 1), Vec3::splat(lin(128)));
    assert!((t.texel(1, 1).x - 0.215_860_5).abs() < 1e-6);
}

#[test]
fn lookup_at_texel_centres_is_the_texel_and_v_grows_up_the_image() {
    let t = quadrants();
    for wrap in [Wrap::Repeat, Wrap::Clamp] {
        // v = 0.75 is the top row (the image's first), v = 0.25 the bottom one.
        assert_eq!(t.lookup(Vec2::new(0.25, 0.75), wrap), Vec3::X);
        assert_eq!(t.lookup(Vec2::new(0.75, 0.75), wrap), Vec3::Y);
        assert_eq!(t.lookup(Vec2::new(0.25, 0.25), wrap), Vec3::Z);
        assert_eq!(t.lookup(Vec2::new(0.75, 0.25), wrap), t.texel(1, 1));
    }
}

#[test]
fn bilinear_blends_linear_values() {
    let t = quadrants();
    // Halfway between red and green along the top row: half of each, in linear terms.
    let mid = t.lookup(Vec2::new(0.5, 0.75), Wrap::Repeat);
    assert!(mid.abs_diff_eq(Vec3::new(0.5, 0.5, 0.0), 1e-6), "{mid}");
    // The centre: a quarter of each texel.
    let centre = t.lookup(Vec2::splat(0.5), Wrap::Clamp);
    let expected = (Vec3::X + Vec3::Y + Vec3::Z + Vec3::splat(lin(128))) / 4.0;
    assert!(centre.abs_diff_eq(expected, 1e-6), "{centre}");
}

#[test]
fn repeat_wraps_around_and_clamp_holds_the_edge() {
    let t = quadrants();
    // u = 0 on the top row is halfway between the last column and the first when repeating.
    let wrapped = t.lookup(Vec2::new(0.0, 0.75), Wrap::Repeat);
    assert!(
        wrapped.abs_diff_eq(Vec3::new(0.5, 0.5, 0.0), 1e-6),
        "{wrapped}"
    );
    assert_eq!(t.lookup(Vec2::new(0.0, 0.75), Wrap::Clamp), Vec3::X);
    assert_eq!(t.lookup(Vec2::new(-3.0, 7.0), Wrap::Clamp), Vec3::X);
    // Whole periods away, the same texel; far coordinates keep their fraction.
    for u in [1.25, -0.75, 1000.25, -999.75] {
        let far = t.lookup(Vec2::new(u, 0.75 + 3.0), Wrap::Repeat);
        assert!(far.abs_diff_eq(Vec3::X, 1e-3), "u {u}: {far}");
    }
    // A non-finite coordinate reads as 0 instead of indexing out of range.
    let nan = t.lookup(Vec2::new(f32::NAN, f32::INFINITY), Wrap::Repeat);
    assert_eq!(nan, t.lookup(Vec2::ZERO, Wrap::Repeat));
}

#[test]
fn the_nearest_texel_is_the_one_under_the_coordinates_unblended() {
    let t = quadrants();
    // Red top-left, green top-right, blue bottom-left; v grows up the image.
    for wrap in [Wrap::Repeat, Wrap::Clamp] {
        assert_eq!(t.nearest(Vec2::new(0.01, 0.99), wrap), Vec3::X);
        assert_eq!(t.nearest(Vec2::new(0.51, 0.51), wrap), Vec3::Y);
        assert_eq!(t.nearest(Vec2::new(0.49, 0.49), wrap), Vec3::Z);
    }
    // Repeating, whole periods away and below zero; clamped, the edge.
    assert_eq!(t.nearest(Vec2::new(-0.75, 3.75), Wrap::Repeat), Vec3::X);
    assert_eq!(t.nearest(Vec2::new(1.75, -0.25), Wrap::Repeat), Vec3::Y);
    assert_eq!(t.nearest(Vec2::new(-3.0, 7.0), Wrap::Clamp), Vec3::X);
    assert_eq!(t.nearest(Vec2::new(f32::NAN, 1.0), Wrap::Repeat), Vec3::X);
}

#[test]
fn the_mean_is_over_linear_values() {
    let t = Texture::from_srgb8(2, 1, &[[0, 0, 0], [255, 255, 255]]);
    assert!(t.mean().abs_diff_eq(Vec3::splat(0.5), 1e-7));
}

#[test]
fn png_and_jpeg_decode() {
    let texels = [[255, 0, 0], [0, 255, 0], [0, 0, 255], [128, 128, 128]];
    let png = encoded(&texels, 2, 2, image::ImageFormat::Png);
    let decoded = Texture::decode(&png, Path::new("t.png")).expect("a PNG decodes");
    assert_eq!(decoded.texture, quadrants());
    assert_eq!(decoded.downscaled_from, None);
    // JPEG is lossy: a flat colour comes back within a few codes.
    let flat = vec![[200, 100, 50]; 64];
    let jpeg = encoded(&flat, 8, 8, image::ImageFormat::Jpeg);
    // The format is found from the content, whatever the name says.
    let decoded = Texture::decode(&jpeg, Path::new("named wrongly.png")).expect("decodes");
    let mean = decoded.texture.mean();
    let expected = Vec3::new(lin(200), lin(100), lin(50));
    assert!(mean.abs_diff_eq(expected, 0.02), "{mean} vs {expected}");
}

#[test]
fn undecodable_bytes_are_an_error_not_a_panic() {
    for bytes in [&b""[..], b"not an image", &b"\x89PNG\r\n\x1a\n"[..]] {
        assert!(Texture::decode(bytes, Path::new("t.png")).is_err());
    }
    let png = encoded(&[[1, 2, 3]; 4], 2, 2, image::ImageFormat::Png);
    assert!(Texture::decode(&png[..png.len() / 2], Path::new("t.png")).is_err());
}

/// A PNG header announcing 20000 × 20000 texels (1.2 GB decoded) in a file of a few dozen
/// bytes is refused by the decoding limits before anything is allocated.
#[test]
fn a_decompression_bomb_is_refused_by_the_limits() {
    let mut ihdr = Vec::new();
    ihdr.extend(20_000u32.to_be_bytes());
    ihdr.extend(20_000u32.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]); // 8-bit RGB, no interlace
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    for (kind, data) in [
        (b"IHDR", ihdr),
        (b"IDAT", vec![0x78, 0x9c]),
        (b"IEND", vec![]),
    ] {
        png.extend((data.len() as u32).to_be_bytes());
        let typed: Vec<u8> = kind.iter().chain(&data).copied().collect();
        png.extend(&typed);
        png.extend(crc32(&typed).to_be_bytes());
    }
    let error = Texture::decode(&png, Path::new("bomb.png")).expect_err("refused");
    assert!(error.contains("limit"), "{error}");
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

#[test]
fn a_texture_over_the_cap_is_box_filtered_in_linear_values() {
    // 4 × 2 → cap 2 → 2 × 1: each target texel is the linear mean of a 2 × 2 block.
    let t = Texture::from_srgb8(
        4,
        2,
        &[
            [0, 0, 0],
            [255, 255, 255],
            [10, 20, 30],
            [10, 20, 30],
            [255, 255, 255],
            [0, 0, 0],
            [10, 20, 30],
            [10, 20, 30],
        ],
    );
    let capped = t.capped(2);
    assert_eq!(capped.downscaled_from, Some((4, 2)));
    let small = capped.texture;
    assert_eq!((small.width(), small.height()), (2, 1));
    // Black and white average to linear 0.5, sRGB code 188 (not 128).
    assert_eq!(&small.srgb[..3], &[188, 188, 188]);
    assert_eq!(&small.srgb[3..], &[10, 20, 30]);
    // Under the cap nothing changes.
    let same = quadrants().capped(2);
    assert_eq!(same.downscaled_from, None);
    assert_eq!(same.texture, quadrants());
}

#[test]
fn mip_levels_halve_down_to_one_texel_and_keep_the_mean() {
    // 8 × 2 black and white stripes one texel wide: 4 × 1, 2 × 1, 1 × 1 below it.
    let texels: Vec<[u8; 3]> = (0..16)
        .map(|i| if i % 2 == 0 { [0; 3] } else { [255; 3] })
        .collect();
    let t = Texture::from_srgb8(8, 2, &texels);
    let levels = t.mip_levels();
    let sizes: Vec<(u32, u32)> = levels.iter().map(|l| (l.width(), l.height())).collect();
    assert_eq!(sizes, [(4, 1), (2, 1), (1, 1)]);
    // Every level is uniform at the stripes' linear mean (a quantisation step of the code).
    for level in &levels {
        assert!(
            (level.mean() - t.mean()).abs().max_element() < 0.01,
            "{level:?}"
        );
        assert_eq!(level.texel(0, 0), level.texel(level.width() - 1, 0));
    }
    assert!(
        Texture::from_srgb8(1, 1, &[[9, 9, 9]])
            .mip_levels()
            .is_empty()
    );
}

#[test]
fn decoding_caps_the_longest_side_keeping_the_aspect() {
    let wide = MAX_TEXTURE_SIDE + 2;
    let texels = vec![[90, 90, 90]; wide as usize * 3];
    let png = encoded(&texels, wide, 3, image::ImageFormat::Png);
    let decoded = Texture::decode(&png, Path::new("wide.png")).expect("decodes");
    assert_eq!(decoded.downscaled_from, Some((wide, 3)));
    let t = &decoded.texture;
    assert_eq!((t.width(), t.height()), (MAX_TEXTURE_SIDE, 3));
    assert!(t.srgb.iter().all(|&c| c == 90));
}

#[test]
fn the_albedo_rules_and_the_map_transform() {
    let map = DiffuseMap {
        texture: Arc::new(quadrants()),
        scale: Vec2::new(0.5, 0.5),
        offset: Vec2::new(0.5, 0.5),
        wrap: Wrap::Repeat,
        rule: AlbedoRule::KdTimesTexture,
        file: "q.png".into(),
        source: [0; 32],
    };
    let kd = Vec3::new(0.5, 0.25, 1.0);
    // (0.5, 0.5) × 0.5 + 0.5 = (0.75, 0.75): the green texel.
    assert_eq!(map.albedo(kd, Vec2::splat(0.5)), Vec3::new(0.0, 0.25, 0.0));
    let texture_only = DiffuseMap {
        rule: AlbedoRule::Texture,
        ..map
    };
    assert_eq!(texture_only.albedo(kd, Vec2::splat(0.5)), Vec3::Y);
}
