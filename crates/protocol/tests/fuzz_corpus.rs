//! The frame fuzz targets' corpus as a stable test: every seed, crash reproducer and local crash
//! artifact of `fuzz/` goes through the very code the targets run (`fuzz/src/frames.rs`), so a
//! decoder that panics on one fails `cargo test` without a fuzzer. The seeds are valid frames of
//! every message of both links and of the handshake (DESIGN.md §8), and a few malformed ones;
//! `cargo test -p protocol --test fuzz_corpus -- --ignored` writes them again.

#[path = "../../../fuzz/src/corpus.rs"]
mod corpus;
#[path = "../../../fuzz/src/frames.rs"]
mod frames;

use protocol::direct_tile::{
    DirectLights, TileAnswer, TilePixel, TileRect, TileRequest, ViewerTile,
};
use protocol::frame::encode;
use protocol::renderer_link::{
    FromRenderer, Quality, Radiance, SampleKey, ShadeBatch, ShadePoint, ToRenderer,
};
use protocol::texture::{MaterialLook, MaterialTexture, Texcoords, TextureImage, TextureInfo};
use protocol::types::{Bounds, Viewpoint};
use protocol::viewer_link::{
    Camera, CornerShading, DirectShare, Epoch, MeshShape, Recolour, SceneInfo, ShownTriangle,
    SkyInfo, SmaMemory, SmaToViewer, Stats, SunInfo, ViewerToSma,
};
use protocol::{
    Hello, HelloReply, PROTOCOL_VERSION, PartEstimate, Role, SampleParts, SceneIdentity, Side,
};
use serde::Serialize;

const TARGETS: [(&str, corpus::Target); 3] = [
    ("handshake", frames::handshake),
    ("renderer_link", frames::renderer_link),
    ("viewer_link", frames::viewer_link),
];

#[test]
fn the_frame_fuzz_corpus_decodes_without_panicking() {
    corpus::replay_targets(env!("CARGO_MANIFEST_DIR"), &TARGETS, 10);
}

#[test]
#[ignore = "writes fuzz/corpus: run with --ignored after changing a message"]
fn write_seed_corpus() {
    let dir = corpus::fuzz_dir(env!("CARGO_MANIFEST_DIR"));
    corpus::write_seeds(&dir, "handshake", &handshake_seeds());
    corpus::write_seeds(&dir, "renderer_link", &renderer_link_seeds());
    corpus::write_seeds(&dir, "viewer_link", &viewer_link_seeds());
}

/// One frame as on the wire: 4-byte big-endian length, then the payload (DESIGN.md §8).
fn frame<M: Serialize>(message: &M) -> Vec<u8> {
    let payload = encode(message).expect("a seed encodes");
    let mut out = (payload.len() as u32).to_be_bytes().to_vec();
    out.extend(payload);
    out
}

/// The seeds of one direction, named after it: each message alone, all of them as one stream,
/// then malformed ones. A name tells what the target must do with the seed: refuse it when it
/// starts with one of `corpus::REFUSED_PREFIXES`, accept it otherwise.
fn seeds<M: Serialize>(direction: &str, named: &[(&str, M)]) -> Vec<(String, Vec<u8>)> {
    let file = |name: &str| match name.strip_prefix("rejected-") {
        Some(rest) => format!("rejected-{direction}-{rest}.bin"),
        None => format!("{direction}-{name}.bin"),
    };
    let mut out: Vec<(String, Vec<u8>)> = named.iter().map(|(n, m)| (file(n), frame(m))).collect();
    out.push((
        file("all-in-one-stream"),
        out.iter().flat_map(|(_, b)| b.clone()).collect(),
    ));
    let first = out[0].1.clone();
    let mut truncated = first.clone();
    truncated.truncate(first.len() - 1);
    let mut trailing = first.clone();
    trailing.push(0);
    trailing[..4].copy_from_slice(&((first.len() - 3) as u32).to_be_bytes());
    let mut unknown_tag = first.clone();
    unknown_tag[4] = 0x7f;
    let malformed = [
        ("truncated-frame", truncated),
        ("trailing-byte", trailing),
        ("unknown-tag", unknown_tag),
        ("empty-frame", vec![0, 0, 0, 0]),
        ("2gib-length", [0x80, 0, 0, 0, 1, 2, 3].to_vec()),
        ("64mib-plus-one-length", [0x04, 0, 0, 1, 0].to_vec()),
        ("length-prefix-only", [0, 0, 0, 9].to_vec()),
    ];
    out.extend(
        malformed
            .into_iter()
            .map(|(name, b)| (format!("malformed-{direction}-{name}.bin"), b)),
    );
    out
}

fn handshake_seeds() -> Vec<(String, Vec<u8>)> {
    let fp = Some(frames::RENDERER_SCENE);
    let hellos = [
        ("sma", Hello::new(Role::Sma, fp)),
        ("viewer", Hello::new(Role::Viewer, None)),
        ("rejected-renderer", Hello::new(Role::Renderer, fp)),
        (
            "rejected-other-fingerprint",
            Hello::new(
                Role::Sma,
                Some(SceneIdentity {
                    fingerprint: [1; 32],
                    ..frames::RENDERER_SCENE
                }),
            ),
        ),
        (
            "rejected-other-textures",
            Hello::new(
                Role::Sma,
                Some(SceneIdentity {
                    textures: true,
                    ..frames::RENDERER_SCENE
                }),
            ),
        ),
        (
            "rejected-bad-magic",
            Hello {
                magic: *b"HTTP",
                ..Hello::new(Role::Sma, fp)
            },
        ),
        (
            "rejected-next-version",
            Hello {
                version: PROTOCOL_VERSION + 1,
                ..Hello::new(Role::Viewer, None)
            },
        ),
    ];
    let welcome = |role, scene| HelloReply::Welcome {
        role,
        version: PROTOCOL_VERSION,
        scene,
    };
    let replies = [
        ("welcome-renderer", welcome(Role::Renderer, fp)),
        ("welcome-sma", welcome(Role::Sma, None)),
        (
            "rejected-welcome-no-fingerprint",
            welcome(Role::Renderer, None),
        ),
        (
            "rejected-refused",
            HelloReply::Refused {
                reason: "scene fingerprint mismatch".into(),
            },
        ),
    ];
    let mut out = seeds("hello", &hellos);
    out.extend(seeds("reply", &replies));
    // A hello followed by the link's first message, as a real connection starts.
    let mut stream = frame(&Hello::new(Role::Viewer, None));
    stream.extend(frame(&ViewerToSma::Camera(camera())));
    out.push(("hello-then-camera.bin".into(), stream));
    out
}

fn renderer_link_seeds() -> Vec<(String, Vec<u8>)> {
    let point = |vertex, side, eye| ShadePoint {
        key: SampleKey { vertex, side },
        base_triangle: vertex / 3,
        bary: [0.25, 0.5],
        side,
        eye,
    };
    let batch = ShadeBatch {
        batch_id: 42,
        quality: Quality::INTERACTIVE,
        seed: 0x5eed,
        points: vec![
            point(0, Side::Front, None),
            point(7, Side::Back, Some([1.0, 2.0, -3.0])),
            point(u32::MAX, Side::Front, Some([f32::NAN, 0.0, 0.0])),
        ],
    };
    let to_renderer = [
        ("shade-batch", ToRenderer::ShadeBatch(batch.clone())),
        (
            "shade-batch-unbounded-empty",
            ToRenderer::ShadeBatch(ShadeBatch {
                quality: Quality {
                    paths: 1,
                    bounces: None,
                },
                points: Vec::new(),
                ..batch
            }),
        ),
        ("bye", ToRenderer::Bye),
        ("ping", ToRenderer::Ping { nonce: 7 }),
        (
            "direct-tile",
            ToRenderer::DirectTile(TileRequest {
                tile_id: 5,
                camera: camera(),
                rect: tile_rect(),
                samples_per_pixel: 4,
                pass: 2,
                lights: DirectLights::All,
            }),
        ),
    ];
    let from_renderer = [
        (
            "radiance",
            FromRenderer::Radiance(Radiance {
                batch_id: 42,
                quality: Quality::DIRECT,
                parts: vec![
                    SampleParts {
                        direct: PartEstimate {
                            rgb: [0.1, 0.2, 0.3],
                            luminance_variance: 0.01,
                        },
                        indirect: PartEstimate {
                            rgb: [0.05, 0.04, 0.03],
                            luminance_variance: 0.002,
                        },
                        view_dependent: PartEstimate {
                            rgb: [2.0, 1.5, 0.5],
                            luminance_variance: 0.3,
                        },
                    },
                    SampleParts {
                        direct: PartEstimate {
                            rgb: [1e6, 0.0, f32::INFINITY],
                            luminance_variance: f32::NAN,
                        },
                        indirect: PartEstimate {
                            rgb: [-1.0, 0.0, 0.0],
                            luminance_variance: 0.0,
                        },
                        view_dependent: PartEstimate {
                            rgb: [f32::NAN, 0.0, 0.0],
                            luminance_variance: -1.0,
                        },
                    },
                ],
                paths: vec![16, 0],
                flags: vec![0, 1 | 8],
                micros: 1234,
            }),
        ),
        (
            "rejected",
            FromRenderer::Rejected {
                batch_id: 42,
                reason: "base triangle out of range".into(),
            },
        ),
        (
            "error",
            FromRenderer::Error {
                message: "out of memory".into(),
            },
        ),
        ("pong", FromRenderer::Pong { nonce: u64::MAX }),
        (
            "direct-tile",
            FromRenderer::DirectTile(TileAnswer {
                tile_id: 5,
                camera_seq: 3,
                rect: tile_rect(),
                pass: 2,
                samples_per_pixel: 4,
                // One pixel short, and one non-finite: decoded, then refused by its check.
                pixels: [[0.3, 0.2, 0.1], [f32::NAN, 0.0, 1.0]]
                    .into_iter()
                    .cycle()
                    .take(tile_rect().pixels() - 1)
                    .map(|rgb| PartEstimate {
                        rgb,
                        luminance_variance: 0.02,
                    })
                    .collect(),
                micros: 800,
            }),
        ),
        (
            "tile-rejected",
            FromRenderer::TileRejected {
                tile_id: 5,
                reason: "tile outside the image".into(),
            },
        ),
    ];
    let mut out = seeds("to-renderer", &to_renderer);
    out.extend(seeds("from-renderer", &from_renderer));
    out
}

/// A small tile at the edge of `camera()`'s image.
fn tile_rect() -> TileRect {
    TileRect {
        x: 632,
        y: 472,
        width: 8,
        height: 8,
    }
}

fn camera() -> Camera {
    Camera {
        seq: 3,
        eye: [1.0, 1.7, 5.0],
        orientation: [0.0, 0.0, 0.0, 1.0],
        fov_y_deg: 60.0,
        width: 640,
        height: 480,
    }
}

/// A PNG of one 8-bit RGB texel, (180, 120, 60).
fn one_texel_png() -> Vec<u8> {
    vec![
        137, 80, 78, 71, 13, 10, 26, 10, 0, 0, 0, 13, 73, 72, 68, 82, 0, 0, 0, 1, 0, 0, 0, 1, 8, 2,
        0, 0, 0, 144, 119, 83, 222, 0, 0, 0, 12, 73, 68, 65, 84, 120, 156, 99, 216, 82, 97, 3, 0,
        3, 76, 1, 105, 212, 238, 220, 119, 0, 0, 0, 0, 73, 69, 78, 68, 174, 66, 96, 130,
    ]
}

fn viewer_link_seeds() -> Vec<(String, Vec<u8>)> {
    let to_sma = [
        ("camera", ViewerToSma::Camera(camera())),
        (
            "set-criterion",
            ViewerToSma::SetCriterion {
                name: "nld-os".into(),
            },
        ),
        ("pause", ViewerToSma::Pause),
        ("resume", ViewerToSma::Resume),
        ("bye", ViewerToSma::Bye),
        ("pong", ViewerToSma::Pong { nonce: 11 }),
    ];
    let triangle = |id| ShownTriangle {
        id,
        positions: [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        material: 1,
        texcoords: Texcoords::encode([[0.0, 0.0], [2.5, 0.0], [0.0, 1.0]], false),
        shading: CornerShading {
            illumination: [[0.5; 3], [1.0; 3], [0.0; 3]],
            direct_share: [DirectShare(128), DirectShare(255), DirectShare(0)],
            view_dependent: (id == 1).then_some([[0.0; 3], [0.25; 3], [4.0, 0.0, 1.0]]),
        },
    };
    let to_viewer = [
        (
            "scene-info",
            SmaToViewer::SceneInfo(Box::new(SceneInfo {
                name: "cornell".into(),
                fingerprint: [9; 32],
                bounds: Bounds {
                    min: [0.0; 3],
                    max: [0.55, 0.55, 0.56],
                },
                viewpoints: vec![Viewpoint {
                    name: "main".into(),
                    eye: [0.278, 0.273, -0.8],
                    target: [0.278, 0.273, 0.0],
                    up: [0.0, 1.0, 0.0],
                    fov_y_deg: 39.3,
                }],
                criteria: vec!["nld-os".into(), "rnd".into()],
                sky: SkyInfo {
                    radiance: [0.6, 0.7, 1.0],
                    sun: Some(SunInfo {
                        direction: [0.0, 0.6, 0.8],
                        radiance: [1.6e5, 1.5e5, 1.3e5],
                        angular_diameter_deg: 0.53,
                    }),
                },
                quality: Quality {
                    paths: 64,
                    bounces: Some(2),
                },
                textures: true,
                materials: vec![
                    MaterialLook {
                        kd: [0.7, 0.5, 0.3],
                        texture: None,
                    },
                    MaterialLook {
                        kd: [0.8; 3],
                        texture: Some(MaterialTexture {
                            index: 0,
                            times_kd: true,
                            clamp: false,
                        }),
                    },
                ],
                texture_table: vec![TextureInfo {
                    name: "textures/paving.png".into(),
                    width: 1,
                    height: 1,
                    bytes: 70,
                }],
            })),
        ),
        (
            "texture",
            SmaToViewer::Texture(TextureImage {
                index: 0,
                png: one_texel_png(),
            }),
        ),
        (
            "insert",
            SmaToViewer::Insert {
                triangles: vec![triangle(1), triangle(u64::MAX)],
            },
        ),
        (
            "remove",
            SmaToViewer::Remove {
                ids: vec![1, 300, u64::MAX],
            },
        ),
        (
            "update",
            SmaToViewer::Update {
                triangles: vec![Recolour {
                    id: 1,
                    shading: CornerShading {
                        illumination: [[2.0; 3]; 3],
                        direct_share: [DirectShare(7); 3],
                        view_dependent: Some([[0.5; 3]; 3]),
                    },
                }],
            },
        ),
        ("tone-map", SmaToViewer::ToneMap { l_white: 3.5 }),
        (
            "epoch",
            SmaToViewer::Epoch(Epoch {
                camera_seq: 3,
                shown: 2,
                visible_leaves: 5,
                inserted: 2,
                removed: 0,
                samples: 1000,
                paths: 64000,
                outstanding: 7,
            }),
        ),
        (
            "stats",
            SmaToViewer::Stats(Stats {
                samples_per_sec: 5e4,
                paths_per_sec: 3.2e6,
                renderer_busy: 0.9,
                leaves: 100,
                cached_samples: 80,
                renderers: 2,
                converged: true,
                rejected_points: 3,
                memory: SmaMemory {
                    nodes_bytes: 1 << 20,
                    vertices_bytes: 1 << 19,
                    edge_tables_bytes: 1 << 18,
                    cache_bytes: 3 << 20,
                    viewers_bytes: 1 << 21,
                    budget_bytes: 64 << 20,
                    rss_bytes: Some(200 << 20),
                    memory_bound: true,
                },
                mesh: MeshShape {
                    smallest_split_angle_deg: Some(12.5),
                    smallest_split_angle_ratio: Some(0.5),
                    neighbour_bound_hits: 2,
                    uniform_merges: 9,
                },
            }),
        ),
        (
            "refinement",
            SmaToViewer::Refinement {
                criterion: "rnd".into(),
                paused: true,
            },
        ),
        (
            "error",
            SmaToViewer::Error {
                message: "unknown criterion".into(),
            },
        ),
        ("ping", SmaToViewer::Ping { nonce: u64::MAX }),
        (
            "direct-tile",
            SmaToViewer::DirectTile(ViewerTile {
                camera_seq: 3,
                rect: tile_rect(),
                samples: 16,
                pixels: [0.0, 0.5, 1e5, f32::INFINITY]
                    .into_iter()
                    .cycle()
                    .take(tile_rect().pixels())
                    .map(|v| TilePixel::new([v, 0.25, 0.125], 0.01))
                    .collect(),
            }),
        ),
    ];
    let mut out = seeds("to-sma", &to_sma);
    out.extend(seeds("to-viewer", &to_viewer));
    out
}
