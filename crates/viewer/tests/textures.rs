//! Each pixel's albedo (DESIGN.md §5, "Parts, and textures"): a textured quad lit evenly, as by
//! the sun, shows its texture's pattern, the right way up, with the texel colours times its
//! material's factor times the illumination; an untextured quad drawn in the same pass shows
//! the colour it had when the SMA multiplied `kd` in itself, within one 8-bit step; a material
//! whose texture did not decode shows its flat `kd`. Needs a wgpu adapter: run on GL and Vulkan.

mod common;

use common::{front_camera, lit_triangle, scene};
use protocol::texture::{MaterialLook, MaterialTexture, Texcoords, TextureImage, TextureInfo};
use protocol::viewer_link::{SceneInfo, ShownTriangle};
use viewer::direct_image::DirectImage;
use viewer::gpu::headless_or_skip;
use viewer::looks::Looks;
use viewer::{DrawSettings, Snapshot, render_offscreen_with, render_offscreen_with_looks};

const W: u32 = 192;
const H: u32 = 144;
const ILLUMINATION: f32 = 1.5;
/// The quadrants of the texture, as an image shows them: top-left, top-right, bottom-left,
/// bottom-right.
const QUADRANTS: [[u8; 3]; 4] = [[230, 40, 20], [40, 200, 30], [20, 60, 200], [250, 250, 250]];

/// A 4×4 texture whose 2×2 quadrants are one colour each: the centre of a quadrant reads its
/// colour exactly, however the sampler filters.
fn quadrant_png() -> Vec<u8> {
    let image = image::RgbImage::from_fn(4, 4, |x, y| {
        image::Rgb(QUADRANTS[(2 * (y / 2) + x / 2) as usize])
    });
    let mut bytes = Vec::new();
    image
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .unwrap();
    bytes
}

fn info() -> SceneInfo {
    let textured = |index| MaterialLook {
        kd: [0.8, 0.7, 0.9],
        texture: Some(MaterialTexture {
            index,
            times_kd: true,
            clamp: false,
        }),
    };
    let table = |name: &str| TextureInfo {
        name: name.into(),
        width: 4,
        height: 4,
        bytes: 0,
    };
    SceneInfo {
        materials: vec![
            MaterialLook {
                kd: [0.6, 0.3, 0.2],
                texture: None,
            },
            textured(0),
            textured(1),
        ],
        texture_table: vec![table("quadrants.png"), table("broken.png")],
        textures: true,
        ..scene()
    }
}

/// A unit-lit quad of `material` over x0..x1, y -0.6..0.6, texture coordinates 0..1 from its
/// bottom-left corner (OBJ's v grows up the image).
fn quad(id: u64, x0: f32, x1: f32, material: u16) -> Vec<ShownTriangle> {
    let (a, b, c, d) = (
        [x0, -0.6, 0.0],
        [x1, -0.6, 0.0],
        [x1, 0.6, 0.0],
        [x0, 0.6, 0.0],
    );
    let uv = |p: [f32; 3]| [(p[0] - x0) / (x1 - x0), (p[1] + 0.6) / 1.2];
    [[a, b, c], [a, c, d]]
        .into_iter()
        .enumerate()
        .map(|(k, positions)| ShownTriangle {
            material,
            texcoords: Texcoords::encode(positions.map(uv), false),
            ..lit_triangle(id + k as u64, positions, [[ILLUMINATION; 3]; 3])
        })
        .collect()
}

/// The pixel seen through world point (x, y) on the z = 0 plane (front camera, at z = 3).
fn pixel_of(x: f32, y: f32) -> (u32, u32) {
    let per_unit = H as f32 / 2.0 / (3.0 * 30f32.to_radians().tan());
    let px = W as f32 / 2.0 + x * per_unit;
    let py = H as f32 / 2.0 - y * per_unit;
    (px as u32, py as u32)
}

fn linear_at(s: &Snapshot, (x, y): (u32, u32)) -> [f32; 3] {
    s.linear[(y * W + x) as usize]
}

fn display_at(s: &Snapshot, (x, y): (u32, u32)) -> [i32; 3] {
    let p = s.display.get_pixel(x, y).0;
    [p[0], p[1], p[2]].map(i32::from)
}

fn assert_near(found: [f32; 3], want: [f32; 3], what: &str) {
    // Relative 1 %: GL draws linear radiance in half floats, and the texels are 8-bit sRGB.
    let ok = found
        .iter()
        .zip(want)
        .all(|(f, w)| (f - w).abs() <= 0.01 * w + 1e-3);
    assert!(ok, "{what}: found {found:?}, expected {want:?}");
}

#[test]
fn textured_and_untextured_materials_draw_in_one_pass_with_their_albedos() {
    let Some(gpu) = headless_or_skip("textured_and_untextured_materials_draw_in_one_pass")
        .expect("a graphics adapter is required")
    else {
        return;
    };
    let mut looks = Looks::of(&info());
    assert!(looks.accept(&TextureImage {
        index: 0,
        png: quadrant_png(),
    }));
    assert!(!looks.accept(&TextureImage {
        index: 1,
        png: b"\x89PNG but not really".to_vec(),
    }));
    let triangles: Vec<ShownTriangle> = [
        quad(10, -2.0, -0.7, 1),
        quad(20, -0.5, 0.5, 0),
        quad(30, 0.7, 2.0, 2),
    ]
    .concat();
    let camera = front_camera(1, W, H);
    let settings = DrawSettings {
        l_white: 4.0,
        ..DrawSettings::default()
    };
    let drawn = render_offscreen_with_looks(
        &gpu,
        &triangles,
        (&looks, &DirectImage::default()),
        &camera,
        &settings,
    )
    .unwrap();

    // The textured quad: each quadrant's colour, the image's top on top.
    let kd = [0.8, 0.7, 0.9];
    let centres = [(-1.675, 0.3), (-1.025, 0.3), (-1.675, -0.3), (-1.025, -0.3)];
    for (quadrant, (x, y)) in QUADRANTS.iter().zip(centres) {
        let texel = quadrant.map(|c| conventions::tone_map::srgb_decode(f32::from(c) / 255.0));
        let want: [f32; 3] = std::array::from_fn(|c| kd[c] * texel[c] * ILLUMINATION);
        assert_near(
            linear_at(&drawn, pixel_of(x, y)),
            want,
            &format!("texel {quadrant:?}"),
        );
    }

    // The untextured quad, against the same quad drawn as before: kd multiplied in by the SMA,
    // no materials (albedo one).
    let premultiplied: Vec<ShownTriangle> = quad(20, -0.5, 0.5, 0)
        .into_iter()
        .map(|t| {
            let radiance = [0.6 * ILLUMINATION, 0.3 * ILLUMINATION, 0.2 * ILLUMINATION];
            lit_triangle(t.id, t.positions, [radiance; 3])
        })
        .collect();
    let before = render_offscreen_with(&gpu, &premultiplied, &camera, &settings).unwrap();
    for (x, y) in [(0.0, 0.0), (-0.3, 0.4), (0.35, -0.45)] {
        let (now, then) = (
            display_at(&drawn, pixel_of(x, y)),
            display_at(&before, pixel_of(x, y)),
        );
        assert!(
            now.iter().zip(then).all(|(a, b)| (a - b).abs() <= 1),
            "untextured at ({x}, {y}): {now:?}, before {then:?}"
        );
    }

    // The texture that did not decode: its material's flat kd.
    let want = kd.map(|c| c * ILLUMINATION);
    for (x, y) in [(1.0, 0.3), (1.7, -0.3)] {
        assert_near(linear_at(&drawn, pixel_of(x, y)), want, "flat kd");
    }
}

/// Five textures and white make six layers, which wgpu's GL backend would take for a cube map
/// (drawing every albedo black): each quad shows its own texture's colour.
#[test]
fn five_textures_each_show_their_colour() {
    let Some(gpu) = headless_or_skip("five_textures_each_show_their_colour")
        .expect("a graphics adapter is required")
    else {
        return;
    };
    let colours: [[u8; 3]; 5] = [
        [200, 30, 30],
        [30, 200, 30],
        [30, 30, 200],
        [200, 200, 30],
        [30, 200, 200],
    ];
    let scene = SceneInfo {
        materials: (0..5)
            .map(|index| MaterialLook {
                kd: [1.0; 3],
                texture: Some(MaterialTexture {
                    index,
                    times_kd: true,
                    clamp: index == 4,
                }),
            })
            .collect(),
        texture_table: (0..5)
            .map(|i| TextureInfo {
                name: format!("{i}.png"),
                width: 2,
                height: 2,
                bytes: 0,
            })
            .collect(),
        ..info()
    };
    let mut looks = Looks::of(&scene);
    for (index, colour) in colours.iter().enumerate() {
        let image = image::RgbImage::from_pixel(2, 2, image::Rgb(*colour));
        let mut png = Vec::new();
        image
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        assert!(looks.accept(&TextureImage {
            index: index as u32,
            png,
        }));
    }
    let triangles: Vec<ShownTriangle> = (0..5)
        .flat_map(|m| {
            let x0 = -2.0 + 0.8 * m as f32;
            quad(10 * m as u64, x0, x0 + 0.6, m as u16)
        })
        .collect();
    let drawn = render_offscreen_with_looks(
        &gpu,
        &triangles,
        (&looks, &DirectImage::default()),
        &front_camera(1, W, H),
        &DrawSettings::default(),
    )
    .unwrap();
    for (m, colour) in colours.iter().enumerate() {
        let x = -2.0 + 0.8 * m as f32 + 0.3;
        let texel = colour.map(|c| conventions::tone_map::srgb_decode(f32::from(c) / 255.0));
        assert_near(
            linear_at(&drawn, pixel_of(x, 0.0)),
            texel.map(|c| c * ILLUMINATION),
            &format!("texture {m}"),
        );
    }
}
