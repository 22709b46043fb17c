//! Small scenes built in code for the renderer's tests, and helpers to name points on them.
#![allow(dead_code)] // each test binary uses its own subset

use std::time::Duration;

use glam::Vec3;
use protocol::connection::{TcpReader, TcpWriter, connect_handshake, split_tcp};
use protocol::frame::DEFAULT_MAX_FRAME;
use protocol::renderer_link::{FromRenderer, ShadePoint, ToRenderer};
use protocol::{Hello, MessageReader, MessageWriter, ProtocolError, Role, SceneIdentity, Side};
use renderer::World;
use renderer::estimator::Estimator;
use renderer::point::{front_point_hit_by, surface_of};
use scene::settings::QualitySetting;
use scene::{Material, SceneBuilder, SceneSettings, Sky, Sun};
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::{TcpStream, ToSocketAddrs};

pub fn settings(sun: Option<Sun>, sky: Sky) -> SceneSettings {
    SceneSettings {
        name: "test".into(),
        obj: String::new(),
        units: "m".into(),
        crease_angle_deg: 45.0,
        sun,
        sky,
        quality: QualitySetting {
            paths: 16,
            bounces: Some(2),
        },
        viewpoints: Vec::new(),
        textures: Default::default(),
    }
}

/// A sun toward `dir` with the given radiance and the real sun's 0.53° diameter.
pub fn sun(dir: Vec3, radiance: f32) -> Sun {
    Sun {
        direction: dir.to_array(),
        radiance: [radiance; 3],
        angular_diameter_deg: 0.53,
    }
}

/// A quad whose counter-clockwise side is the side its corners turn around (p, q, r, s).
pub fn quad(b: &mut SceneBuilder, corners: [Vec3; 4], material: u32) {
    let [p, q, r, s] = corners.map(|c| b.vertex(c));
    b.triangle([p, q, r], material);
    b.triangle([p, r, s], material);
}

/// A horizontal square at height `y`, centred on (cx, cz), facing +Y.
pub fn floor(b: &mut SceneBuilder, centre: Vec3, half: f32, material: u32) {
    let c = |dx: f32, dz: f32| centre + Vec3::new(dx, 0.0, dz);
    quad(
        b,
        [
            c(-half, -half),
            c(-half, half),
            c(half, half),
            c(half, -half),
        ],
        material,
    );
}

/// The six faces of an axis-aligned box, facing inward (`inward`) or outward.
pub fn cube(b: &mut SceneBuilder, min: Vec3, max: Vec3, inward: bool, material: u32) {
    let k = |x: bool, y: bool, z: bool| {
        Vec3::new(
            if x { max.x } else { min.x },
            if y { max.y } else { min.y },
            if z { max.z } else { min.z },
        )
    };
    let (f, t) = (false, true);
    // Outward-facing, counter-clockwise seen from outside.
    let faces = [
        [k(f, t, f), k(f, t, t), k(t, t, t), k(t, t, f)],
        [k(f, f, f), k(t, f, f), k(t, f, t), k(f, f, t)],
        [k(f, f, t), k(t, f, t), k(t, t, t), k(f, t, t)],
        [k(t, f, f), k(f, f, f), k(f, t, f), k(t, t, f)],
        [k(t, f, t), k(t, f, f), k(t, t, f), k(t, t, t)],
        [k(f, f, f), k(f, f, t), k(f, t, t), k(f, t, f)],
    ];
    for mut face in faces {
        if inward {
            face.reverse();
        }
        quad(b, face, material);
    }
}

pub fn grey(albedo: f32) -> Material {
    Material::diffuse("grey", Vec3::splat(albedo))
}

pub fn world(b: SceneBuilder) -> World {
    World::new(b.build().expect("test scene builds"))
}

/// Runs `check` on `w` under each estimator: both schedules must pass the same checks (DESIGN.md
/// §7). Says which on stderr, which the harness shows when a check fails.
pub fn with_each_estimator(mut w: World, mut check: impl FnMut(&World)) {
    for estimator in Estimator::ALL {
        w.estimator = estimator;
        eprintln!("estimator: {}", estimator.name());
        check(&w);
    }
}

/// The side of `p` whose normal points toward `facing`.
pub fn with_side_facing(world: &World, mut p: ShadePoint, facing: Vec3) -> ShadePoint {
    p.side = Side::Front;
    let s = surface_of(world, &p).expect("valid point");
    if s.normal.dot(facing) < 0.0 {
        p.side = Side::Back;
        p.key.side = Side::Back;
    }
    p
}

/// The shading point where the ray from `origin` along `dir` first hits, on the side facing the
/// ray's origin.
pub fn point_hit_by(world: &World, origin: Vec3, dir: Vec3) -> ShadePoint {
    let p = front_point_hit_by(world, origin, dir, None).expect("ray hits the scene");
    with_side_facing(world, p, -dir)
}

/// Mean and standard error of per-path samples of one channel.
pub fn mean_and_standard_error(samples: &[f64]) -> (f64, f64) {
    let n = samples.len() as f64;
    let mean = samples.iter().sum::<f64>() / n;
    let var = samples.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// The scene as an SMA that loaded it says it in the handshake.
pub fn identity(scene: &scene::Scene) -> SceneIdentity {
    SceneIdentity {
        fingerprint: scene.fingerprint,
        textures: scene.settings.textures.enabled,
    }
}

/// The SMA's side of the handshake with a renderer serving the scene `ours`.
pub async fn handshake_as_sma<R, W>(
    r: &mut MessageReader<R, FromRenderer>,
    w: &mut MessageWriter<W, ToRenderer>,
    ours: SceneIdentity,
) -> Result<Option<SceneIdentity>, ProtocolError>
where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
{
    connect_handshake(r, w, Hello::new(Role::Sma, Some(ours)), Role::Renderer).await
}

/// A link to the renderer at `addr`, as an SMA of the scene `ours`.
pub async fn connect_as_sma(
    addr: impl ToSocketAddrs,
    ours: SceneIdentity,
) -> Result<(TcpReader<FromRenderer>, TcpWriter<ToRenderer>), ProtocolError> {
    let stream = TcpStream::connect(addr).await?;
    let (mut r, mut w) = split_tcp::<FromRenderer, ToRenderer>(stream, DEFAULT_MAX_FRAME);
    handshake_as_sma(&mut r, &mut w, ours).await?;
    Ok((r, w))
}

/// The renderer's next message, within 30 s.
pub async fn recv(r: &mut TcpReader<FromRenderer>) -> Result<FromRenderer, ProtocolError> {
    tokio::time::timeout(Duration::from_secs(30), r.recv())
        .await
        .expect("reply within 30 s")
}
