//! Cutting an image into tiles for extraction: each tile owns a square of
//! pixels (its core) and is analysed with a margin of context around it, so
//! regions, crowns and fill objects near the core's edge see what lies
//! beyond. Only a tile's core is kept: every pixel and every object belongs
//! to exactly one tile. Memory then grows with the tile, not the image.

use super::detect::Placement;

/// Default side of the square of pixels a tile owns. An image this size or
/// smaller is one tile, analysed whole.
pub const CORE_PX: usize = 2048;

/// Cores and margins are multiples of this many pixels, so that a tile's
/// quadtree blocks (up to this size) fall where the whole image's do.
pub const ALIGN_PX: usize = super::segment::TILE;

/// Smallest margin of context around a core, pixels: a quadtree tile of
/// the split, more than a Haar signature's window.
const MIN_MARGIN_PX: usize = ALIGN_PX;

/// How an image is cut.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Tiling {
    /// Side of a tile's core, pixels.
    pub core_px: usize,
    /// Context analysed on each side of the core, pixels.
    pub margin_px: usize,
}

impl Tiling {
    /// Cores of `core_px` with a margin wide enough for `placement`: for
    /// crowns, four crown spacings (the brightness smoothing, the window a
    /// maximum must dominate, the disc of vegetation measured around it and
    /// the spacing the greedy selection keeps all lie within that). Both are
    /// rounded up to multiples of [`ALIGN_PX`].
    pub fn for_placement(placement: &Placement, core_px: usize) -> Tiling {
        let context = match placement {
            Placement::Crowns { spacing_px, .. } => (4.0 * spacing_px).ceil() as usize,
            Placement::Fill { .. } => 0,
        };
        Tiling {
            core_px: core_px.max(1).next_multiple_of(ALIGN_PX),
            margin_px: context.max(MIN_MARGIN_PX).next_multiple_of(ALIGN_PX),
        }
    }

    /// The tiles of a `width`×`height` image, row by row.
    pub fn plan(&self, width: usize, height: usize) -> Vec<Tile> {
        let core = self.core_px.max(1);
        let mut tiles = Vec::new();
        for y0 in (0..height).step_by(core) {
            for x0 in (0..width).step_by(core) {
                let (x1, y1) = ((x0 + core).min(width), (y0 + core).min(height));
                tiles.push(Tile {
                    core: [x0, y0, x1, y1],
                    context: [
                        x0.saturating_sub(self.margin_px),
                        y0.saturating_sub(self.margin_px),
                        (x1 + self.margin_px).min(width),
                        (y1 + self.margin_px).min(height),
                    ],
                });
            }
        }
        tiles
    }
}

/// One tile: `[x0, y0, x1, y1)` rectangles in the image's pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Tile {
    /// The pixels the tile owns.
    pub core: [usize; 4],
    /// The pixels it analyses: the core and its margin, inside the image.
    pub context: [usize; 4],
}

impl Tile {
    /// Whether the tile owns the point `(x, y)` (pixel coordinates of the
    /// image; pixel `i` spans `[i, i+1)`).
    pub fn owns(&self, x: f64, y: f64) -> bool {
        let [x0, y0, x1, y1] = self.core.map(|v| v as f64);
        x >= x0 && x < x1 && y >= y0 && y < y1
    }

    /// Width and height of the context.
    pub fn context_size(&self) -> (usize, usize) {
        let [x0, y0, x1, y1] = self.context;
        (x1 - x0, y1 - y0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_own_every_pixel_once_and_see_their_margin() {
        let tiling = Tiling {
            core_px: 100,
            margin_px: 16,
        };
        let (w, h) = (250, 130);
        let tiles = tiling.plan(w, h);
        assert_eq!(tiles.len(), 3 * 2);
        for y in 0..h {
            for x in 0..w {
                let owners = tiles
                    .iter()
                    .filter(|t| t.owns(x as f64 + 0.5, y as f64 + 0.5))
                    .count();
                assert_eq!(owners, 1, "pixel {x},{y}");
            }
        }
        for t in &tiles {
            let [cx0, cy0, cx1, cy1] = t.core;
            let [x0, y0, x1, y1] = t.context;
            assert_eq!(x0, cx0.saturating_sub(16));
            assert_eq!(y0, cy0.saturating_sub(16));
            assert_eq!(x1, (cx1 + 16).min(w));
            assert_eq!(y1, (cy1 + 16).min(h));
        }
        // An image no larger than a core is one tile: the whole image.
        let one = tiling.plan(100, 60);
        assert_eq!(one.len(), 1);
        assert_eq!(one[0].core, [0, 0, 100, 60]);
        assert_eq!(one[0].context, one[0].core);
    }

    #[test]
    fn crowns_get_a_margin_of_four_spacings_aligned_to_the_quadtree() {
        let crowns = Placement::Crowns {
            spacing_px: 25.0,
            min_radius_px: 5.0,
            marked_size_px: None,
            template: None,
        };
        assert_eq!(Tiling::for_placement(&crowns, CORE_PX).margin_px, 128);
        assert_eq!(Tiling::for_placement(&crowns, 300).core_px, 320);
        let fill = Placement::Fill {
            spacing_px: 0.3,
            diameter_px: 0.3,
        };
        assert_eq!(
            Tiling::for_placement(&fill, CORE_PX).margin_px,
            MIN_MARGIN_PX
        );
    }
}
