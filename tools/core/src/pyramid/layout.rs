//! Where every tile of a pyramid lies: on the grid, and in the tile files.
//!
//! Level 0 cuts the (2^n+1)² grid into tiles of (T+1)² vertices (T = 2^k
//! cells), neighbours sharing their border vertices; level l holds every
//! 2^l-th vertex, so its tiles cover T·2^l cells each and the top level is
//! one tile. A vertex of level l's lattice is a vertex of the LP
//! hierarchy's coarser part (every vertex of scale ≥ 2^l lies on it), so
//! each level holds the coarser part of the same hierarchy. Tiles are
//! stored in slots of fixed size, level 0 first, row by row within a
//! level: a tile's data is one slice of each tile file, found without a
//! search.

use crate::geo::GeoTransform;
use crate::lp::window::Rect;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};

/// A tile: its level and its column and row among that level's tiles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct TileKey {
    pub level: u32,
    pub x: usize,
    pub y: usize,
}

/// The tiling of a `side`² grid into tiles of `tile_cells` cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TileLayout {
    /// Grid vertices a side, 2^n + 1.
    pub side: usize,
    /// Cells a tile side at level 0, 2^k (a tile has `tile_cells + 1`
    /// vertices a side).
    pub tile_cells: usize,
}

/// Smallest and largest tile, cells a side.
pub const TILE_CELLS_RANGE: [usize; 2] = [16, 4096];

/// The default tile: 512 cells, 513² vertices (see docs/formats.md).
pub const DEFAULT_TILE_CELLS: usize = 512;

/// The tile a `side`² grid is cut into when none is asked for: the
/// default tile, or one tile of the whole grid when that is smaller (never
/// below the smallest tile).
///
/// ```
/// use relevo_core::pyramid::layout::default_tile_cells;
/// assert_eq!(default_tile_cells(16385), 512);
/// assert_eq!(default_tile_cells(129), 128);
/// ```
pub fn default_tile_cells(side: usize) -> usize {
    DEFAULT_TILE_CELLS.min(side.saturating_sub(1).max(TILE_CELLS_RANGE[0]))
}

impl TileLayout {
    /// The tiling of a `side`² grid into tiles of `tile_cells` cells: a
    /// power of two within [`TILE_CELLS_RANGE`], at most the grid's cells.
    pub fn new(side: usize, tile_cells: usize) -> Result<TileLayout> {
        let [lo, hi] = TILE_CELLS_RANGE;
        if !(tile_cells.is_power_of_two() && (lo..=hi).contains(&tile_cells)) {
            return Err(Error::Input(format!(
                "a tile of {tile_cells} cells: tiles are a power of two between {lo} and {hi} cells \
                 ({}–{} vertices) a side",
                lo + 1,
                hi + 1
            )));
        }
        if side < 3 || !(side - 1).is_power_of_two() || side - 1 < tile_cells {
            return Err(Error::Input(format!(
                "a {side}×{side} grid cannot be cut into tiles of {tile_cells} cells \
                 (its side must be 2^n+1 and at least a tile)"
            )));
        }
        Ok(TileLayout { side, tile_cells })
    }

    /// Vertices a tile side.
    pub fn samples(&self) -> usize {
        self.tile_cells + 1
    }

    /// Vertices a tile holds.
    pub fn tile_len(&self) -> usize {
        self.samples() * self.samples()
    }

    /// Levels, 0 (finest) to the one-tile top.
    pub fn levels(&self) -> u32 {
        ((self.side - 1) / self.tile_cells).trailing_zeros() + 1
    }

    /// Grid vertices between neighbouring samples of `level`.
    pub fn stride(&self, level: u32) -> usize {
        1 << level
    }

    /// Tiles along a side of `level`.
    pub fn across(&self, level: u32) -> usize {
        (self.side - 1) / (self.tile_cells << level)
    }

    /// Tiles in every level.
    pub fn count(&self) -> usize {
        (0..self.levels()).map(|l| self.across(l).pow(2)).sum()
    }

    /// The tile's slot in the tile files.
    pub fn slot(&self, key: TileKey) -> usize {
        let before: usize = (0..key.level).map(|l| self.across(l).pow(2)).sum();
        before + key.y * self.across(key.level) + key.x
    }

    /// Every tile of `level`, row by row.
    pub fn tiles(&self, level: u32) -> impl Iterator<Item = TileKey> {
        let across = self.across(level);
        (0..across * across).map(move |i| TileKey {
            level,
            x: i % across,
            y: i / across,
        })
    }

    /// Whether `key` names a tile of this pyramid.
    pub fn holds(&self, key: TileKey) -> bool {
        key.level < self.levels()
            && key.x < self.across(key.level)
            && key.y < self.across(key.level)
    }

    /// The geotransform of level `level`'s lattice from lattice vertex
    /// (`rect.c0`, `rect.r0`) on, a pixel a vertex, for a level-0 grid
    /// georeferenced by `grid` (a pixel a vertex): lattice pixel p (its
    /// centre at p + ½) lies where the grid's puts level-0 column
    /// (c0 + p − ½)·2^level + ½.
    pub fn lattice_geotransform(
        &self,
        grid: &GeoTransform,
        level: u32,
        rect: Rect,
    ) -> GeoTransform {
        let g = grid;
        let s = self.stride(level) as f64;
        let at = |lattice: usize| (lattice as f64 - 0.5) * s + 0.5;
        let (ox, oy) = g.apply(at(rect.c0), at(rect.r0));
        GeoTransform([ox, g.0[1] * s, g.0[2] * s, oy, g.0[4] * s, g.0[5] * s])
    }

    /// The geotransform of tile `key`'s samples, a pixel a sample.
    pub fn tile_geotransform(&self, grid: &GeoTransform, key: TileKey) -> GeoTransform {
        let t = self.tile_cells;
        let rect = Rect {
            c0: key.x * t,
            r0: key.y * t,
            width: t + 1,
            height: t + 1,
        };
        self.lattice_geotransform(grid, key.level, rect)
    }

    /// The grid vertices a tile covers: first column and row, last column
    /// and row (inclusive), and the stride between its samples.
    pub fn vertices(&self, key: TileKey) -> ([usize; 4], usize) {
        let stride = self.stride(key.level);
        let span = self.tile_cells * stride;
        let (c0, r0) = (key.x * span, key.y * span);
        ([c0, r0, c0 + span, r0 + span], stride)
    }

    /// The grid vertex of sample (i, j) of a tile.
    pub fn vertex(&self, key: TileKey, (i, j): (usize, usize)) -> (usize, usize) {
        let ([c0, r0, _, _], stride) = self.vertices(key);
        (c0 + i * stride, r0 + j * stride)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_halve_until_one_tile_and_slots_follow_each_other() {
        let l = TileLayout::new(1025, 64).unwrap();
        assert_eq!(l.levels(), 5);
        assert_eq!(
            (0..5).map(|lv| l.across(lv)).collect::<Vec<_>>(),
            [16, 8, 4, 2, 1]
        );
        assert_eq!(l.count(), 256 + 64 + 16 + 4 + 1);
        let slots: Vec<usize> = (0..5)
            .flat_map(|lv| l.tiles(lv))
            .map(|k| l.slot(k))
            .collect();
        assert_eq!(slots, (0..l.count()).collect::<Vec<_>>());
        let top = TileKey {
            level: 4,
            x: 0,
            y: 0,
        };
        assert_eq!(l.vertices(top), ([0, 0, 1024, 1024], 16));
        assert_eq!(
            l.vertex(
                TileKey {
                    level: 1,
                    x: 1,
                    y: 0
                },
                (1, 2)
            ),
            (130, 4)
        );
        assert!(TileLayout::new(1025, 100).is_err() && TileLayout::new(513, 1024).is_err());
    }
}
