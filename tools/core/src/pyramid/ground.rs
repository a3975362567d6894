//! The ground under points read through a region's level-0 tiles, for the
//! vegetation standing on a pyramid: the heights a single grid's
//! [`Terrain::surface`] gives, bit for bit, without the grid in memory.
//!
//! Points are grouped by the level-0 tile whose cells hold them; each group
//! reads one square window of the level-0 grid — the tile and one vertex
//! around it, the window moved inwards at the grid's edges so that it never
//! leaves the grid — and evaluates the bilinear surface there. The surface
//! reads a cell's four corners and, for a corner without data, the mean of
//! its eight neighbours (see [`Terrain`]): all inside such a window, and
//! the window's edges coincide with the grid's wherever the grid clamps.
//! Shifting a grid position by the window's origin (an integer no larger
//! than the position) is exact in floating point, so each point sees the
//! same cell at the same offsets.

use super::build::HeightSource;
use super::layout::TileLayout;
use crate::cluster::stage::Ground;
use crate::horizon::{grid_position, Terrain};
use crate::lp::window::Rect;
use crate::Result;
use rayon::prelude::*;
use std::collections::BTreeMap;

/// A point by its index among those asked and its grid position (column,
/// row).
type GridPoint = (usize, f64, f64);

/// The ground of a pyramid's level 0 read tile by tile from `source`.
///
/// ```
/// use relevo_core::cluster::stage::Ground;
/// use relevo_core::geo::GeoTransform;
/// use relevo_core::grid::HeightGrid;
/// use relevo_core::horizon::Terrain;
/// use relevo_core::pyramid::{ground::TiledGround, TileLayout};
///
/// let side = 65;
/// let grid = HeightGrid {
///     side,
///     heights: (0..side * side).map(|i| ((i * 7919) % 101) as f32).collect(),
///     mask: vec![1; side * side],
///     geotransform: GeoTransform::north_up(0.0, 640.0, 10.0, 10.0),
/// };
/// let points = [[3.5, 7.25], [333.3, 101.0], [640.0, 0.0], [700.0, 5.0]];
/// let tiled = TiledGround::new(&grid, TileLayout::new(side, 16).unwrap(), 10.0);
/// let whole = Terrain::new(side, 10.0, &grid.heights[..], &grid.mask[..], None);
/// assert_eq!(tiled.heights_under(&points).unwrap(), whole.heights_under(&points).unwrap());
/// ```
pub struct TiledGround<'a> {
    source: &'a dyn HeightSource,
    layout: TileLayout,
    cell_size_m: f64,
}

impl<'a> TiledGround<'a> {
    /// The ground of the level-0 grid of `layout` whose heights `source`
    /// gives, cells `cell_size_m` metres.
    pub fn new(source: &'a dyn HeightSource, layout: TileLayout, cell_size_m: f64) -> Self {
        TiledGround {
            source,
            layout,
            cell_size_m,
        }
    }

    /// The square window of the level-0 grid around level-0 tile
    /// (`x`, `y`): the tile and one vertex around it, moved inwards where
    /// it would leave the grid.
    fn window(&self, (x, y): (usize, usize)) -> Rect {
        let (side, t) = (self.layout.side, self.layout.tile_cells);
        let width = (t + 3).min(side);
        let origin = |first: usize| first.saturating_sub(1).min(side - width);
        Rect {
            c0: origin(x * t),
            r0: origin(y * t),
            width,
            height: width,
        }
    }
}

impl Ground for TiledGround<'_> {
    fn heights_under(&self, points: &[[f64; 2]]) -> Result<Vec<Option<f64>>> {
        let (side, t) = (self.layout.side, self.layout.tile_cells);
        let (inv_cell, last) = (1.0 / self.cell_size_m, (side - 1) as f64);
        let across = self.layout.across(0);
        // Grid positions by tile; a point whose nearest vertex is off the
        // grid (or not a number) is off the terrain.
        let mut by_tile: BTreeMap<(usize, usize), Vec<GridPoint>> = BTreeMap::new();
        for (i, &[x, y]) in points.iter().enumerate() {
            let (c, r) = grid_position(x, y, inv_cell, last);
            let on_grid = |v: f64| v > -0.5 && v < last + 0.5;
            if on_grid(c) && on_grid(r) {
                let tile = |v: f64| ((v.max(0.0) as usize) / t).min(across - 1);
                by_tile
                    .entry((tile(c), tile(r)))
                    .or_default()
                    .push((i, c, r));
            }
        }
        let groups: Vec<_> = by_tile.into_iter().collect();
        let found: Vec<Vec<(usize, Option<f64>)>> = groups
            .par_iter()
            .map(|(tile, group)| {
                let rect = self.window(*tile);
                let (heights, mask) = self.source.window(rect)?;
                let terrain = Terrain::new(rect.width, self.cell_size_m, heights, mask, None);
                let (dc, dr) = (rect.c0 as f64, rect.r0 as f64);
                Ok(group
                    .iter()
                    .map(|&(i, c, r)| (i, terrain.surface_at(c - dc, r - dr)))
                    .collect())
            })
            .collect::<Result<_>>()?;
        let mut out = vec![None; points.len()];
        for (i, z) in found.into_iter().flatten() {
            out[i] = z;
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::HeightGrid;
    use crate::testdata;

    /// On the real crops, with voids punched in and points everywhere —
    /// tile borders and corners, the half cell outside the grid, beside
    /// the voids — the tiled ground equals the whole grid's bit for bit.
    #[test]
    fn tiled_ground_equals_the_whole_grids_surface() {
        for dem in testdata::dems() {
            let side = dem.side;
            let mut mask = vec![1u8; side * side];
            for i in (0..mask.len()).step_by(37) {
                mask[i] = 0;
            }
            let grid = HeightGrid {
                side,
                heights: dem.heights.clone(),
                mask,
                geotransform: crate::geo::GeoTransform::north_up(0.0, 0.0, 1.0, 1.0),
            };
            let cell = dem.cell_size_m;
            let whole = Terrain::new(side, cell, &grid.heights[..], &grid.mask[..], None);
            let extent = (side - 1) as f64 * cell;
            let mut points = Vec::new();
            let steps = 97;
            for j in 0..=steps {
                for i in 0..=steps {
                    // From half a cell outside the grid to half a cell past it.
                    let at =
                        |k: usize| -0.6 * cell + (extent + 1.2 * cell) * k as f64 / steps as f64;
                    points.push([at(i), at(j)]);
                }
            }
            for k in 0..=side {
                // Along the tile borders of 16-cell tiles, and the grid's edges.
                let v = (k * 16).min(side - 1) as f64 * cell;
                points.extend([
                    [v, 0.3 * cell],
                    [0.7 * cell, v],
                    [v, extent],
                    [extent, v],
                    [v, v],
                ]);
            }
            let expected = whole.heights_under(&points).unwrap();
            assert!(expected.iter().filter(|z| z.is_some()).count() > points.len() / 2);
            for tile_cells in [16, 64] {
                let layout = TileLayout::new(side, tile_cells).unwrap();
                let tiled = TiledGround::new(&grid, layout, cell)
                    .heights_under(&points)
                    .unwrap();
                for (k, (a, b)) in tiled.iter().zip(&expected).enumerate() {
                    assert_eq!(
                        a.map(f64::to_bits),
                        b.map(f64::to_bits),
                        "{} tiles of {tile_cells}: point {:?}",
                        dem.name,
                        points[k]
                    );
                }
            }
        }
    }
}
