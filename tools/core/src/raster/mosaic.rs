//! Combining tiles that already sit on one target grid into a mosaic.
//!
//! Ingest warps every input tile onto a window of the common grid (GDAL does
//! that part); this module decides what each output cell gets where tiles
//! overlap.

use super::{distance::distance_to_seeds, Raster};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// How overlapping tiles combine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Overlap {
    /// The first tile (in input order) that has data wins.
    First,
    /// The last tile that has data wins.
    Last,
    /// Feathering: each tile is weighted by the distance from the cell to the
    /// edge of that tile's valid data, so every tile fades to zero weight at
    /// its own edge and radiometric seams disappear.
    #[default]
    Blend,
}

/// A tile resampled onto the target grid, covering the window whose top-left
/// cell is (`col`, `row`).
#[derive(Debug, Clone)]
pub struct PlacedTile {
    pub col: usize,
    pub row: usize,
    pub raster: Raster,
}

/// Feathering weight of every cell of a tile: distance in cells from the cell
/// centre to where this tile's data ends and another tile's data goes on
/// (halfway to the nearest cell that some tile covers and this one does not).
/// The outer edge of the mosaic and holes no tile covers are not such edges,
/// so they do not pull a tile's weight down. Zero where the tile has no data.
/// `covered` flags, for the whole `grid_width`-wide grid, cells with any data.
pub fn feather_weights(tile: &PlacedTile, covered: &[bool], grid_width: usize) -> Vec<f32> {
    let r = &tile.raster;
    let grid_height = covered.len() / grid_width;
    // The tile's window grown by one cell, so that neighbouring data just
    // beyond the window counts as an edge.
    let c0 = tile.col.saturating_sub(1);
    let r0 = tile.row.saturating_sub(1);
    let c1 = (tile.col + r.width + 1).min(grid_width);
    let r1 = (tile.row + r.height + 1).min(grid_height);
    let (w, h) = (c1 - c0, r1 - r0);
    let valid = r.valid_mask();
    let valid_here = |gc: usize, gr: usize| {
        gc >= tile.col
            && gr >= tile.row
            && gc < tile.col + r.width
            && gr < tile.row + r.height
            && valid[(gr - tile.row) * r.width + (gc - tile.col)]
    };
    let seed: Vec<bool> = (0..w * h)
        .map(|i| {
            let (gc, gr) = (c0 + i % w, r0 + i / w);
            covered[gr * grid_width + gc] && !valid_here(gc, gr)
        })
        .collect();
    let distance = distance_to_seeds(&seed, w, h);
    let mut weights = vec![0.0f32; r.cells()];
    for (i, weight) in weights.iter_mut().enumerate() {
        let (gc, gr) = (tile.col + i % r.width, tile.row + i / r.width);
        if valid[i] {
            *weight = distance[(gr - r0) * w + (gc - c0)] - 0.5;
        }
    }
    weights
}

/// Mosaic `tiles` onto a `width`×`height` grid with `bands` bands.
/// Cells no tile covers stay no-data. Deterministic: tiles are visited in
/// input order and every sum is accumulated in that fixed order.
pub fn mosaic(
    width: usize,
    height: usize,
    bands: usize,
    tiles: &[PlacedTile],
    rule: Overlap,
) -> Raster {
    for t in tiles {
        assert_eq!(t.raster.bands, bands, "tile band count");
        assert!(t.col + t.raster.width <= width && t.row + t.raster.height <= height);
    }
    let weights: Vec<Vec<f32>> = match rule {
        Overlap::Blend => {
            let covered = coverage(width, height, tiles);
            tiles
                .par_iter()
                .map(|t| feather_weights(t, &covered, width))
                .collect()
        }
        Overlap::First | Overlap::Last => Vec::new(),
    };
    let order: Vec<usize> = match rule {
        Overlap::Last => (0..tiles.len()).rev().collect(),
        _ => (0..tiles.len()).collect(),
    };

    // Rows are independent; build them in parallel, each band-interleaved, then
    // scatter to band-major.
    let rows: Vec<Vec<f64>> = (0..height)
        .into_par_iter()
        .map(|row| {
            let mut sum = vec![0.0f64; width * bands];
            let mut weight_sum = vec![0.0f64; width];
            for &ti in &order {
                let tile = &tiles[ti];
                let r = &tile.raster;
                if row < tile.row || row >= tile.row + r.height {
                    continue;
                }
                let tr = row - tile.row;
                let n = r.cells();
                for tc in 0..r.width {
                    let i = tr * r.width + tc;
                    let c = tile.col + tc;
                    // A blend weight is positive exactly where the tile has data.
                    let w = match rule {
                        Overlap::Blend => weights[ti][i] as f64,
                        _ if weight_sum[c] > 0.0 || !r.is_valid(i) => continue,
                        _ => 1.0,
                    };
                    if w <= 0.0 {
                        continue;
                    }
                    for b in 0..bands {
                        sum[c * bands + b] += w * r.data[b * n + i];
                    }
                    weight_sum[c] += w;
                }
            }
            for c in 0..width {
                for b in 0..bands {
                    let s = &mut sum[c * bands + b];
                    *s = if weight_sum[c] > 0.0 {
                        *s / weight_sum[c]
                    } else {
                        f64::NAN
                    };
                }
            }
            sum
        })
        .collect();

    let mut out = Raster::empty(width, height, bands);
    let n = width * height;
    for (row, values) in rows.iter().enumerate() {
        for c in 0..width {
            for b in 0..bands {
                out.data[b * n + row * width + c] = values[c * bands + b];
            }
        }
    }
    out
}

/// How visible tile seams are in a mosaic, as a step relative to texture.
///
/// Neighbouring cells covered by different sets of tiles straddle a tile
/// edge. For each kind of edge (pair of cover sets) the mean *signed*
/// difference across it is the systematic step there (texture averages out);
/// the figure is the mean of those |steps| weighted by how many neighbour
/// pairs each kind has, divided by the mean absolute
/// difference between neighbours covered by the same tiles (the image's own
/// texture). 0 means no step; a visible seam is a sizeable fraction of 1.
/// Averaged over bands; `None` without both kinds of pairs. At most 64 tiles.
pub fn seam_visibility(mosaic: &Raster, tiles: &[PlacedTile]) -> Option<f64> {
    assert!(tiles.len() <= 64, "seam_visibility takes at most 64 tiles");
    let (w, h) = (mosaic.width, mosaic.height);
    let mut cover = vec![0u64; w * h];
    for (k, t) in tiles.iter().enumerate() {
        for i in 0..t.raster.cells() {
            if t.raster.is_valid(i) {
                cover[(t.row + i / t.raster.width) * w + t.col + i % t.raster.width] |= 1 << k;
            }
        }
    }
    // Signed step sums per edge kind, ordered (smaller cover set first).
    let mut steps: std::collections::BTreeMap<(u64, u64), (f64, usize)> = Default::default();
    let (mut texture, mut texture_n) = (0.0, 0usize);
    for r in 0..h {
        for c in 0..w {
            let p = r * w + c;
            for q in [(c + 1 < w).then(|| p + 1), (r + 1 < h).then(|| p + w)]
                .into_iter()
                .flatten()
            {
                if !mosaic.is_valid(p) || !mosaic.is_valid(q) || cover[p] == 0 || cover[q] == 0 {
                    continue;
                }
                let (p, q) = if cover[p] <= cover[q] { (p, q) } else { (q, p) };
                let diff: f64 = (0..mosaic.bands)
                    .map(|b| mosaic.band(b)[q] - mosaic.band(b)[p])
                    .sum::<f64>()
                    / mosaic.bands as f64;
                if cover[p] == cover[q] {
                    texture += diff.abs();
                    texture_n += 1;
                } else {
                    let s = steps.entry((cover[p], cover[q])).or_default();
                    s.0 += diff;
                    s.1 += 1;
                }
            }
        }
    }
    if steps.is_empty() || texture_n == 0 || texture == 0.0 {
        return None;
    }
    let pairs: usize = steps.values().map(|s| s.1).sum();
    let step = steps
        .values()
        .map(|&(sum, n)| (sum / n as f64).abs() * n as f64)
        .sum::<f64>()
        / pairs as f64;
    Some(step / (texture / texture_n as f64))
}

/// Cells of the grid where at least one tile has data.
fn coverage(width: usize, height: usize, tiles: &[PlacedTile]) -> Vec<bool> {
    let mut covered = vec![false; width * height];
    for t in tiles {
        for i in 0..t.raster.cells() {
            if t.raster.is_valid(i) {
                covered[(t.row + i / t.raster.width) * width + t.col + i % t.raster.width] = true;
            }
        }
    }
    covered
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tile(col: usize, row: usize, w: usize, h: usize, value: f64) -> PlacedTile {
        PlacedTile {
            col,
            row,
            raster: Raster::from_data(w, h, 1, vec![value; w * h]),
        }
    }

    #[test]
    fn first_and_last_pick_by_order() {
        let tiles = [tile(0, 0, 4, 1, 1.0), tile(2, 0, 4, 1, 2.0)];
        let first = mosaic(6, 1, 1, &tiles, Overlap::First);
        let last = mosaic(6, 1, 1, &tiles, Overlap::Last);
        assert_eq!(first.data, vec![1.0, 1.0, 1.0, 1.0, 2.0, 2.0]);
        assert_eq!(last.data, vec![1.0, 1.0, 2.0, 2.0, 2.0, 2.0]);
    }

    #[test]
    fn blend_stays_between_sources_and_fades_at_edges() {
        let tiles = [tile(0, 0, 40, 9, 10.0), tile(20, 0, 40, 9, 20.0)];
        let m = mosaic(60, 9, 1, &tiles, Overlap::Blend);
        for r in 0..9 {
            let row: Vec<f64> = m.data[r * 60..(r + 1) * 60].to_vec();
            assert!(row.iter().all(|v| (10.0..=20.0).contains(v)));
            assert_eq!(row[10], 10.0);
            assert_eq!(row[50], 20.0);
            // A monotonic ramp across the overlap, with no step at either tile edge.
            for c in 18..42 {
                assert!(row[c + 1] >= row[c]);
                assert!(row[c + 1] - row[c] <= 10.0 / 20.0 + 1e-9, "row {r} col {c}");
            }
        }
    }

    #[test]
    fn blend_hides_a_radiometric_step_that_first_shows() {
        // Two overlapping tiles of one textured scene, the second 30 units brighter.
        let texture = |c: usize, r: usize| ((c * 7 + r * 13) % 11) as f64;
        let make = |col: usize, offset: f64| PlacedTile {
            col,
            row: 0,
            raster: Raster::from_data(
                40,
                20,
                1,
                (0..800)
                    .map(|i| texture(col + i % 40, i / 40) + offset)
                    .collect(),
            ),
        };
        let tiles = [make(0, 0.0), make(20, 30.0)];
        let first = seam_visibility(&mosaic(60, 20, 1, &tiles, Overlap::First), &tiles).unwrap();
        let blend = seam_visibility(&mosaic(60, 20, 1, &tiles, Overlap::Blend), &tiles).unwrap();
        assert!(first > 3.0, "first: {first}");
        assert!(blend < 0.5, "blend: {blend}");
    }

    #[test]
    fn uncovered_cells_stay_nodata() {
        let m = mosaic(5, 2, 1, &[tile(0, 0, 2, 2, 3.0)], Overlap::Blend);
        assert!(m.data[4].is_nan());
        assert_eq!(m.data[0], 3.0);
    }
}
