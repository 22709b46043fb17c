//! A scripted protocol viewer that checks what the SMA sends: it keeps the viewer's triangle table
//! and fails on a duplicate insert, a remove or update of an unknown id, an `Error`, or an `Epoch`
//! whose `shown` disagrees with the table (DESIGN.md §8). Used by the service tests (in-process
//! and with real processes) and by the service benchmarks.
//!
//! Like a viewer's link, a task of its own reads the connection and answers the SMA's heartbeats
//! at once, so a test may spend long on its own checks between reads without being taken for a
//! hung viewer; [`Probe::stop_answering_pings`] plays one.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};
use glam::Vec3;
use protocol::connection::{TcpReader, TcpWriter, connect_handshake};
use protocol::direct_tile::ViewerTile;
use protocol::frame::DEFAULT_MAX_FRAME;
use protocol::texture::TextureImage;
use protocol::viewer_link::{
    Camera, Epoch, SceneInfo, ShownTriangle, SmaToViewer, Stats, TriangleId, ViewerToSma,
};
use protocol::{Hello, ProtocolError, Rgb, Role, split_tcp};
use tokio::net::TcpStream;
use tokio::sync::{Mutex, mpsc};
use tokio::task::JoinHandle;

pub struct Probe {
    /// What the reading task took off the connection, heartbeats left out; an error ends it.
    incoming: mpsc::UnboundedReceiver<Result<SmaToViewer, ProtocolError>>,
    reading: JoinHandle<()>,
    writer: Arc<Mutex<TcpWriter<ViewerToSma>>>,
    answer_pings: Arc<AtomicBool>,
    pub scene: SceneInfo,
    pub table: HashMap<TriangleId, ShownTriangle>,
    pub l_white: Option<f32>,
    pub epochs: Vec<Epoch>,
    /// `Refinement` replies, in order.
    pub refinement: Vec<(String, bool)>,
    /// The latest `Stats`.
    pub stats: Option<Stats>,
    /// Every `Stats`, in order.
    pub stats_seen: Vec<Stats>,
    /// Every direct-light tile, in order, with the number of epochs seen before it.
    pub tiles: Vec<(usize, ViewerTile)>,
    /// Every texture of `scene.texture_table` received, by index (checked, not decoded).
    pub textures: Vec<Option<TextureImage>>,
    /// Every camera sent, for the tiles' sizes.
    sent: Vec<Camera>,
    next_seq: u64,
}

impl Drop for Probe {
    fn drop(&mut self) {
        self.reading.abort();
    }
}

/// Reads `reader` until it fails: heartbeats are answered through `writer` while `answer` holds,
/// everything else goes to `incoming`.
async fn read_all(
    mut reader: TcpReader<SmaToViewer>,
    writer: Arc<Mutex<TcpWriter<ViewerToSma>>>,
    answer: Arc<AtomicBool>,
    incoming: mpsc::UnboundedSender<Result<SmaToViewer, ProtocolError>>,
) {
    loop {
        let message = match reader.recv().await {
            Ok(SmaToViewer::Ping { nonce }) if answer.load(Ordering::Relaxed) => {
                match writer.lock().await.send(&ViewerToSma::Pong { nonce }).await {
                    Ok(()) => continue,
                    Err(e) => Err(e),
                }
            }
            Ok(SmaToViewer::Ping { .. }) => continue,
            other => other,
        };
        let failed = message.is_err();
        if incoming.send(message).is_err() || failed {
            return;
        }
    }
}

impl Probe {
    /// Connects, shakes hands as a viewer, and reads `SceneInfo`.
    pub async fn connect(addr: &str) -> anyhow::Result<Probe> {
        let stream = TcpStream::connect(addr)
            .await
            .with_context(|| format!("connecting to {addr}"))?;
        let (mut reader, mut writer) = split_tcp(stream, DEFAULT_MAX_FRAME);
        connect_handshake(
            &mut reader,
            &mut writer,
            Hello::new(Role::Viewer, None),
            Role::Sma,
        )
        .await?;
        let scene = match reader.recv().await? {
            SmaToViewer::SceneInfo(info) => *info,
            other => bail!("expected SceneInfo first, got {other:?}"),
        };
        let writer = Arc::new(Mutex::new(writer));
        let answer_pings = Arc::new(AtomicBool::new(true));
        let (incoming_tx, incoming) = mpsc::unbounded_channel();
        let reading = tokio::spawn(read_all(
            reader,
            Arc::clone(&writer),
            Arc::clone(&answer_pings),
            incoming_tx,
        ));
        Ok(Probe {
            incoming,
            reading,
            writer,
            answer_pings,
            table: HashMap::new(),
            l_white: None,
            epochs: Vec::new(),
            refinement: Vec::new(),
            stats: None,
            stats_seen: Vec::new(),
            tiles: Vec::new(),
            textures: vec![None; scene.texture_table.len()],
            scene,
            sent: Vec::new(),
            next_seq: 0,
        })
    }

    /// Per vertex the radiance a viewer shows of `t` with its material's flat `kd` as the albedo
    /// (one for a material the scene does not list): what an untextured surface looks like.
    pub fn radiance(&self, t: &ShownTriangle) -> [Rgb; 3] {
        let kd = self
            .scene
            .materials
            .get(usize::from(t.material))
            .map_or([1.0; 3], |m| m.kd);
        t.shading.radiance([kd; 3])
    }

    pub async fn send(&mut self, message: ViewerToSma) -> anyhow::Result<()> {
        Ok(self.writer.lock().await.send(&message).await?)
    }

    /// From now on heartbeats go unanswered, as from a viewer that hangs; everything is still
    /// read.
    pub fn stop_answering_pings(&self) {
        self.answer_pings.store(false, Ordering::Relaxed);
    }

    /// The next message that is not a heartbeat.
    pub async fn read(&mut self) -> anyhow::Result<SmaToViewer> {
        match self.incoming.recv().await {
            Some(message) => Ok(message?),
            None => Err(ProtocolError::Closed.into()),
        }
    }

    /// Sends a camera for a named viewpoint of the scene; returns its seq.
    pub async fn view(&mut self, name: &str, width: u32, height: u32) -> anyhow::Result<Camera> {
        let vp = self
            .scene
            .viewpoints
            .iter()
            .find(|v| v.name == name)
            .context("no such viewpoint")?;
        let camera = Camera::from_viewpoint(&vp.clone(), self.next_seq + 1, width, height);
        self.camera(camera).await
    }

    /// Sends `camera` with the next seq; returns it as sent.
    pub async fn camera(&mut self, mut camera: Camera) -> anyhow::Result<Camera> {
        self.next_seq += 1;
        camera.seq = self.next_seq;
        self.sent.push(camera.clone());
        self.send(ViewerToSma::Camera(camera.clone())).await?;
        Ok(camera)
    }

    /// Applies messages up to and including the next `Epoch`, checking the table.
    pub async fn next_epoch(&mut self) -> anyhow::Result<Epoch> {
        loop {
            let message = self.read().await?;
            if let Some(epoch) = self.apply(message)? {
                return Ok(epoch);
            }
        }
    }

    /// Reads until a `Stats` read by this call says the SMA has converged, within `timeout`. One
    /// read before it does not count: it may have been sent for the camera before the last one.
    pub async fn until_converged(&mut self, timeout: Duration) -> anyhow::Result<Stats> {
        self.until_stats(timeout, |s| s.converged)
            .await
            .with_context(|| format!("not converged; last {:?}", self.stats))
    }

    /// Reads until a `Stats` satisfies `done`, within `timeout`.
    pub async fn until_stats(
        &mut self,
        timeout: Duration,
        mut done: impl FnMut(&Stats) -> bool,
    ) -> anyhow::Result<Stats> {
        tokio::time::timeout(timeout, async {
            loop {
                let message = self.read().await?;
                if let SmaToViewer::Stats(stats) = &message
                    && done(stats)
                {
                    let stats = *stats;
                    self.apply(message)?;
                    return Ok(stats);
                }
                self.apply(message)?;
            }
        })
        .await
        .with_context(|| {
            format!(
                "no satisfying stats within {timeout:?}; last {:?}",
                self.stats
            )
        })?
    }

    /// Applies one message to the table; the epoch it closes, if it is one.
    fn apply(&mut self, message: SmaToViewer) -> anyhow::Result<Option<Epoch>> {
        match message {
            SmaToViewer::Insert { triangles } => {
                for t in triangles {
                    let look = self.scene.materials.get(usize::from(t.material));
                    let texture = look.and_then(|m| m.texture);
                    if let Some(texture) = texture
                        && self
                            .textures
                            .get(texture.index as usize)
                            .is_none_or(Option::is_none)
                    {
                        bail!(
                            "triangle {} inserted before its texture {}",
                            t.id,
                            texture.index
                        );
                    }
                    if self.table.insert(t.id, t.clone()).is_some() {
                        bail!("duplicate insert of triangle {}", t.id);
                    }
                }
            }
            SmaToViewer::Remove { ids } => {
                for id in ids {
                    if self.table.remove(&id).is_none() {
                        bail!("remove of unknown triangle {id}");
                    }
                }
            }
            SmaToViewer::Update { triangles } => {
                for r in triangles {
                    let t = self
                        .table
                        .get_mut(&r.id)
                        .with_context(|| format!("update of unknown {}", r.id))?;
                    t.shading = r.shading;
                }
            }
            SmaToViewer::ToneMap { l_white } => self.l_white = Some(l_white),
            SmaToViewer::Epoch(epoch) => {
                if epoch.shown != self.table.len() as u64 {
                    bail!(
                        "epoch says {} shown, the table holds {}",
                        epoch.shown,
                        self.table.len()
                    );
                }
                self.epochs.push(epoch);
                return Ok(Some(epoch));
            }
            SmaToViewer::Refinement { criterion, paused } => {
                self.refinement.push((criterion, paused))
            }
            SmaToViewer::Stats(stats) => {
                self.stats = Some(stats);
                self.stats_seen.push(stats);
            }
            // A direct tile changes no triangle: it is kept, checked as a viewer checks it.
            SmaToViewer::DirectTile(tile) => {
                let camera = self.sent.iter().find(|c| c.seq == tile.camera_seq);
                let camera = camera.context("a tile of a camera never sent")?;
                if let Err(reason) = tile.check(camera.width, camera.height) {
                    bail!("a tile its own check refuses: {reason}");
                }
                self.tiles.push((self.epochs.len(), tile));
            }
            SmaToViewer::Texture(image) => {
                if let Err(reason) = image.check(self.textures.len()) {
                    bail!("a texture its own check refuses: {reason}");
                }
                let index = image.index as usize;
                if self.textures[index].replace(image).is_some() {
                    bail!("texture {index} sent twice");
                }
            }
            SmaToViewer::SceneInfo(_) | SmaToViewer::Ping { .. } => {}
            SmaToViewer::Error { message } => bail!("the SMA reported an error: {message}"),
        }
        Ok(None)
    }

    /// Epochs until one satisfies `done`, within `timeout`.
    pub async fn until(
        &mut self,
        timeout: Duration,
        mut done: impl FnMut(&Epoch) -> bool,
    ) -> anyhow::Result<Epoch> {
        tokio::time::timeout(timeout, async {
            loop {
                let epoch = self.next_epoch().await?;
                if done(&epoch) {
                    return Ok(epoch);
                }
            }
        })
        .await
        .with_context(|| {
            format!(
                "no satisfying epoch within {timeout:?}; last {:?}",
                self.epochs.last()
            )
        })?
    }

    /// Messages until the tiles so far satisfy `done`, within `timeout`.
    pub async fn until_tiles(
        &mut self,
        timeout: Duration,
        mut done: impl FnMut(&[(usize, ViewerTile)]) -> bool,
    ) -> anyhow::Result<()> {
        tokio::time::timeout(timeout, async {
            while !done(&self.tiles) {
                let message = self.read().await?;
                self.apply(message)?;
            }
            Ok(())
        })
        .await
        .with_context(|| format!("tiles not as awaited within {timeout:?}"))?
    }

    /// Messages until every texture of the scene's table has arrived, within `timeout`.
    pub async fn until_textures(&mut self, timeout: Duration) -> anyhow::Result<()> {
        tokio::time::timeout(timeout, async {
            while self.textures.iter().any(Option::is_none) {
                let message = self.read().await?;
                self.apply(message)?;
            }
            Ok(())
        })
        .await
        .with_context(|| format!("textures not all sent within {timeout:?}"))?
    }

    /// The first epoch answering camera `seq` with nothing outstanding.
    pub async fn complete(&mut self, seq: u64, timeout: Duration) -> anyhow::Result<Epoch> {
        self.until(timeout, |e| e.camera_seq == seq && e.outstanding == 0)
            .await
    }

    /// The table's triangles.
    pub fn triangles(&self) -> Vec<[Vec3; 3]> {
        self.table
            .values()
            .map(|t| t.positions.map(Vec3::from))
            .collect()
    }

    /// Scene bounds as sent in `SceneInfo`.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        (
            Vec3::from(self.scene.bounds.min),
            Vec3::from(self.scene.bounds.max),
        )
    }

    /// Pairs of shown triangles whose interiors overlap (coplanar and intersecting): a parent
    /// shown with its child, or two sides of one leaf. Shared edges and corners do not count.
    pub fn overlaps(&self) -> Vec<(TriangleId, TriangleId)> {
        self.pairs_where(coplanar_overlap)
    }

    /// Pairs (a, b) of shown coplanar triangles where a corner of `a` lies inside an edge of `b`:
    /// a T-junction, the crack a partial refinement closure would show (DESIGN.md §4). Only
    /// coplanar pairs are judged: a wall standing on a floor may have its foot on a floor edge
    /// without being stitched to it, and no test of positions alone tells that apart from a crack
    /// at a crease.
    pub fn t_junctions(&self) -> Vec<(TriangleId, TriangleId)> {
        self.pairs_where(|a, b| t_junction(a, b) || t_junction(b, a))
    }

    /// Why the table is not a conforming set of leaves (DESIGN.md §4: no overlap and no
    /// T-junction between shown triangles), if it is not.
    pub fn conformity_problem(&self) -> Option<String> {
        let overlaps = self.overlaps();
        let junctions = self.t_junctions();
        (!overlaps.is_empty() || !junctions.is_empty()).then(|| {
            format!(
                "{} overlapping pairs (first {:?}), {} T-junctions (first {:?})",
                overlaps.len(),
                overlaps.first(),
                junctions.len(),
                junctions.first()
            )
        })
    }

    fn pairs_where(
        &self,
        related: impl Fn(&[Vec3; 3], &[Vec3; 3]) -> bool,
    ) -> Vec<(TriangleId, TriangleId)> {
        let tris: Vec<(TriangleId, [Vec3; 3])> = self
            .table
            .values()
            .map(|t| (t.id, t.positions.map(Vec3::from)))
            .collect();
        let mut out = Vec::new();
        for (i, (a_id, a)) in tris.iter().enumerate() {
            for (b_id, b) in &tris[i + 1..] {
                if related(a, b) {
                    out.push((*a_id, *b_id));
                }
            }
        }
        out
    }
}

/// The tolerance of the geometric tests: a small fraction of the triangles' size, so that
/// midpoints rounded to f32 still meet.
fn tolerance(a: &[Vec3; 3], b: &[Vec3; 3]) -> f32 {
    let scale = (a[1] - a[0])
        .length()
        .max((b[1] - b[0]).length())
        .max(1e-12);
    1e-4 * scale
}

/// `b`'s corners lie in `a`'s plane; the plane's unit normal when they do.
fn common_plane(a: &[Vec3; 3], b: &[Vec3; 3]) -> Option<Vec3> {
    let n = (a[1] - a[0]).cross(a[2] - a[0]).try_normalize()?;
    let eps = tolerance(a, b);
    b.iter()
        .all(|p| (p - a[0]).dot(n).abs() <= eps)
        .then_some(n)
}

/// Whether a corner of `a` lies strictly inside an edge of `b`, the two being coplanar.
fn t_junction(a: &[Vec3; 3], b: &[Vec3; 3]) -> bool {
    if common_plane(a, b).is_none() {
        return false;
    }
    let eps = tolerance(a, b);
    a.iter().any(|p| {
        (0..3).any(|k| {
            let (q, r) = (b[k], b[(k + 1) % 3]);
            let edge = r - q;
            let t = (p - q).dot(edge) / edge.length_squared().max(1e-24);
            let inside = t * edge.length() > eps && (1.0 - t) * edge.length() > eps;
            inside && (q + t * edge).distance(*p) <= eps
        })
    })
}

/// Whether two triangles lie in one plane and their interiors meet (separating-axis test in
/// the plane, with a tolerance so that touching edges are not an overlap).
fn coplanar_overlap(a: &[Vec3; 3], b: &[Vec3; 3]) -> bool {
    let Some(n) = common_plane(a, b) else {
        return false;
    };
    let u = (a[1] - a[0]).normalize();
    let v = n.cross(u);
    let flat = |t: &[Vec3; 3]| t.map(|p| glam::Vec2::new((p - a[0]).dot(u), (p - a[0]).dot(v)));
    let (pa, pb) = (flat(a), flat(b));
    let eps = tolerance(a, b);
    for tri in [&pa, &pb] {
        for k in 0..3 {
            let e = tri[(k + 1) % 3] - tri[k];
            let axis = glam::Vec2::new(-e.y, e.x).normalize_or_zero();
            let range = |t: &[glam::Vec2; 3]| {
                t.iter()
                    .map(|p| p.dot(axis))
                    .fold((f32::MAX, f32::MIN), |(lo, hi), x| (lo.min(x), hi.max(x)))
            };
            let ((alo, ahi), (blo, bhi)) = (range(&pa), range(&pb));
            if ahi <= blo + eps || bhi <= alo + eps {
                return false;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(p: [[f32; 3]; 3]) -> [Vec3; 3] {
        p.map(Vec3::from)
    }

    #[test]
    fn overlap_means_shared_interior_in_one_plane() {
        let parent = t([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]]);
        let child = t([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        let neighbour = t([[2.0, 0.0, 0.0], [2.0, 2.0, 0.0], [0.0, 2.0, 0.0]]);
        let corner_only = t([[2.0, 0.0, 0.0], [3.0, 0.0, 0.0], [3.0, 1.0, 0.0]]);
        let lifted = t([[0.0, 0.0, 0.1], [1.0, 0.0, 0.1], [0.0, 1.0, 0.1]]);
        assert!(coplanar_overlap(&parent, &child));
        assert!(coplanar_overlap(&child, &parent));
        assert!(coplanar_overlap(&parent, &parent));
        assert!(
            !coplanar_overlap(&parent, &neighbour),
            "a shared edge is no overlap"
        );
        assert!(!coplanar_overlap(&parent, &corner_only));
        assert!(!coplanar_overlap(&parent, &lifted), "another plane");
    }

    #[test]
    fn a_corner_inside_a_coplanar_edge_is_a_t_junction() {
        // A square's two halves; the lower one bisected at its hypotenuse's midpoint while the
        // upper one is not: the midpoint lies inside the upper half's edge.
        let upper = t([[2.0, 0.0, 0.0], [2.0, 2.0, 0.0], [0.0, 2.0, 0.0]]);
        let lower_a = t([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 1.0, 0.0]]);
        let lower_b = t([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 2.0, 0.0]]);
        let lower = t([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]]);
        assert!(t_junction(&lower_a, &upper));
        assert!(t_junction(&lower_b, &upper));
        assert!(
            !t_junction(&upper, &lower_a),
            "no corner of the upper half is inside"
        );
        assert!(
            !t_junction(&lower, &upper),
            "a shared whole edge is conforming"
        );
        assert!(!t_junction(&upper, &lower));
        // The same corner beside a triangle in another plane (a wall's foot on a floor edge).
        let wall = t([[1.0, 1.0, 0.0], [1.0, 1.0, 1.0], [0.0, 2.0, 1.0]]);
        assert!(!t_junction(&wall, &upper));
    }
}
