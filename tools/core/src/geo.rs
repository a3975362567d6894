//! Affine georeferencing of a grid, and the terrain frame every renderer
//! and exporter works in.

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

    /// When `self` and `other` are north-up grids with the same cells (to
    /// 1e-9 relative) whose origins are a whole number of cells apart, the
    /// (column, row) of `other`'s origin in `self`'s cells: copying cells
    /// then places one grid on the other exactly.
    pub fn whole_cell_offset(&self, other: &GeoTransform) -> Option<(i64, i64)> {
        let (rx, ry) = other.cell_size();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs());
        if !self.is_north_up() || !close(self.0[1], rx) || !close(-self.0[5], ry) {
            return None;
        }
        let dc = (other.0[0] - self.0[0]) / rx;
        let dr = (self.0[3] - other.0[3]) / ry;
        let whole = |v: f64| (v - v.round()).abs() < 1e-6;
        (whole(dc) && whole(dr)).then(|| (dc.round() as i64, dr.round() as i64))
    }

    /// Cell width and height in world units (positive).
    pub fn cell_size(&self) -> (f64, f64) {
        let t = &self.0;
        (t[1].hypot(t[4]), t[2].hypot(t[5]))
    }

    /// The shorter side of a cell, in world units: the ground size of a
    /// pixel as vegetation extraction takes it.
    pub fn smallest_cell_side(&self) -> f64 {
        let (w, h) = self.cell_size();
        w.min(h)
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

/// The terrain frame of a (2^n+1)² height grid and its conversions to and
/// from world (CRS) coordinates. One definition serves the raycaster, the
/// mesh exporter, vegetation placement and the viewer.
///
/// Vertex (c, r) of the grid (column, row; row 0 is north) stands at the
/// centre of cell (c, r) of `geotransform`, and at x = c·cell (east),
/// y = (side − 1 − r)·cell (north) in the terrain frame, whose origin is the
/// south-west vertex. Heights (z) are metres in both frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TerrainFrame {
    /// Vertices per side, 2^n + 1.
    pub side: usize,
    /// Horizontal vertex spacing, metres.
    pub cell_size_m: f64,
    /// Grid cell → world coordinates.
    pub geotransform: GeoTransform,
}

impl TerrainFrame {
    /// Fractional grid position (column, row) of terrain point (x, y).
    #[inline]
    pub fn vertex_from_terrain(&self, x: f64, y: f64) -> (f64, f64) {
        (
            x / self.cell_size_m,
            (self.side - 1) as f64 - y / self.cell_size_m,
        )
    }

    /// Terrain-frame (x, y) of fractional grid position (column, row).
    #[inline]
    pub fn terrain_from_vertex(&self, col: f64, row: f64) -> (f64, f64) {
        (
            col * self.cell_size_m,
            ((self.side - 1) as f64 - row) * self.cell_size_m,
        )
    }

    /// World (east, north) of terrain point (x, y).
    pub fn world_from_terrain(&self, x: f64, y: f64) -> (f64, f64) {
        let (col, row) = self.vertex_from_terrain(x, y);
        self.world_from_vertex(col, row)
    }

    /// Terrain (x, y) of world point (east, north); `None` when the
    /// geotransform cannot be inverted.
    pub fn terrain_from_world(&self, east: f64, north: f64) -> Option<(f64, f64)> {
        let (col, row) = self.vertex_from_world(east, north)?;
        Some(self.terrain_from_vertex(col, row))
    }

    /// World (east, north) of fractional grid position (column, row).
    pub fn world_from_vertex(&self, col: f64, row: f64) -> (f64, f64) {
        self.geotransform.apply(col + 0.5, row + 0.5)
    }

    /// Fractional grid position of world point (east, north).
    pub fn vertex_from_world(&self, east: f64, north: f64) -> Option<(f64, f64)> {
        let (col, row) = self.geotransform.invert(east, north)?;
        Some((col - 0.5, row - 0.5))
    }

    /// The affine map from terrain (x, y) to pixel (column, row) of an
    /// image georeferenced by `image`: `[a₀, a₁, a₂, a₃, a₄, a₅]` with
    /// column = a₀ + a₁x + a₂y, row = a₃ + a₄x + a₅y. `None` when either
    /// geotransform cannot be inverted.
    pub fn terrain_to_pixel(&self, image: &GeoTransform) -> Option<[f64; 6]> {
        let pixel = |x: f64, y: f64| {
            let (east, north) = self.world_from_terrain(x, y);
            image.invert(east, north)
        };
        let (o, ex, ey) = (pixel(0.0, 0.0)?, pixel(1.0, 0.0)?, pixel(0.0, 1.0)?);
        Some([o.0, ex.0 - o.0, ey.0 - o.0, o.1, ex.1 - o.1, ey.1 - o.1])
    }

    /// World (east, north) of the terrain frame's origin, the south-west vertex.
    pub fn world_origin(&self) -> (f64, f64) {
        self.world_from_vertex(0.0, (self.side - 1) as f64)
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
    fn terrain_frame_round_trips_and_puts_vertices_at_cell_centres() {
        let frame = TerrainFrame {
            side: 129,
            cell_size_m: 30.0,
            geotransform: GeoTransform::north_up(288_000.0, 9_115_000.0, 30.0, 30.0),
        };
        // The north-west vertex is the centre of the top-left cell.
        assert_eq!(frame.world_from_vertex(0.0, 0.0), (288_015.0, 9_114_985.0));
        assert_eq!(
            frame.world_origin(),
            (288_015.0, 9_114_985.0 - 128.0 * 30.0)
        );
        assert_eq!(frame.world_from_terrain(0.0, 0.0), frame.world_origin());
        let (x, y) = frame.terrain_from_world(289_000.25, 9_111_000.5).unwrap();
        let (e, n) = frame.world_from_terrain(x, y);
        assert!((e - 289_000.25).abs() < 1e-6 && (n - 9_111_000.5).abs() < 1e-6);
        assert_eq!(frame.terrain_from_vertex(2.0, 128.0), (60.0, 0.0));
    }

    #[test]
    fn whole_cell_offsets_only_between_aligned_grids() {
        let src = GeoTransform::north_up(1000.0, 2000.0, 30.0, 30.0);
        let window = GeoTransform::north_up(1090.0, 1940.0, 30.0, 30.0);
        assert_eq!(src.whole_cell_offset(&window), Some((3, 2)));
        let shifted = GeoTransform::north_up(1095.0, 1940.0, 30.0, 30.0);
        assert_eq!(src.whole_cell_offset(&shifted), None);
        let coarser = GeoTransform::north_up(1090.0, 1940.0, 60.0, 60.0);
        assert_eq!(src.whole_cell_offset(&coarser), None);
    }

    #[test]
    fn bounds_of_north_up_grid() {
        let g = GeoTransform::north_up(100.0, 500.0, 10.0, 20.0);
        assert_eq!(g.bounds(3, 2), [100.0, 460.0, 130.0, 500.0]);
        assert!(g.is_north_up());
        assert_eq!(g.cell_size(), (10.0, 20.0));
    }
}
