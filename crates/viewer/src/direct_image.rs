//! The per-pixel direct light of the resting camera (DESIGN.md §3 step 8): the SMA sends it in
//! tiles (`protocol::direct_tile::ViewerTile`) while the camera this viewer last sent rests. A
//! pixel of a tile keeps its direct part and that part's standard error; the drawing pass
//! (`draw.wgsl`, `tile_weight`) shows it in place of the vertices' direct part where it is
//! precise, or where the two differ by more than the tile's noise explains, and then shows
//! `tile direct + albedo × interpolated illumination × (1 − interpolated direct share)` plus the
//! interpolated view-dependent part; a tile's direct part is radiance, the renderer's albedo of
//! that pixel's first hit times its direct illumination. Tiles of another
//! camera are ignored; sending a new camera drops the old one's, and a picture drawn for a camera
//! other than the tiles' (a move the camera sender has not sent yet) shows none of them.

use protocol::direct_tile::ViewerTile;
use protocol::viewer_link::Camera;

use crate::camera_sender::same_view;

/// One texel per pixel: the direct part's RGB and the standard error of its luminance
/// ([`NO_TILE`] where no tile has covered the pixel yet).
pub type DirectTexel = [f32; 4];

/// The standard error of a pixel no tile has covered: `draw.wgsl` shows the vertices' there.
pub const NO_TILE: f32 = -1.0;

/// The direct tiles of the camera this viewer last sent, per pixel (rows from the top).
#[derive(Clone, Debug, Default)]
pub struct DirectImage {
    camera: Option<Camera>,
    /// Counts the cameras followed: a GPU copy of another generation holds none of these tiles.
    generation: u64,
    /// `width × height` texels once a tile of the camera has arrived; empty before, so a moving
    /// camera costs no clearing.
    texels: Vec<DirectTexel>,
    tiles: usize,
    /// Tiles accepted since the GPU copy last took them (`direct_texture`).
    dirty: Vec<protocol::direct_tile::TileRect>,
}

impl DirectImage {
    /// `camera` was sent to the SMA: tiles of any other camera are dropped from now on.
    pub fn follow(&mut self, camera: &Camera) {
        if self.camera.as_ref().is_some_and(|c| c.seq == camera.seq) {
            return;
        }
        self.camera = Some(camera.clone());
        self.generation += 1;
        self.texels.clear();
        self.tiles = 0;
        self.dirty.clear();
    }

    /// Takes `tile` into the image if it is of the followed camera and well formed; says
    /// whether it did (a malformed tile is logged).
    pub fn accept(&mut self, tile: &ViewerTile) -> bool {
        let Some(camera) = &self.camera else {
            return false;
        };
        if tile.camera_seq != camera.seq {
            tracing::trace!(
                tile = tile.camera_seq,
                camera = camera.seq,
                "stale direct tile"
            );
            return false;
        }
        let (width, height) = (camera.width, camera.height);
        if let Err(reason) = tile.check(width, height) {
            tracing::warn!(%reason, "direct tile refused");
            return false;
        }
        if self.texels.is_empty() {
            self.texels = vec![[0.0, 0.0, 0.0, NO_TILE]; width as usize * height as usize];
        }
        let rect = tile.rect;
        for (i, pixel) in tile.pixels.iter().enumerate() {
            let (x, y) = (
                rect.x as usize + i % rect.width as usize,
                rect.y as usize + i / rect.width as usize,
            );
            let [r, g, b] = pixel.rgb.map(|h| h.decode());
            self.texels[y * width as usize + x] = [r, g, b, pixel.standard_error.decode()];
        }
        self.tiles += 1;
        self.dirty.push(rect);
        true
    }

    /// Whether a picture drawn for `camera` shows tiles: some have arrived for it.
    pub fn shown_for(&self, camera: &Camera) -> bool {
        self.tiles > 0 && self.camera.as_ref().is_some_and(|c| same_view(c, camera))
    }

    /// The image's size in pixels (the followed camera's), if it has texels.
    pub fn size(&self) -> Option<(u32, u32)> {
        let camera = self.camera.as_ref()?;
        (!self.texels.is_empty()).then_some((camera.width, camera.height))
    }

    pub fn generation(&self) -> u64 {
        self.generation
    }

    pub fn texels(&self) -> &[DirectTexel] {
        &self.texels
    }

    /// The tiles accepted since the last call.
    pub fn take_dirty(&mut self) -> Vec<protocol::direct_tile::TileRect> {
        std::mem::take(&mut self.dirty)
    }

    /// The tiles of the followed camera, if a picture of `camera` shows them (a snapshot's copy).
    pub fn copy_for(&self, camera: &Camera) -> Option<DirectImage> {
        self.shown_for(camera).then(|| DirectImage {
            dirty: Vec::new(),
            ..self.clone()
        })
    }

    /// Drops everything (a new session: the SMA knows no camera of this viewer).
    pub fn clear(&mut self) {
        self.camera = None;
        self.generation += 1;
        self.texels.clear();
        self.tiles = 0;
        self.dirty.clear();
    }
}

#[cfg(test)]
mod tests {
    use protocol::direct_tile::{TilePixel, TileRect};

    use super::*;

    fn camera(seq: u64, x: f32) -> Camera {
        Camera {
            seq,
            eye: [x, 0.0, 0.0],
            orientation: [0.0, 0.0, 0.0, 1.0],
            fov_y_deg: 60.0,
            width: 8,
            height: 4,
        }
    }

    fn tile(camera_seq: u64, standard_error: f32) -> ViewerTile {
        ViewerTile {
            camera_seq,
            rect: TileRect {
                x: 2,
                y: 1,
                width: 2,
                height: 2,
            },
            samples: 4,
            pixels: vec![TilePixel::new([1.0, 2.0, 3.0], standard_error); 4],
        }
    }

    #[test]
    fn tiles_of_the_followed_camera_fill_their_pixels_and_others_are_ignored() {
        let mut image = DirectImage::default();
        assert!(!image.accept(&tile(1, 0.0)), "no camera followed yet");
        image.follow(&camera(1, 0.0));
        assert!(!image.accept(&tile(2, 0.0)), "a tile of another camera");
        assert!(!image.shown_for(&camera(1, 0.0)));
        assert!(image.accept(&tile(1, 0.0)));
        assert!(image.shown_for(&camera(1, 0.0)));
        assert!(
            !image.shown_for(&camera(1, 0.5)),
            "a moved camera shows no tiles"
        );
        let texels = image.texels();
        assert_eq!(texels[8 + 2], [1.0, 2.0, 3.0, 0.0]);
        assert_eq!(texels[2 * 8 + 3], [1.0, 2.0, 3.0, 0.0]);
        assert_eq!(texels[0], [0.0, 0.0, 0.0, NO_TILE]);
        assert_eq!(texels[8 + 4], [0.0, 0.0, 0.0, NO_TILE]);
        assert_eq!(image.take_dirty(), vec![tile(1, 0.0).rect]);
        assert!(image.take_dirty().is_empty());
        // A new camera drops the old one's tiles.
        image.follow(&camera(2, 0.5));
        assert!(!image.shown_for(&camera(2, 0.5)) && image.size().is_none());
        assert!(!image.accept(&tile(1, 0.0)));
    }

    #[test]
    fn pixels_keep_their_standard_error_and_malformed_tiles_are_refused() {
        let mut image = DirectImage::default();
        image.follow(&camera(3, 0.0));
        assert!(image.accept(&tile(3, 0.75)));
        assert_eq!(image.texels()[8 + 2][3], 0.75);
        let mut outside = tile(3, 0.0);
        outside.rect.x = 7;
        assert!(!image.accept(&outside));
        let mut short = tile(3, 0.0);
        short.pixels.pop();
        assert!(!image.accept(&short));
    }
}
