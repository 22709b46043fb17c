//! "bracara", the default scene: a small Roman town in the spirit of the thesis's model of
//! Bracara Augusta (thesis §2.4, views of §5.2; DESIGN.md §11). A temple on a podium with columns
//! and a gabled roof, a colonnaded street between houses with tiled roofs, a stretch of city wall
//! with round towers and merlons, and a reflecting pool, under a low sun.
//!
//! As in the thesis's model, ground, walls and roofs are few large triangles that shadows cross
//! (fig. 4.10) while columns and towers are finely tessellated. Units are metres, +Y up; the
//! temple stands at the north (-z) end of the street, the wall across its south (+z) end.
//! Views: MC looks at the wall and through its gate from outside (§5.2.1: many triangles in
//! view), VR down the street toward the temple (§5.2.2: column and roof shadows on the street),
//! VT at the temple front past the pool (§5.2.3: the shadow of its columns and roof).
//!
//! `bracara-textured` is the same town with its textures on (DESIGN.md §5): paving, stone
//! blocks, roof tiles, plaster and water, generated in code (`textures`) and box-projected onto
//! the faces. It is not the default while the viewer shows textures only at the mesh's
//! vertices, through the SMA: a texture sampled there, on triangles metres wide, shows as
//! blotches until the viewer multiplies it in per pixel.

use std::f32::consts::TAU;

use glam::{Vec3, vec3};

use super::shapes::{cuboid, cylinder, gable_roof, polygon, prism, quad};
use super::textures::{Pattern, box_projection};
use crate::builder::SceneBuilder;
use crate::model::Material;
use crate::settings::{
    AlbedoRule, QualitySetting, SceneSettings, Sky, Sun, TextureSettings, ViewpointSetting,
};
use crate::texture::DiffuseMap;

struct Palette {
    ground: u32,
    marble: u32,
    plaster: u32,
    tiles: u32,
    stone: u32,
    water: u32,
}

impl Palette {
    /// The town's materials; with `textured`, each but the marble with its pattern's texture.
    fn new(b: &mut SceneBuilder, textured: bool) -> Palette {
        let mut add = |material: Material, pattern: Option<Pattern>| {
            let diffuse_map = pattern.filter(|_| textured).map(|pattern| {
                let file = format!("{}.png", material.name);
                DiffuseMap::generated(pattern.texture(material.kd), file, AlbedoRule::Texture)
            });
            b.material(Material {
                diffuse_map,
                ..material
            })
        };
        Palette {
            ground: add(
                Material::diffuse("ground", vec3(0.45, 0.42, 0.38)),
                Some(Pattern::Paving),
            ),
            marble: add(Material::diffuse("marble", vec3(0.78, 0.76, 0.72)), None),
            plaster: add(
                Material::diffuse("plaster", vec3(0.72, 0.62, 0.48)),
                Some(Pattern::Plaster),
            ),
            tiles: add(
                Material::diffuse("roof_tiles", vec3(0.55, 0.25, 0.15)),
                Some(Pattern::RoofTiles),
            ),
            stone: add(
                Material::diffuse("wall_stone", vec3(0.52, 0.48, 0.42)),
                Some(Pattern::StoneBlocks),
            ),
            // Still water: a dark bottom seen through a mirror-like surface.
            water: add(
                Material::mirror("pool_water", vec3(0.03, 0.04, 0.05), vec3(0.6, 0.65, 0.7)),
                Some(Pattern::Water),
            ),
        }
    }

    /// The pattern of a material, for its texture coordinates.
    fn pattern(&self, material: u32) -> Option<Pattern> {
        [
            (self.ground, Pattern::Paving),
            (self.plaster, Pattern::Plaster),
            (self.tiles, Pattern::RoofTiles),
            (self.stone, Pattern::StoneBlocks),
            (self.water, Pattern::Water),
        ]
        .into_iter()
        .find_map(|(m, pattern)| (m == material).then_some(pattern))
    }
}

/// A column: a square base, a shaft of `segments` × `rings`, a square capital.
struct ColumnStyle {
    radius: f32,
    shaft: f32,
    segments: u32,
    rings: u32,
}

impl ColumnStyle {
    /// Base and capital height; their width is 2.6 radii.
    fn block(&self) -> f32 {
        0.5 * self.radius
    }

    fn height(&self) -> f32 {
        self.shaft + 2.0 * self.block()
    }

    fn add(&self, b: &mut SceneBuilder, foot: Vec3, material: u32) {
        let half = Vec3::new(1.3 * self.radius, 0.0, 1.3 * self.radius);
        let up = Vec3::Y * self.block();
        cuboid(b, foot - half, foot + half + up, false, material);
        cylinder(
            b,
            foot + up,
            self.radius,
            self.shaft,
            self.segments,
            self.rings,
            material,
        );
        let top = foot + up + Vec3::Y * self.shaft;
        cuboid(b, top - half, top + half + up, true, material);
    }
}

const TEMPLE_COLUMN: ColumnStyle = ColumnStyle {
    radius: 0.6,
    shaft: 7.8,
    segments: 20,
    rings: 8,
};
const STREET_COLUMN: ColumnStyle = ColumnStyle {
    radius: 0.3,
    shaft: 4.2,
    segments: 12,
    rings: 3,
};

/// The town; `textured`: with its textures on (`bracara-textured`).
pub fn bracara(textured: bool) -> SceneBuilder {
    let mut b = SceneBuilder::new(settings(textured));
    let p = Palette::new(&mut b, textured);
    ground(&mut b, &p);
    temple(&mut b, &p);
    pool(&mut b, &p);
    street(&mut b, &p);
    city_wall(&mut b, &p);
    if textured {
        b.project_texcoords(|material, corners| {
            p.pattern(material)
                .map(|pattern| box_projection(corners, pattern.repeat_m()))
        });
    }
    b
}

/// 240 m square of ground in 4 × 4 tiles: large triangles, as in the thesis's model.
fn ground(b: &mut SceneBuilder, p: &Palette) {
    let (size, tiles) = (240.0, 4);
    let step = size / tiles as f32;
    for i in 0..tiles {
        for j in 0..tiles {
            let (x, z) = (-0.5 * size + i as f32 * step, -0.5 * size + j as f32 * step);
            quad(
                b,
                [
                    vec3(x, 0.0, z),
                    vec3(x, 0.0, z + step),
                    vec3(x + step, 0.0, z + step),
                    vec3(x + step, 0.0, z),
                ],
                p.ground,
            );
        }
    }
}

/// A peripteral temple facing south (+z): podium with steps, 6 × 9 columns, cella, entablature,
/// gabled roof.
fn temple(b: &mut SceneBuilder, p: &Palette) {
    let (front, back, podium) = (-34.0, -66.0, 3.0);
    cuboid(
        b,
        vec3(-9.0, 0.0, back),
        vec3(9.0, podium, front),
        false,
        p.marble,
    );
    // Five steps, each a slab of its own run: slabs that overlapped would put coplanar side faces
    // on top of one another, which no depth test can order.
    let run = 0.8;
    for k in 0..5 {
        let outer = front + (5 - k) as f32 * run;
        let height = (k + 1) as f32 * podium / 6.0;
        cuboid(
            b,
            vec3(-6.0, 0.0, outer - run),
            vec3(6.0, height, outer),
            false,
            p.marble,
        );
    }
    let inset = 1.5;
    let (z0, z1) = (front - inset, back + inset);
    let xs = [-7.5, -4.5, -1.5, 1.5, 4.5, 7.5];
    let mut feet: Vec<(f32, f32)> = xs.iter().flat_map(|&x| [(x, z0), (x, z1)]).collect();
    for i in 1..8 {
        let z = z0 + (z1 - z0) * i as f32 / 8.0;
        feet.extend([(xs[0], z), (xs[5], z)]);
    }
    for (x, z) in feet {
        TEMPLE_COLUMN.add(b, vec3(x, podium, z), p.marble);
    }
    let top = podium + TEMPLE_COLUMN.height();
    cuboid(
        b,
        vec3(-5.0, podium, -61.0),
        vec3(5.0, top, -41.0),
        false,
        p.marble,
    );
    cuboid(
        b,
        vec3(-8.5, top, back + 0.5),
        vec3(8.5, top + 1.5, front - 0.5),
        true,
        p.marble,
    );
    gable_roof(
        b,
        vec3(-8.8, top + 1.5, back + 0.2),
        vec3(8.8, top + 1.5, front - 0.2),
        top + 5.0,
        p.tiles,
        p.marble,
    );
}

/// A reflecting pool in the forum before the temple steps: a stone rim around still water.
fn pool(b: &mut SceneBuilder, p: &Palette) {
    let (x, z0, z1, rim, h) = (4.0, -28.0, -14.0, 0.5, 0.5);
    cuboid(
        b,
        vec3(-x - rim, 0.0, z0 - rim),
        vec3(x + rim, h, z0),
        false,
        p.marble,
    );
    cuboid(
        b,
        vec3(-x - rim, 0.0, z1),
        vec3(x + rim, h, z1 + rim),
        false,
        p.marble,
    );
    cuboid(b, vec3(-x - rim, 0.0, z0), vec3(-x, h, z1), false, p.marble);
    cuboid(b, vec3(x, 0.0, z0), vec3(x + rim, h, z1), false, p.marble);
    let w = h - 0.15;
    quad(
        b,
        [
            vec3(-x, w, z0),
            vec3(-x, w, z1),
            vec3(x, w, z1),
            vec3(x, w, z0),
        ],
        p.water,
    );
}

/// The street from the forum to the city gate: a colonnade each side under a lean-to portico
/// roof, and a row of houses behind each colonnade.
fn street(b: &mut SceneBuilder, p: &Palette) {
    let (z0, z1) = (-10.0, 70.0);
    for side in [-1.0f32, 1.0] {
        for i in 0..16 {
            STREET_COLUMN.add(b, vec3(6.0 * side, 0.0, -8.0 + 5.0 * i as f32), p.marble);
        }
        let top = STREET_COLUMN.height();
        let (inner, outer) = (5.5 * side, 6.5 * side);
        cuboid(
            b,
            vec3(inner.min(outer), top, z0),
            vec3(inner.max(outer), top + 0.4, z1),
            true,
            p.marble,
        );
        // The portico roof rises from the colonnade to the houses.
        let (lo, hi) = (
            vec3(inner, top + 0.4, 0.0),
            vec3(9.0 * side, top + 1.2, 0.0),
        );
        let corners = [
            lo + Vec3::Z * z1,
            lo + Vec3::Z * z0,
            hi + Vec3::Z * z0,
            hi + Vec3::Z * z1,
        ];
        // Wound to face up on either side.
        quad(
            b,
            if side < 0.0 {
                corners
            } else {
                [corners[1], corners[0], corners[3], corners[2]]
            },
            p.tiles,
        );
        for i in 0..8 {
            let z = z0 + 10.0 * i as f32;
            let height = if i % 2 == 0 { 6.5 } else { 7.5 };
            let (xa, xb) = (9.0 * side, 19.0 * side);
            let (min, max) = (vec3(xa.min(xb), 0.0, z), vec3(xa.max(xb), height, z + 10.0));
            cuboid(b, min, max, false, p.plaster);
            // A lower house's gables stand against its taller neighbours' end walls: set back a
            // little, they are not coplanar with those walls, which no depth test could order.
            let inset = if height < 7.0 { 0.05 } else { 0.0 };
            let overhang = vec3(0.5, 0.0, -inset);
            gable_roof(
                b,
                min.with_y(height) - overhang,
                max + overhang,
                height + 2.5,
                p.tiles,
                p.plaster,
            );
        }
    }
}

/// The city wall across the south end: a gate with two towers over the street, more towers
/// along it, merlons along its outer edge and on every tower.
fn city_wall(b: &mut SceneBuilder, p: &Palette) {
    let (inner, outer, height, gate) = (78.0, 81.0, 8.0, 5.0);
    for side in [-1.0f32, 1.0] {
        let (xa, xb) = (gate * side, 100.0 * side);
        cuboid(
            b,
            vec3(xa.min(xb), 0.0, inner),
            vec3(xa.max(xb), height, outer),
            false,
            p.stone,
        );
        // (x, radius, height): two gate towers, then two more along the wall.
        let towers = [(9.0f32, 4.0f32, 13.0), (40.0, 4.5, 12.0), (75.0, 4.5, 12.0)];
        for (x, r, h) in towers {
            tower(b, vec3(x * side, 0.0, 0.5 * (inner + outer)), r, h, p.stone);
        }
        // Merlons every 2.5 m, except where a tower stands.
        let free = |x: f32| towers.iter().all(|(tx, r, _)| (x - tx).abs() > r + 0.5);
        for x in (0..40)
            .map(|i| gate + 1.0 + 2.5 * i as f32)
            .filter(|x| free(*x))
        {
            merlon(b, vec3(x * side, height, outer - 0.3), p.stone);
        }
    }
    cuboid(
        b,
        vec3(-gate, 6.0, inner),
        vec3(gate, height, outer),
        true,
        p.stone,
    );
}

/// A round tower, finely tessellated like the columns, with a flat top and 16 merlons around
/// its rim.
fn tower(b: &mut SceneBuilder, centre: Vec3, radius: f32, height: f32, material: u32) {
    let segments = 40;
    cylinder(b, centre, radius, height, segments, 8, material);
    let top = centre.y + height;
    let rim: Vec<Vec3> = (0..segments)
        .map(|i| {
            let a = TAU * i as f32 / segments as f32;
            vec3(
                centre.x + radius * a.cos(),
                top,
                centre.z - radius * a.sin(),
            )
        })
        .collect();
    polygon(b, &rim, material);
    let merlons = 16;
    for i in 0..merlons {
        let (a0, a1) = (
            TAU * i as f32 / merlons as f32,
            TAU * (i as f32 + 0.5) / merlons as f32,
        );
        let at = |r: f32, a: f32| (centre.x + r * a.cos(), centre.z - r * a.sin());
        let inner = radius - 0.6;
        prism(
            b,
            &[at(inner, a0), at(radius, a0), at(radius, a1), at(inner, a1)],
            top,
            top + 1.2,
            material,
        );
    }
}

/// A 1 m wide, 1.2 m high, 0.6 m deep merlon standing on `foot`.
fn merlon(b: &mut SceneBuilder, foot: Vec3, material: u32) {
    let half = vec3(0.5, 0.0, 0.3);
    cuboid(b, foot - half, foot + half + Vec3::Y * 1.2, false, material);
}

fn settings(textured: bool) -> SceneSettings {
    let viewpoint = |name: &str, eye: [f32; 3], target: [f32; 3]| ViewpointSetting {
        name: name.into(),
        eye,
        target,
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 60.0,
    };
    SceneSettings {
        name: if textured {
            "bracara-textured"
        } else {
            "bracara"
        }
        .into(),
        obj: String::new(),
        units: "m".into(),
        crease_angle_deg: 45.0,
        // Low (about 20°) from the south-west: column shadows cross the street, the temple front
        // is lit and its roof throws a long shadow.
        sun: Some(Sun {
            direction: [-0.85, 0.35, 0.4],
            radiance: [5.0e4, 4.6e4, 3.8e4],
            angular_diameter_deg: 0.53,
        }),
        sky: Sky::Uniform {
            radiance: [0.10, 0.13, 0.20],
        },
        quality: QualitySetting::default(),
        viewpoints: vec![
            viewpoint("MC", [2.0, 1.7, 110.0], [0.0, 6.0, 80.0]),
            viewpoint("VR", [-1.5, 1.7, 60.0], [0.5, 3.0, -20.0]),
            viewpoint("VT", [-9.0, 1.7, -11.0], [0.0, 6.0, -40.0]),
        ],
        // The texels are the materials' colours times a pattern (`textures`): taken alone.
        textures: TextureSettings {
            enabled: textured,
            albedo: if textured {
                AlbedoRule::Texture
            } else {
                AlbedoRule::default()
            },
        },
    }
}
