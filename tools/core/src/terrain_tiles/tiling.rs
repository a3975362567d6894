//! Cesium's geodetic tiling (EPSG:4326, the tiling quantized-mesh terrain
//! uses): level z holds 2^(z+1) × 2^z tiles of 180/2^z degrees, x counted
//! eastward from the antimeridian, y northward from the south pole (TMS).

use super::ellipsoid::SEMI_MAJOR_AXIS_M;

/// A tile of the geodetic tiling.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileId {
    pub z: u32,
    pub x: u32,
    pub y: u32,
}

/// Degrees a tile of level `z` spans, east–west and south–north.
pub fn tile_size_deg(z: u32) -> f64 {
    180.0 / f64::powi(2.0, z as i32)
}

impl TileId {
    /// `[west, south, east, north]`, degrees.
    pub fn bounds_deg(&self) -> [f64; 4] {
        let size = tile_size_deg(self.z);
        let west = -180.0 + self.x as f64 * size;
        let south = -90.0 + self.y as f64 * size;
        [west, south, west + size, south + size]
    }

    /// Its four tiles at the next level.
    pub fn children(&self) -> [TileId; 4] {
        let (z, x, y) = (self.z + 1, 2 * self.x, 2 * self.y);
        [(x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1)].map(|(x, y)| TileId { z, x, y })
    }
}

/// A rectangle of tiles of one level, inclusive: what `layer.json` calls an
/// available range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileRange {
    pub z: u32,
    pub x: [u32; 2],
    pub y: [u32; 2],
}

impl TileRange {
    /// The tiles of level `z` that share a positive area with `bounds`
    /// (`[west, south, east, north]`, degrees); both level-0 tiles at z = 0,
    /// since a client starts from them.
    pub fn covering(z: u32, [w, s, e, n]: [f64; 4]) -> TileRange {
        if z == 0 {
            return TileRange {
                z,
                x: [0, 1],
                y: [0, 0],
            };
        }
        let size = tile_size_deg(z);
        let (columns, rows) = (1u64 << (z + 1), 1u64 << z);
        let first = |v: f64, origin: f64, count: u64| {
            (((v - origin) / size).floor().max(0.0) as u64).min(count - 1) as u32
        };
        // A tile that only touches the east or north edge is left out.
        let last = |v: f64, origin: f64, count: u64| {
            ((((v - origin) / size).ceil() - 1.0).max(0.0) as u64).min(count - 1) as u32
        };
        TileRange {
            z,
            x: [first(w, -180.0, columns), last(e, -180.0, columns)],
            y: [first(s, -90.0, rows), last(n, -90.0, rows)],
        }
    }

    pub fn contains(&self, t: TileId) -> bool {
        t.z == self.z
            && (self.x[0]..=self.x[1]).contains(&t.x)
            && (self.y[0]..=self.y[1]).contains(&t.y)
    }

    /// The tiles, row by row from the south-west.
    pub fn tiles(&self) -> impl Iterator<Item = TileId> + '_ {
        (self.y[0]..=self.y[1])
            .flat_map(move |y| (self.x[0]..=self.x[1]).map(move |x| TileId { z: self.z, x, y }))
    }

    /// The tiles it holds (at least one).
    pub fn tile_count(&self) -> usize {
        (self.x[1] - self.x[0] + 1) as usize * (self.y[1] - self.y[0] + 1) as usize
    }
}

/// The geometric error a client allows a tile of level `z`, metres: the
/// estimate for a 65-sample heightmap over the two level-0 tiles (a quarter
/// of the equator's length over 65 × 2 samples), halved each level — what
/// CesiumJS's terrain providers assume for quantized-mesh tiles.
pub fn level_geometric_error_m(z: u32) -> f64 {
    let level_zero = SEMI_MAJOR_AXIS_M * 2.0 * std::f64::consts::PI * 0.25 / (65.0 * 2.0);
    level_zero / f64::powi(2.0, z as i32)
}

/// The first level whose tiles' 64 sample intervals are no wider than
/// `cell_deg` degrees: the level that matches the source's resolution.
pub fn level_for_resolution(cell_deg: f64) -> u32 {
    (0..=24)
        .find(|&z| tile_size_deg(z) / 64.0 <= cell_deg)
        .unwrap_or(24)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_follow_the_geodetic_scheme() {
        assert_eq!(
            TileId { z: 0, x: 1, y: 0 }.bounds_deg(),
            [0.0, -90.0, 180.0, 90.0]
        );
        assert_eq!(
            TileId { z: 2, x: 3, y: 1 }.bounds_deg(),
            [-45.0, -45.0, 0.0, 0.0]
        );
        // Olinda (35° W, 8° S) at level 12.
        let r = TileRange::covering(12, [-34.95, -8.05, -34.85, -7.95]);
        for t in r.tiles() {
            let [w, s, e, n] = t.bounds_deg();
            assert!(w < -34.85 && e > -34.95 && s < -7.95 && n > -8.05, "{t:?}");
        }
        assert_eq!(r.tile_count(), 3 * 4);
        // A tile that only touches the range's edge is not in it.
        assert_eq!(
            TileRange::covering(2, [-45.0, -45.0, 0.0, 0.0]).tile_count(),
            1
        );
        assert_eq!(TileRange::covering(0, [1.0, 1.0, 2.0, 2.0]).tile_count(), 2);
        let child = TileId { z: 3, x: 5, y: 2 }.children()[3];
        assert_eq!(child, TileId { z: 4, x: 11, y: 5 });
    }

    #[test]
    fn geometric_error_halves_each_level() {
        // 6 378 137 · 2π / 4 / 130 ≈ 77 067 m at level 0.
        assert!((level_geometric_error_m(0) - 77_067.34).abs() < 0.01);
        assert_eq!(level_geometric_error_m(3) * 8.0, level_geometric_error_m(0));
        // 90 m cells at the equator ≈ 0.000 81°: level 12 (0.000 69° a sample).
        assert_eq!(level_for_resolution(0.000_81), 12);
    }
}
