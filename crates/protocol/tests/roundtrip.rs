//! Every message survives encode + decode unchanged (property tests over random contents).

use proptest::prelude::*;
use protocol::direct_tile::*;
use protocol::frame::{decode, encode};
use protocol::handshake::{Hello, HelloReply, Role};
use protocol::renderer_link::*;
use protocol::texture::*;
use protocol::types::{Bounds, PartEstimate, SampleParts, SceneIdentity, Side, Viewpoint};
use protocol::viewer_link::*;

fn finite() -> impl Strategy<Value = f32> {
    -1e6f32..1e6f32
}
fn v3() -> impl Strategy<Value = [f32; 3]> {
    [finite(), finite(), finite()]
}

fn sky() -> impl Strategy<Value = SkyInfo> {
    let sun =
        (v3(), v3(), finite()).prop_map(|(direction, radiance, angular_diameter_deg)| SunInfo {
            direction,
            radiance,
            angular_diameter_deg,
        });
    (v3(), prop::option::of(sun)).prop_map(|(radiance, sun)| SkyInfo { radiance, sun })
}
fn side() -> impl Strategy<Value = Side> {
    prop_oneof![Just(Side::Front), Just(Side::Back)]
}
fn role() -> impl Strategy<Value = Role> {
    prop_oneof![Just(Role::Renderer), Just(Role::Sma), Just(Role::Viewer)]
}
fn quality() -> impl Strategy<Value = Quality> {
    (1u32..5000, proptest::option::of(0u32..16))
        .prop_map(|(paths, bounces)| Quality { paths, bounces })
}
fn point() -> impl Strategy<Value = ShadePoint> {
    (
        any::<u32>(),
        side(),
        any::<u32>(),
        [0f32..1.0, 0f32..1.0],
        side(),
        proptest::option::of(v3()),
    )
        .prop_map(
            |(vertex, kside, base_triangle, bary, side, eye)| ShadePoint {
                key: SampleKey {
                    vertex,
                    side: kside,
                },
                base_triangle,
                bary,
                side,
                eye,
            },
        )
}
fn shading() -> impl Strategy<Value = CornerShading> {
    (
        [v3(), v3(), v3()],
        any::<[u8; 3]>(),
        prop::option::of([v3(), v3(), v3()]),
    )
        .prop_map(|(illumination, share, view_dependent)| CornerShading {
            illumination,
            direct_share: share.map(DirectShare),
            view_dependent,
        })
}
fn shown() -> impl Strategy<Value = ShownTriangle> {
    (
        any::<u64>(),
        [v3(), v3(), v3()],
        any::<u16>(),
        any::<[u8; 13]>(),
        shading(),
    )
        .prop_map(
            |(id, positions, material, texcoords, shading)| ShownTriangle {
                id,
                positions,
                material,
                texcoords: Texcoords(texcoords),
                shading,
            },
        )
}
fn material() -> impl Strategy<Value = MaterialLook> {
    let texture =
        (any::<u32>(), any::<bool>(), any::<bool>()).prop_map(|(index, times_kd, clamp)| {
            MaterialTexture {
                index,
                times_kd,
                clamp,
            }
        });
    (v3(), prop::option::of(texture)).prop_map(|(kd, texture)| MaterialLook { kd, texture })
}
fn texture_info() -> impl Strategy<Value = TextureInfo> {
    ("[a-z./]{0,12}", any::<u32>(), any::<u32>(), any::<u64>()).prop_map(
        |(name, width, height, bytes)| TextureInfo {
            name,
            width,
            height,
            bytes,
        },
    )
}
fn viewpoint() -> impl Strategy<Value = Viewpoint> {
    ("[A-Za-z0-9]{0,8}", v3(), v3(), v3(), 1f32..170.0).prop_map(
        |(name, eye, target, up, fov_y_deg)| Viewpoint {
            name,
            eye,
            target,
            up,
            fov_y_deg,
        },
    )
}

fn rect() -> impl Strategy<Value = TileRect> {
    any::<[u32; 4]>().prop_map(|[x, y, width, height]| TileRect {
        x,
        y,
        width,
        height,
    })
}
fn lights() -> impl Strategy<Value = DirectLights> {
    prop::sample::select(DirectLights::ALL.to_vec())
}
fn camera() -> impl Strategy<Value = Camera> {
    (
        any::<u64>(),
        v3(),
        [finite(), finite(), finite(), finite()],
        1f32..170.0,
        any::<u32>(),
        any::<u32>(),
    )
        .prop_map(|(seq, eye, orientation, fov_y_deg, width, height)| Camera {
            seq,
            eye,
            orientation,
            fov_y_deg,
            width,
            height,
        })
}
fn to_renderer() -> impl Strategy<Value = ToRenderer> {
    prop_oneof![
        (
            any::<u64>(),
            quality(),
            any::<u64>(),
            prop::collection::vec(point(), 0..50)
        )
            .prop_map(|(batch_id, quality, seed, points)| ToRenderer::ShadeBatch(
                ShadeBatch {
                    batch_id,
                    quality,
                    seed,
                    points
                }
            )),
        Just(ToRenderer::Bye),
        any::<u64>().prop_map(|nonce| ToRenderer::Ping { nonce }),
        (any::<u64>(), camera(), rect(), any::<[u32; 2]>(), lights()).prop_map(
            |(tile_id, camera, rect, [samples_per_pixel, pass], lights)| {
                ToRenderer::DirectTile(TileRequest {
                    tile_id,
                    camera,
                    rect,
                    samples_per_pixel,
                    pass,
                    lights,
                })
            }
        ),
    ]
}
fn from_renderer() -> impl Strategy<Value = FromRenderer> {
    prop_oneof![
        (
            any::<u64>(),
            quality(),
            prop::collection::vec(
                (
                    v3(),
                    any::<u8>(),
                    0.0f32..1e6,
                    any::<u32>(),
                    v3(),
                    0.0f32..1e6,
                    v3(),
                    0.0f32..1e6
                ),
                0..50
            ),
            any::<u64>()
        )
            .prop_map(|(batch_id, quality, vals, micros)| FromRenderer::Radiance(
                Radiance {
                    batch_id,
                    quality,
                    parts: vals
                        .iter()
                        .map(|v| SampleParts {
                            direct: PartEstimate {
                                rgb: v.0,
                                luminance_variance: v.2,
                            },
                            indirect: PartEstimate {
                                rgb: v.4,
                                luminance_variance: v.5,
                            },
                            view_dependent: PartEstimate {
                                rgb: v.6,
                                luminance_variance: v.7,
                            },
                        })
                        .collect(),
                    paths: vals.iter().map(|v| v.3).collect(),
                    flags: vals.iter().map(|v| v.1).collect(),
                    micros,
                }
            )),
        (any::<u64>(), ".*")
            .prop_map(|(batch_id, reason)| FromRenderer::Rejected { batch_id, reason }),
        ".*".prop_map(|message| FromRenderer::Error { message }),
        any::<u64>().prop_map(|nonce| FromRenderer::Pong { nonce }),
        (
            any::<[u64; 3]>(),
            rect(),
            any::<[u32; 2]>(),
            prop::collection::vec((v3(), finite()), 0..64)
        )
            .prop_map(
                |([tile_id, camera_seq, micros], rect, [pass, samples_per_pixel], px)| {
                    FromRenderer::DirectTile(TileAnswer {
                        tile_id,
                        camera_seq,
                        rect,
                        pass,
                        samples_per_pixel,
                        pixels: px
                            .into_iter()
                            .map(|(rgb, luminance_variance)| PartEstimate {
                                rgb,
                                luminance_variance,
                            })
                            .collect(),
                        micros,
                    })
                }
            ),
        (any::<u64>(), ".*")
            .prop_map(|(tile_id, reason)| FromRenderer::TileRejected { tile_id, reason }),
    ]
}
fn to_sma() -> impl Strategy<Value = ViewerToSma> {
    prop_oneof![
        camera().prop_map(ViewerToSma::Camera),
        ".*".prop_map(|name| ViewerToSma::SetCriterion { name }),
        Just(ViewerToSma::Pause),
        Just(ViewerToSma::Resume),
        Just(ViewerToSma::Bye),
        any::<u64>().prop_map(|nonce| ViewerToSma::Pong { nonce }),
    ]
}
fn to_viewer() -> impl Strategy<Value = SmaToViewer> {
    prop_oneof![
        (
            "[a-z]{0,10}",
            any::<[u8; 32]>(),
            v3(),
            v3(),
            prop::collection::vec(viewpoint(), 0..4),
            prop::collection::vec("[a-z-]{1,8}", 0..4),
            sky(),
            (1u32..1024, prop::option::of(0u32..8), any::<bool>()),
            prop::collection::vec(material(), 0..4),
            prop::collection::vec(texture_info(), 0..3),
        )
            .prop_map(
                |(
                    name,
                    fingerprint,
                    min,
                    max,
                    viewpoints,
                    criteria,
                    sky,
                    (paths, bounces, textures),
                    materials,
                    texture_table,
                )| {
                    SmaToViewer::SceneInfo(Box::new(SceneInfo {
                        name,
                        fingerprint,
                        bounds: Bounds { min, max },
                        viewpoints,
                        criteria,
                        sky,
                        quality: Quality { paths, bounces },
                        textures,
                        materials,
                        texture_table,
                    }))
                }
            ),
        (any::<u32>(), prop::collection::vec(any::<u8>(), 0..64))
            .prop_map(|(index, png)| SmaToViewer::Texture(TextureImage { index, png })),
        prop::collection::vec(shown(), 0..40)
            .prop_map(|triangles| SmaToViewer::Insert { triangles }),
        prop::collection::vec(any::<u64>(), 0..100).prop_map(|ids| SmaToViewer::Remove { ids }),
        prop::collection::vec((any::<u64>(), shading()), 0..40).prop_map(|v| {
            SmaToViewer::Update {
                triangles: v
                    .into_iter()
                    .map(|(id, shading)| Recolour { id, shading })
                    .collect(),
            }
        }),
        finite().prop_map(|l_white| SmaToViewer::ToneMap { l_white }),
        any::<[u64; 8]>().prop_map(|c| SmaToViewer::Epoch(Epoch {
            camera_seq: c[0],
            shown: c[1],
            visible_leaves: c[2],
            inserted: c[3],
            removed: c[4],
            samples: c[5],
            paths: c[6],
            outstanding: c[7],
        })),
        (finite(), any::<u64>(), any::<u64>(), any::<u32>()).prop_map(
            |(samples_per_sec, leaves, cached_samples, renderers)| {
                SmaToViewer::Stats(Stats {
                    samples_per_sec,
                    paths_per_sec: samples_per_sec * 64.0,
                    renderer_busy: (leaves % 101) as f32 / 100.0,
                    leaves,
                    cached_samples,
                    renderers,
                    converged: leaves % 2 == 0,
                    rejected_points: cached_samples / 3,
                    memory: SmaMemory {
                        nodes_bytes: leaves.wrapping_mul(100),
                        vertices_bytes: leaves / 2,
                        edge_tables_bytes: leaves / 3,
                        cache_bytes: cached_samples,
                        viewers_bytes: cached_samples / 2,
                        budget_bytes: leaves ^ cached_samples,
                        rss_bytes: (leaves % 2 == 1).then_some(cached_samples),
                        memory_bound: leaves % 5 == 0,
                    },
                    mesh: MeshShape {
                        smallest_split_angle_deg: (leaves % 3 > 0).then_some(samples_per_sec),
                        smallest_split_angle_ratio: None,
                        neighbour_bound_hits: leaves / 7,
                        uniform_merges: cached_samples / 5,
                    },
                })
            }
        ),
        ("[a-z-]{0,8}", any::<bool>())
            .prop_map(|(criterion, paused)| SmaToViewer::Refinement { criterion, paused }),
        ".*".prop_map(|message| SmaToViewer::Error { message }),
        any::<u64>().prop_map(|nonce| SmaToViewer::Ping { nonce }),
        (
            any::<u64>(),
            rect(),
            any::<u32>(),
            prop::collection::vec(any::<[u16; 4]>(), 0..64)
        )
            .prop_map(|(camera_seq, rect, samples, px)| {
                SmaToViewer::DirectTile(ViewerTile {
                    camera_seq,
                    rect,
                    samples,
                    pixels: px
                        .into_iter()
                        .map(|[r, g, b, e]| TilePixel {
                            rgb: [r, g, b].map(|h| Half(h.to_le_bytes())),
                            standard_error: Half(e.to_le_bytes()),
                        })
                        .collect(),
                })
            }),
    ]
}

fn round_trip<M>(msg: &M) -> M
where
    M: serde::Serialize + serde::de::DeserializeOwned,
{
    decode(&encode(msg).expect("encode")).expect("decode")
}

proptest! {
    #[test]
    fn renderer_requests(msg in to_renderer()) { prop_assert_eq!(round_trip(&msg), msg); }
    #[test]
    fn renderer_replies(msg in from_renderer()) { prop_assert_eq!(round_trip(&msg), msg); }
    #[test]
    fn viewer_requests(msg in to_sma()) { prop_assert_eq!(round_trip(&msg), msg); }
    #[test]
    fn viewer_updates(msg in to_viewer()) { prop_assert_eq!(round_trip(&msg), msg); }
    #[test]
    fn hellos(r in role(), scene in proptest::option::of((any::<[u8; 32]>(), any::<bool>()))) {
        let scene = scene.map(|(fingerprint, textures)| SceneIdentity { fingerprint, textures });
        let hello = Hello::new(r, scene);
        prop_assert_eq!(round_trip(&hello), hello);
        let welcome = HelloReply::Welcome { role: r, version: 3, scene };
        prop_assert_eq!(round_trip(&welcome), welcome);
    }
}

/// Bulk data stays compact: a shown diffuse triangle is its id varint, 18 little-endian floats,
/// a byte of direct share per vertex, a material varint, 13 bytes of texture coordinates with
/// their length and one byte saying it has no view-dependent part.
#[test]
fn triangles_encode_compactly() {
    let triangles: Vec<ShownTriangle> = (0..1000)
        .map(|i| ShownTriangle {
            id: i,
            positions: [[1.0; 3]; 3],
            material: 3,
            texcoords: Texcoords::encode([[0.1, 0.2], [0.3, 0.2], [0.1, 0.4]], false),
            shading: CornerShading {
                illumination: [[0.5; 3]; 3],
                direct_share: [DirectShare(100); 3],
                view_dependent: None,
            },
        })
        .collect();
    let bytes = encode(&SmaToViewer::Insert { triangles }).unwrap();
    let per_triangle = bytes.len() as f64 / 1000.0;
    assert!(
        per_triangle <= 18.0 * 4.0 + 3.0 + 3.0 + 1.0 + 14.0 + 1.0,
        "{per_triangle} bytes per triangle"
    );
}

/// A viewer tile is 8 bytes a pixel (three halves of RGB, one of standard error, two bytes
/// each) plus a few for its header.
#[test]
fn viewer_tiles_encode_compactly() {
    let rect = TileRect {
        x: 0,
        y: 0,
        width: TILE_SIDE,
        height: TILE_SIDE,
    };
    let tile = ViewerTile {
        camera_seq: 9,
        rect,
        samples: 64,
        pixels: vec![TilePixel::new([0.5, 0.25, 3.0], 0.01); rect.pixels()],
    };
    let bytes = encode(&SmaToViewer::DirectTile(tile.clone())).unwrap();
    let per_pixel = bytes.len() as f64 / rect.pixels() as f64;
    assert!(per_pixel <= 8.0 + 0.02, "{per_pixel} bytes per pixel");
    let back: SmaToViewer = decode(&bytes).unwrap();
    let SmaToViewer::DirectTile(back) = back else {
        panic!("a tile decodes as a tile")
    };
    back.check(TILE_SIDE, TILE_SIDE).expect("a valid tile");
    assert_eq!(back, tile);
}
