//! Affine georeferencing of a grid.

use serde::{Deserialize, Serialize};

/// GDAL-ordered affine transform from grid (column, row) to world (x, y):
/// `x = t[0] + col·t[1] + row·t[2]`, `y = t[3] + col·t[4] + row·t[5]`.
/// `(col, row) = (0, 0)` is the top-left corner of the top-left cell; cell
/// centres sit at half-integers. Units are those of the CRS (metres in a bundle).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GeoTransform(pub [f64; 6]);

impl GeoTransform {
    /// The transform GDAL reports for a raster with no georeferencing: one
    /// world unit per cell, y growing downwards.
    pub const IDENTITY: GeoTransform = GeoTransform([0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);

    /// North-up transform with square or rectangular cells.
    pub fn north_up(origin_x: f64, origin_y: f64, cell_w: f64, cell_h: f64) -> Self {
        GeoTransform([origin_x, cell_w, 0.0, origin_y, 0.0, -cell_h])
    }

    /// World coordinates of fractional grid position (col, row).
    pub fn apply(&self, col: f64, row: f64) -> (f64, f64) {
        let t = &self.0;
        (
            t[0] + col * t[1] + row * t[2],
            t[3] + col * t[4] + row * t[5],
        )
    }

    /// Fractional grid position of world point (x, y); `None` if singular.
    pub fn invert(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let t = &self.0;
        let det = t[1] * t[5] - t[2] * t[4];
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let (dx, dy) = (x - t[0], y - t[3]);
        Some(((dx * t[5] - dy * t[2]) / det, (dy * t[1] - dx * t[4]) / det))
    }

    /// True when rows and columns are aligned with the world axes.
    pub fn is_north_up(&self) -> bool {
        self.0[2] == 0.0 && self.0[4] == 0.0 && self.0[1] > 0.0 && self.0[5] < 0.0
    }

    /// Cell width and height in world units (positive).
    pub fn cell_size(&self) -> (f64, f64) {
        let t = &self.0;
        (t[1].hypot(t[4]), t[2].hypot(t[5]))
    }

    /// World bounding box `[xmin, ymin, xmax, ymax]` of a `width`×`height` grid.
    pub fn bounds(&self, width: usize, height: usize) -> [f64; 4] {
        let corners = [
            self.apply(0.0, 0.0),
            self.apply(width as f64, 0.0),
            self.apply(0.0, height as f64),
            self.apply(width as f64, height as f64),
        ];
        let mut b = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for (x, y) in corners {
            b[0] = b[0].min(x);
            b[1] = b[1].min(y);
            b[2] = b[2].max(x);
            b[3] = b[3].max(y);
        }
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn invert_undoes_apply() {
        let g = GeoTransform([288776.25, 28.5, 0.3, 9120760.75, -0.2, -28.5]);
        let (x, y) = g.apply(12.25, 40.5);
        let (c, r) = g.invert(x, y).unwrap();
        assert!((c - 12.25).abs() < 1e-9 && (r - 40.5).abs() < 1e-9);
    }

    #[test]
    fn bounds_of_north_up_grid() {
        let g = GeoTransform::north_up(100.0, 500.0, 10.0, 20.0);
        assert_eq!(g.bounds(3, 2), [100.0, 460.0, 130.0, 500.0]);
        assert!(g.is_north_up());
        assert_eq!(g.cell_size(), (10.0, 20.0));
    }
}
