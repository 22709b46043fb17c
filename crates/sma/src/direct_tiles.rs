//! One viewer's per-pixel direct light while its camera rests (DESIGN.md §3 step 8, §5 "samples
//! in parts"): its image cut into tiles (`TileRect::cover`), each asked for a few samples per
//! pixel a pass, one pass at a time, and every pass's answer merged into the tile's per-pixel
//! estimate by sample counts (Chan et al.'s pairwise update, as a vertex's paths merge). Each
//! merged tile goes to the viewer as a [`ViewerTile`]: per pixel the mean RGB and the standard
//! error of the mean's luminance, `sqrt(s² / n)` with `n` the samples and `s²` the largest
//! luminance variance of the samples of the pixel and its eight neighbours ([`pooled_variances`]).
//! A new camera drops everything of the old one.

use std::sync::atomic::{AtomicU64, Ordering};

use protocol::direct_tile::{
    DirectLights, TileAnswer, TilePixel, TileRect, TileRequest, ViewerTile,
};
use protocol::types::PartEstimate;
use protocol::viewer_link::Camera;

use crate::sample::{DisplayMap, combine_part};

/// Samples per pixel in one pass: an answer comes back within a fraction of a second.
pub const SAMPLES_PER_PASS: u32 = 4;
/// A tile gets no more passes past this many samples per pixel (the renderer's limit per pass
/// is the same figure: `renderer::service::MAX_TILE_SAMPLES`).
pub const MAX_SAMPLES: u32 = 1024;

/// Tile ids are unique across the SMA's viewers, so an answer finds its tile alone.
static NEXT_TILE_ID: AtomicU64 = AtomicU64::new(1);

/// When a tile has samples enough: the display it is seen through and the error it may show.
#[derive(Clone, Copy, Debug)]
pub struct TileTarget {
    /// The viewer's last tone map (None until it has one: no tile is done before).
    pub l_white: Option<f32>,
    /// `ScheduleConfig::display_error`, in displayed units.
    pub display_error: f32,
}

/// One tile's accumulation.
struct Tile {
    rect: TileRect,
    /// Samples per pixel merged so far.
    samples: u32,
    passes: u32,
    /// The id of its pass a renderer holds or the pool queues.
    asked: Option<u64>,
    pixels: Vec<PartEstimate>,
}

impl Tile {
    /// At the cap of samples, or every pixel's displayed standard error below the display
    /// error: the standard error of the mean's luminance, `sqrt(s² / n)`, carried through the
    /// display mapping at the pixel's mean (Drago with the viewer's L_white, then sRGB: its
    /// slope there), as a vertex's sample is judged (`Estimate::displayed`).
    fn done(&self, target: TileTarget) -> bool {
        if self.samples >= MAX_SAMPLES {
            return true;
        }
        let Some(l_white) = target.l_white.filter(|_| self.samples > 0) else {
            return false;
        };
        let map = DisplayMap::new(l_white);
        let n = self.samples as f32;
        let variances = pooled_variances(&self.pixels, self.rect);
        self.pixels.iter().zip(variances).all(|(p, variance)| {
            let (_, slope) = map.display_and_slope(conventions::luminance(p.rgb));
            slope * (variance / n).sqrt() < target.display_error
        })
    }
}

/// Per pixel of a tile, the largest luminance variance of its samples and of its eight
/// neighbours' (within the tile). A variance estimated from a few samples per pixel is itself
/// noisy: four samples of a half-occluded sky or a penumbra all agree often enough that a pixel
/// would claim no error at all, and the viewer would show its grain as exact (`draw.wgsl`,
/// `tile_weight`). A pixel's estimator varies about as its neighbours' do, so their largest
/// variance bounds it from 9 × n samples instead of n; where the whole neighbourhood is in full
/// sun or full shadow it is still zero.
fn pooled_variances(pixels: &[PartEstimate], rect: TileRect) -> Vec<f32> {
    let (width, height) = (rect.width as usize, rect.height as usize);
    let own = |x: usize, y: usize| pixels[y * width + x].luminance_variance;
    (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let xs = x.saturating_sub(1)..=(x + 1).min(width - 1);
            let ys = y.saturating_sub(1)..=(y + 1).min(height - 1);
            ys.flat_map(|ny| xs.clone().map(move |nx| own(nx, ny)))
                .fold(0.0, f32::max)
        })
        .collect()
}

/// One viewer's tiles, of its current camera only.
#[derive(Default)]
pub struct DirectTiles {
    camera: Option<Camera>,
    tiles: Vec<Tile>,
    /// Passes of an old camera still asked for, for the pool to withdraw.
    withdrawn: Vec<u64>,
}

impl DirectTiles {
    /// The camera moved: everything of the old camera is dropped; the passes still asked for
    /// wait in [`DirectTiles::take_withdrawn`].
    pub fn camera_moved(&mut self) {
        let asked = self.tiles.iter().filter_map(|t| t.asked);
        self.withdrawn.extend(asked);
        self.camera = None;
        self.tiles.clear();
    }

    /// Heap bytes by capacity: the tiles and their pixels (part of the viewer's share of the
    /// memory budget, `schedule::memory`).
    pub fn heap_bytes(&self) -> usize {
        self.tiles.capacity() * size_of::<Tile>()
            + self
                .tiles
                .iter()
                .map(|t| t.pixels.capacity() * size_of::<PartEstimate>())
                .sum::<usize>()
            + self.withdrawn.capacity() * size_of::<u64>()
    }

    /// What the tiles of `camera` take once cut ([`Self::heap_bytes`] of its first request).
    pub fn bytes_for(camera: &Camera) -> usize {
        let rects = TileRect::cover(camera.width, camera.height).len();
        rects * size_of::<Tile>()
            + (camera.width as usize * camera.height as usize) * size_of::<PartEstimate>()
    }

    /// Whether `camera` is the one these tiles are of (or were declined for).
    pub fn holds(&self, camera: &Camera) -> bool {
        self.camera.as_ref().is_some_and(|c| c.seq == camera.seq)
    }

    /// No tiles for `camera` (the memory budget has no room for them): it gets no request,
    /// and its stated end does not wait for any.
    pub fn decline(&mut self, camera: &Camera) {
        self.camera_moved();
        self.camera = Some(camera.clone());
        self.tiles = Vec::new();
    }

    /// The passes of old cameras still asked for.
    pub fn take_withdrawn(&mut self) -> Vec<u64> {
        std::mem::take(&mut self.withdrawn)
    }

    /// The next pass of every tile of `camera` (which rests) that has none asked for and is
    /// not done (`Tile::done`); the first call for a camera cuts its image into tiles.
    pub fn requests(
        &mut self,
        camera: &Camera,
        lights: DirectLights,
        target: TileTarget,
    ) -> Vec<TileRequest> {
        if !self.holds(camera) {
            self.camera_moved();
            self.camera = Some(camera.clone());
            self.tiles = TileRect::cover(camera.width, camera.height)
                .into_iter()
                .map(|rect| Tile {
                    rect,
                    samples: 0,
                    passes: 0,
                    asked: None,
                    pixels: vec![PartEstimate::default(); rect.pixels()],
                })
                .collect();
        }
        let mut out = Vec::new();
        for tile in &mut self.tiles {
            if tile.asked.is_some() || tile.done(target) {
                continue;
            }
            let tile_id = NEXT_TILE_ID.fetch_add(1, Ordering::Relaxed);
            tile.asked = Some(tile_id);
            out.push(TileRequest {
                tile_id,
                camera: camera.clone(),
                rect: tile.rect,
                samples_per_pixel: SAMPLES_PER_PASS.min(MAX_SAMPLES - tile.samples),
                pass: tile.passes,
                lights,
            });
        }
        out
    }

    /// Part of the stated end (DESIGN.md §5): every tile of the camera is done, none asked for.
    pub fn converged(&self, target: TileTarget) -> bool {
        self.camera.is_some() && (self.tiles.iter()).all(|t| t.asked.is_none() && t.done(target))
    }

    /// Whether the pass `tile_id` is one of this viewer's.
    pub fn asked(&self, tile_id: u64) -> bool {
        self.tiles.iter().any(|t| t.asked == Some(tile_id))
    }

    /// A pass not answered: asked again at the next turn.
    pub fn dropped(&mut self, tile_id: u64) {
        if let Some(tile) = self.tiles.iter_mut().find(|t| t.asked == Some(tile_id)) {
            tile.asked = None;
        }
    }

    /// Merges an answer (checked by the pool against its camera's image) into its tile and
    /// returns the tile for the viewer. An answer of another camera, or of another rectangle
    /// than its tile's, is refused with its reason.
    pub fn answered(&mut self, answer: &TileAnswer) -> Result<ViewerTile, String> {
        let seq = self.camera.as_ref().map(|c| c.seq);
        if seq != Some(answer.camera_seq) {
            return Err(format!(
                "a tile of camera {} while the viewer's camera is {seq:?}",
                answer.camera_seq
            ));
        }
        let Some(tile) = (self.tiles.iter_mut()).find(|t| t.asked == Some(answer.tile_id)) else {
            return Err(format!("tile {} was not asked for", answer.tile_id));
        };
        tile.asked = None;
        if tile.rect != answer.rect || tile.pixels.len() != answer.pixels.len() {
            return Err(format!(
                "tile {:?} answered as {:?}",
                tile.rect, answer.rect
            ));
        }
        let (na, nb) = (f64::from(tile.samples), f64::from(answer.samples_per_pixel));
        for (pixel, pass) in tile.pixels.iter_mut().zip(&answer.pixels) {
            *pixel = combine_part(pixel, na, pass, nb);
        }
        tile.samples += answer.samples_per_pixel;
        tile.passes += 1;
        let n = tile.samples as f32;
        let variances = pooled_variances(&tile.pixels, tile.rect);
        Ok(ViewerTile {
            camera_seq: answer.camera_seq,
            rect: tile.rect,
            samples: tile.samples,
            pixels: (tile.pixels.iter().zip(variances))
                .map(|(p, variance)| TilePixel::new(p.rgb, (variance / n).sqrt()))
                .collect(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(seq: u64) -> Camera {
        Camera {
            seq,
            eye: [0.0; 3],
            orientation: [0.0, 0.0, 0.0, 1.0],
            fov_y_deg: 60.0,
            width: 40,
            height: 20,
        }
    }

    const TARGET: TileTarget = TileTarget {
        l_white: Some(100.0),
        display_error: 1.0 / 255.0,
    };

    fn answer(request: &TileRequest, value: f32) -> TileAnswer {
        TileAnswer {
            tile_id: request.tile_id,
            camera_seq: request.camera.seq,
            rect: request.rect,
            pass: request.pass,
            samples_per_pixel: request.samples_per_pixel,
            pixels: vec![
                PartEstimate {
                    rgb: [value; 3],
                    luminance_variance: 1.0,
                };
                request.rect.pixels()
            ],
            micros: 1,
        }
    }

    #[test]
    fn passes_merge_by_sample_count_and_the_error_falls() {
        let mut tiles = DirectTiles::default();
        let first = tiles.requests(&camera(1), DirectLights::All, TARGET);
        assert_eq!(first.len(), 2, "a 40×20 image is two tiles of 32");
        assert!(
            tiles
                .requests(&camera(1), DirectLights::All, TARGET)
                .is_empty()
        );
        let one = tiles.answered(&answer(&first[0], 1.0)).unwrap();
        let next = tiles.requests(&camera(1), DirectLights::All, TARGET);
        assert_eq!(next.len(), 1, "only the answered tile gets its next pass");
        assert_eq!(next[0].pass, 1);
        let two = tiles.answered(&answer(&next[0], 1.5)).unwrap();
        assert_eq!(two.samples, 2 * SAMPLES_PER_PASS);
        assert_eq!(
            two.pixels[0].rgb[0].decode(),
            1.25,
            "equal counts: the mean"
        );
        assert!(two.pixels[0].standard_error.decode() < one.pixels[0].standard_error.decode());
        assert!(
            !tiles.converged(TARGET),
            "one tile still asked for, both noisy"
        );
    }

    #[test]
    fn tiles_converge_once_every_pixel_shows_less_than_the_display_error() {
        let mut tiles = DirectTiles::default();
        assert!(!tiles.converged(TARGET), "no camera yet");
        let asked = tiles.requests(&camera(1), DirectLights::All, TARGET);
        for request in &asked {
            let mut quiet = answer(request, 1.0);
            quiet
                .pixels
                .iter_mut()
                .for_each(|p| p.luminance_variance = 0.0);
            tiles.answered(&quiet).unwrap();
        }
        assert!(tiles.converged(TARGET));
        assert!(
            tiles
                .requests(&camera(1), DirectLights::All, TARGET)
                .is_empty()
        );
        let unknown = TileTarget {
            l_white: None,
            ..TARGET
        };
        assert!(
            !tiles.converged(unknown),
            "no tone map: no displayed error to judge"
        );
    }

    #[test]
    fn a_new_camera_drops_the_old_ones_tiles_and_refuses_their_answers() {
        let mut tiles = DirectTiles::default();
        let old = tiles.requests(&camera(1), DirectLights::All, TARGET);
        let new = tiles.requests(&camera(2), DirectLights::All, TARGET);
        assert_eq!(new.len(), 2);
        let ids = |r: &[TileRequest]| r.iter().map(|t| t.tile_id).collect::<Vec<_>>();
        assert_eq!(tiles.take_withdrawn(), ids(&old));
        assert!(tiles.answered(&answer(&old[0], 1.0)).is_err());
        tiles.camera_moved();
        assert_eq!(tiles.take_withdrawn(), ids(&new));
        assert!(tiles.answered(&answer(&new[0], 1.0)).is_err());
    }

    #[test]
    fn a_pixel_whose_few_samples_agree_takes_its_neighbours_variance() {
        let rect = TileRect {
            x: 0,
            y: 0,
            width: 4,
            height: 3,
        };
        let mut pixels = vec![
            PartEstimate {
                rgb: [1.0; 3],
                luminance_variance: 0.0,
            };
            12
        ];
        pixels[4].luminance_variance = 0.5; // (0, 1)
        pixels[7].luminance_variance = 0.25; // (3, 1)
        let pooled = pooled_variances(&pixels, rect);
        #[rustfmt::skip]
        let want = [
            0.5, 0.5, 0.25, 0.25,
            0.5, 0.5, 0.25, 0.25,
            0.5, 0.5, 0.25, 0.25,
        ];
        assert_eq!(pooled, want);
        let quiet = vec![pixels[0]; 12];
        assert!(pooled_variances(&quiet, rect).iter().all(|&v| v == 0.0));
    }

    #[test]
    fn a_declined_camera_asks_for_nothing_and_its_end_waits_for_no_tile() {
        let mut tiles = DirectTiles::default();
        let cut = tiles.requests(&camera(1), DirectLights::All, TARGET);
        assert!(!cut.is_empty() && tiles.heap_bytes() >= DirectTiles::bytes_for(&camera(1)));
        tiles.decline(&camera(2));
        assert_eq!(
            tiles.take_withdrawn().len(),
            cut.len(),
            "the old camera's passes go"
        );
        assert!(tiles.holds(&camera(2)) && tiles.converged(TARGET));
        assert!(
            tiles
                .requests(&camera(2), DirectLights::All, TARGET)
                .is_empty()
        );
        assert!(
            !tiles
                .requests(&camera(3), DirectLights::All, TARGET)
                .is_empty()
        );
    }
}
