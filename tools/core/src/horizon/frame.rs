//! The raycaster's output: colour and depth stored in *column tiles*, the
//! layout the march writes in, and the row-major image files want.
//!
//! The march paints each screen column bottom-up, so a row-major frame
//! would take every pixel at a stride of a whole row: a frame of 1920
//! columns is written 128 bytes at a time, 7.5 KB apart, and waits on
//! memory. In column tiles, [`TILE_COLUMNS`]
//! columns at a time, top row first within a tile, the lines of one packet
//! write one contiguous block: the march paints into the frame itself, and
//! no copy follows. A GPU reads the tiles as the layers of a texture array
//! (one upload, 256 bytes a row); files take [`RaycastFrame::to_rows`].

/// Columns per tile: one packet of the march, 256 bytes of colour a row.
pub const TILE_COLUMNS: usize = 64;

/// Elements of a `width` × `height` image in column tiles (the last tile
/// padded to whole tiles).
pub(super) fn tiled_len(width: usize, height: usize) -> usize {
    width.div_ceil(TILE_COLUMNS) * TILE_COLUMNS * height
}

/// Where pixel (`x`, `y`) (from the top-left) of an image `height` rows
/// high lies in column tiles.
#[inline]
pub fn tiled_index(x: usize, y: usize, height: usize) -> usize {
    (x / TILE_COLUMNS * height + y) * TILE_COLUMNS + x % TILE_COLUMNS
}

/// A rendered image: RGBA8 and [0, 1] depth in column tiles (see the
/// module; [`RaycastFrame::to_rows`] for row-major). Columns past `width` in the
/// last tile are padding, never drawn.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RaycastFrame {
    pub width: usize,
    pub height: usize,
    /// One pixel per element, RGBA bytes in little-endian order, at
    /// [`tiled_index`].
    pub rgba: Vec<u32>,
    /// At [`tiled_index`].
    pub depth: Vec<f32>,
    pub steps: Steps,
}

impl RaycastFrame {
    /// Host bytes a frame costs per pixel at its peak: colour and depth in
    /// column tiles and again as [`Rows`], and the encoded image (a budget
    /// estimate for callers checking a `--size` before rendering).
    pub const BYTES_PER_PIXEL: u64 = 24;
}

/// A frame in row-major order, top row first: what image files and depth
/// files hold.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Rows {
    pub width: usize,
    pub height: usize,
    /// RGBA bytes in little-endian order, one pixel per element.
    pub rgba: Vec<u32>,
    pub depth: Vec<f32>,
}

impl Rows {
    /// The image as RGBA8 bytes.
    pub fn rgba_bytes(&self) -> &[u8] {
        bytemuck::cast_slice(&self.rgba)
    }
}

impl RaycastFrame {
    /// Size the buffers for a `width` × `height` frame; a new size starts
    /// from zeros, so the padding of equal frames is equal too.
    pub(super) fn resize(&mut self, width: usize, height: usize) {
        if (width, height) != (self.width, self.height) {
            self.rgba.clear();
            self.depth.clear();
        }
        self.width = width;
        self.height = height;
        let len = tiled_len(width, height);
        self.rgba.resize(len, 0);
        self.depth.resize(len, 0.0);
    }

    /// Pixel (`x`, `y`) from the top-left: RGBA bytes and depth.
    pub fn pixel(&self, x: usize, y: usize) -> ([u8; 4], f32) {
        let i = tiled_index(x, y, self.height);
        (self.rgba[i].to_le_bytes(), self.depth[i])
    }

    /// The frame in row-major order.
    pub fn to_rows(&self) -> Rows {
        Rows {
            width: self.width,
            height: self.height,
            rgba: self.in_rows(&self.rgba),
            depth: self.in_rows(&self.depth),
        }
    }

    /// The depth alone in row-major order.
    pub fn depth_rows(&self) -> Vec<f32> {
        self.in_rows(&self.depth)
    }

    /// One of the frame's tiled buffers in row-major order.
    fn in_rows<T: Copy>(&self, tiled: &[T]) -> Vec<T> {
        let (w, h) = (self.width, self.height);
        let mut rows = Vec::with_capacity(w * h);
        for y in 0..h {
            for tile in 0..w.div_ceil(TILE_COLUMNS) {
                let at = tiled_index(tile * TILE_COLUMNS, y, h);
                let n = TILE_COLUMNS.min(w - tile * TILE_COLUMNS);
                rows.extend_from_slice(&tiled[at..at + n]);
            }
        }
        rows
    }

    /// Peak signal-to-noise ratio of this image's RGB against `reference`'s
    /// (same size), dB; infinite when they are equal.
    pub fn psnr_db(&self, reference: &RaycastFrame) -> f64 {
        let squared: f64 = (0..self.height)
            .flat_map(|y| (0..self.width).map(move |x| (x, y)))
            .map(|(x, y)| {
                let (a, b) = (self.pixel(x, y).0, reference.pixel(x, y).0);
                (0..3)
                    .map(|c| (a[c] as f64 - b[c] as f64).powi(2))
                    .sum::<f64>()
            })
            .sum();
        let mse = squared / (3 * self.width * self.height).max(1) as f64;
        if mse == 0.0 {
            f64::INFINITY
        } else {
            10.0 * (255.0f64 * 255.0 / mse).log10()
        }
    }
}

/// Wall time of each step of a render, milliseconds (in the spirit of the
/// seed's table 8.1).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Steps {
    /// Slice distances, depth vector and column rays.
    pub setup_ms: f64,
    /// Marching the columns.
    pub march_ms: f64,
    /// A pitched camera's lines to the screen's pixels.
    pub output_ms: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pixel of a frame whose width is not whole tiles has its own
    /// element, and `to_rows` puts each where a row-major image has it.
    #[test]
    fn tiles_hold_each_pixel_once_and_rows_undo_them() {
        let (w, h) = (150, 7);
        let mut frame = RaycastFrame::default();
        frame.resize(w, h);
        assert_eq!(frame.rgba.len(), 3 * TILE_COLUMNS * h);
        let mut seen = vec![false; frame.rgba.len()];
        for y in 0..h {
            for x in 0..w {
                let i = tiled_index(x, y, h);
                assert!(!seen[i], "({x}, {y}) shares element {i}");
                seen[i] = true;
                frame.rgba[i] = (y * w + x) as u32;
                frame.depth[i] = (y * w + x) as f32;
            }
        }
        let rows = frame.to_rows();
        let expected: Vec<u32> = (0..(w * h) as u32).collect();
        assert_eq!(rows.rgba, expected);
        assert!(rows
            .depth
            .iter()
            .zip(&expected)
            .all(|(&d, &e)| d == e as f32));
        assert_eq!(frame.depth_rows(), rows.depth);
        assert_eq!(frame.pixel(149, 6).1, (6 * w + 149) as f32);
    }
}
