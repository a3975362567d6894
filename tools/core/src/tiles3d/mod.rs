//! 3D Tiles 1.1 (OGC 22-025r4): the region's terrain as glb tiles with the
//! drape, its vegetation as instanced glb tiles, and the `tileset.json`
//! files that hold them together.
//!
//! - [`terrain`]: a terrain tile's glb, cut from the same meshes as the
//!   quantized-mesh tiles (`crate::terrain_tiles`), textured with JPEG.
//! - [`vegetation`]: the database's objects split by a quadtree, each
//!   tile one glb of class meshes instanced with `EXT_mesh_gpu_instancing`,
//!   per-instance metadata with `EXT_instance_features` and
//!   `EXT_structural_metadata`.
//! - [`tileset`]: the tile tree as `tileset.json` and external tilesets.
//!
//! Every content is written in one [`LocalFrame`] — east/north/up at the
//! region's centre — which the root tile's transform places on the Earth;
//! each glb node is translated to its tile so that `f32` positions keep
//! millimetres. Bounding volumes are regions (longitude, latitude and
//! ellipsoidal height), which no transform moves.

pub mod terrain;
pub mod tileset;
pub mod vegetation;

use crate::terrain_tiles::ellipsoid::{dot, east_north_up, ecef_from_geodetic};

/// East/north/up axes at a point of the ellipsoid, the frame tile content is
/// written in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalFrame {
    origin_ecef: [f64; 3],
    /// East, north and up, unit vectors in ECEF.
    axes: [[f64; 3]; 3],
}

impl LocalFrame {
    /// The frame at longitude, latitude (degrees) and height above the
    /// ellipsoid (metres).
    pub fn at(lon_deg: f64, lat_deg: f64, height_m: f64) -> LocalFrame {
        LocalFrame {
            origin_ecef: ecef_from_geodetic(lon_deg, lat_deg, height_m),
            axes: east_north_up(lon_deg, lat_deg),
        }
    }

    /// An ECEF point in the frame: metres east, north, up of the origin.
    pub fn local(&self, ecef: [f64; 3]) -> [f64; 3] {
        let d = [0, 1, 2].map(|k| ecef[k] - self.origin_ecef[k]);
        self.axes.map(|axis| dot(axis, d))
    }

    /// An ECEF direction in the frame.
    pub fn local_direction(&self, ecef: [f64; 3]) -> [f64; 3] {
        self.axes.map(|axis| dot(axis, ecef))
    }

    /// The root tile's transform: the frame to ECEF, a column-major 4 × 4
    /// matrix as `tileset.json` holds it.
    pub fn transform(&self) -> [f64; 16] {
        let [e, n, u] = self.axes;
        let o = self.origin_ecef;
        [
            e[0], e[1], e[2], 0.0, n[0], n[1], n[2], 0.0, u[0], u[1], u[2], 0.0, o[0], o[1], o[2],
            1.0,
        ]
    }
}

/// A point or direction east/north/up in glTF's axes: x east, y up, z south
/// (3D Tiles turns a glTF's y up to the tile's z up, §"glTF transforms").
pub fn y_up([east, north, up]: [f64; 3]) -> [f64; 3] {
    [east, up, -north]
}

/// A region bounding volume: longitude and latitude bounds (radians) and the
/// heights above the ellipsoid (metres) it spans.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    pub west_rad: f64,
    pub south_rad: f64,
    pub east_rad: f64,
    pub north_rad: f64,
    pub min_height_m: f64,
    pub max_height_m: f64,
}

impl Region {
    /// The empty region, which any [`Region::extend`] replaces.
    pub const EMPTY: Region = Region {
        west_rad: f64::INFINITY,
        south_rad: f64::INFINITY,
        east_rad: f64::NEG_INFINITY,
        north_rad: f64::NEG_INFINITY,
        min_height_m: f64::INFINITY,
        max_height_m: f64::NEG_INFINITY,
    };

    /// This region grown to hold the point at longitude, latitude (degrees)
    /// and `height_m`.
    pub fn extend(self, lon_deg: f64, lat_deg: f64, height_m: f64) -> Region {
        let (lon, lat) = (lon_deg.to_radians(), lat_deg.to_radians());
        Region {
            west_rad: self.west_rad.min(lon),
            south_rad: self.south_rad.min(lat),
            east_rad: self.east_rad.max(lon),
            north_rad: self.north_rad.max(lat),
            min_height_m: self.min_height_m.min(height_m),
            max_height_m: self.max_height_m.max(height_m),
        }
    }

    /// The smallest region holding both.
    pub fn union(self, other: Region) -> Region {
        Region {
            west_rad: self.west_rad.min(other.west_rad),
            south_rad: self.south_rad.min(other.south_rad),
            east_rad: self.east_rad.max(other.east_rad),
            north_rad: self.north_rad.max(other.north_rad),
            min_height_m: self.min_height_m.min(other.min_height_m),
            max_height_m: self.max_height_m.max(other.max_height_m),
        }
    }

    /// Whether `other` lies inside this region (what the tests check of
    /// the trees built).
    #[cfg(test)]
    pub fn contains(&self, other: &Region) -> bool {
        self.west_rad <= other.west_rad
            && self.south_rad <= other.south_rad
            && self.east_rad >= other.east_rad
            && self.north_rad >= other.north_rad
            && self.min_height_m <= other.min_height_m
            && self.max_height_m >= other.max_height_m
    }

    /// Whether no point was added (tests).
    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.west_rad > self.east_rad
    }

    /// The region's centre: longitude, latitude (degrees), middle height.
    pub fn centre(&self) -> [f64; 3] {
        [
            ((self.west_rad + self.east_rad) / 2.0).to_degrees(),
            ((self.south_rad + self.north_rad) / 2.0).to_degrees(),
            (self.min_height_m + self.max_height_m) / 2.0,
        ]
    }

    /// The `boundingVolume` of a tile.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({"region": [
            self.west_rad, self.south_rad, self.east_rad, self.north_rad,
            self.min_height_m, self.max_height_m,
        ]})
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_local_frame_and_its_transform_agree() {
        let frame = LocalFrame::at(-34.9, -8.0, 0.0);
        let p = ecef_from_geodetic(-34.89, -8.01, 120.0);
        let l = frame.local(p);
        // 0.01° east is ~1.1 km, 0.01° south ~1.1 km, and the Earth's curve
        // lowers a point 1.5 km away by ~0.2 m.
        assert!((l[0] - 1102.0).abs() < 5.0 && (l[1] + 1106.0).abs() < 5.0);
        assert!((l[2] - 120.0 + 0.19).abs() < 0.05, "{l:?}");
        // The transform takes the local point back to ECEF.
        let m = frame.transform();
        let back = [0, 1, 2].map(|k| m[k] * l[0] + m[4 + k] * l[1] + m[8 + k] * l[2] + m[12 + k]);
        assert!(
            (0..3).all(|k| (back[k] - p[k]).abs() < 1e-6),
            "{back:?} {p:?}"
        );
        assert_eq!(y_up([1.0, 2.0, 3.0]), [1.0, 3.0, -2.0]);
    }

    #[test]
    fn regions_grow_and_hold() {
        let a = Region::EMPTY
            .extend(10.0, 20.0, 5.0)
            .extend(11.0, 21.0, 7.0);
        assert!(Region::EMPTY.is_empty() && !a.is_empty());
        let b = Region::EMPTY.extend(10.5, 20.5, 6.0);
        assert!(a.contains(&b) && !b.contains(&a));
        assert!(a.union(b) == a);
        let c = a.centre();
        assert!((c[0] - 10.5).abs() < 1e-12 && (c[1] - 20.5).abs() < 1e-12 && c[2] == 6.0);
    }
}
