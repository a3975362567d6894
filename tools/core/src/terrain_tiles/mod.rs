//! Terrain tiles that other clients read: the region's LP mesh cut into
//! Cesium's geodetic tiling as quantized-mesh tiles, one level at a time.
//!
//! - [`tiling`]: the tiles of each level and the geometric error a client
//!   allows them.
//! - [`ellipsoid`]: WGS84 positions, local frames and horizon occlusion.
//! - [`clip`]: a level's mesh clipped to a tile, the rest of the tile
//!   filled, neighbours meeting exactly.
//! - [`quantized_mesh`]: a tile's bytes.
//!
//! Each level's mesh is the LP refinement at that level's geometric error,
//! so a tile is as accurate as the client assumes it is; with vertices on
//! the ellipsoid (longitude, latitude, ellipsoidal height) from PROJ, this
//! module needs neither GDAL nor a GPU.

pub mod clip;
pub mod ellipsoid;
pub mod quantized_mesh;
pub mod tiling;

use clip::{tile_patch, Coverage, SurfaceMesh};
use quantized_mesh::{WaterMask, WATER_MASK_SIDE};
use rayon::prelude::*;
use tiling::{TileId, TileRange};

/// A tile's mesh: the level's mesh clipped to it (the first `covered`
/// triangles) and the fill.
pub struct TilePatch {
    pub tile: TileId,
    pub mesh: SurfaceMesh,
    pub covered: usize,
}

/// `tile` cut from `mesh` (its level's mesh, or the part of it a window
/// of the grid holds around the tile).
pub fn patch(mesh: &SurfaceMesh, tile: TileId) -> TilePatch {
    let candidates: Vec<u32> = (0..mesh.triangles.len() as u32).collect();
    let (mesh, covered) = tile_patch(mesh, &candidates, tile.bounds_deg());
    TilePatch {
        tile,
        mesh,
        covered,
    }
}

/// The water mask of `patch`: water where the grid's `outline` (its
/// footprint's corners, degrees, in order) holds no data — texels inside
/// the outline that no covered triangle reaches; land elsewhere (outside
/// the grid nothing is known).
pub fn water_mask(patch: &TilePatch, outline: &[[f64; 2]]) -> WaterMask {
    let bounds = patch.tile.bounds_deg();
    let [w, s, e, n] = bounds;
    // Quick answers: a tile the data covers whole, or one clear of the outline.
    let m = &patch.mesh;
    let covered_area: f64 = m.triangles[..patch.covered]
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| m.lon_lat_deg[v as usize]);
            ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])) / 2.0
        })
        .sum();
    let outline_box = bounds_of(outline);
    let clear =
        outline_box[0] >= e || outline_box[2] <= w || outline_box[1] >= n || outline_box[3] <= s;
    if clear || covered_area >= (e - w) * (n - s) * (1.0 - 1e-9) {
        return WaterMask::Land;
    }
    let coverage = Coverage::new(&patch.mesh, patch.covered, bounds);
    let side = WATER_MASK_SIDE;
    let texels: Vec<u8> = (0..side * side)
        .into_par_iter()
        .map(|i| {
            let (col, row) = (i % side, i / side);
            let p = [
                w + (col as f64 + 0.5) / side as f64 * (e - w),
                n - (row as f64 + 0.5) / side as f64 * (n - s),
            ];
            let water = inside_polygon(outline, p) && !coverage.covers(&patch.mesh, p);
            if water {
                255
            } else {
                0
            }
        })
        .collect();
    if texels.iter().all(|&t| t == 0) {
        WaterMask::Land
    } else if texels.iter().all(|&t| t == 255) {
        WaterMask::Water
    } else {
        WaterMask::Texels(texels)
    }
}

/// `[west, south, east, north]` of `points` (degrees).
pub fn bounds_of(points: &[[f64; 2]]) -> [f64; 4] {
    points.iter().fold(
        [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ],
        |b, p| {
            [
                b[0].min(p[0]),
                b[1].min(p[1]),
                b[2].max(p[0]),
                b[3].max(p[1]),
            ]
        },
    )
}

/// Whether `p` lies inside `polygon` (even–odd rule).
fn inside_polygon(polygon: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut inside = false;
    for i in 0..polygon.len() {
        let (a, b) = (polygon[i], polygon[(i + 1) % polygon.len()]);
        if (a[1] > p[1]) != (b[1] > p[1])
            && p[0] < a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0])
        {
            inside = !inside;
        }
    }
    inside
}

/// `available` rectangles in `layer.json`'s and the metadata extension's
/// form.
pub fn available_json(ranges: &[TileRange]) -> serde_json::Value {
    serde_json::Value::Array(
        ranges
            .iter()
            .map(|r| serde_json::json!([{ "startX": r.x[0], "startY": r.y[0], "endX": r.x[1], "endY": r.y[1] }]))
            .collect(),
    )
}

/// The metadata extension's `available` list for `tile`: its children in
/// `next` (the next level's available range; `None` past the last level).
/// Every tile carries one, empty where no child exists, since a client that
/// reads availability from tiles (`metadataAvailability` 1 in
/// `layer.json`) waits for each tile's word on its children.
pub fn children_available(tile: TileId, next: Option<&TileRange>) -> serde_json::Value {
    let Some(next) = next else {
        return serde_json::json!([]);
    };
    let inside: Vec<TileId> = tile
        .children()
        .into_iter()
        .filter(|c| next.contains(*c))
        .collect();
    let (Some(x0), Some(x1), Some(y0), Some(y1)) = (
        inside.iter().map(|c| c.x).min(),
        inside.iter().map(|c| c.x).max(),
        inside.iter().map(|c| c.y).min(),
        inside.iter().map(|c| c.y).max(),
    ) else {
        return serde_json::json!([[]]);
    };
    available_json(&[TileRange {
        z: tile.z + 1,
        x: [x0, x1],
        y: [y0, y1],
    }])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_level_is_cut_into_tiles_that_cover_them() {
        // A 0.3° square mesh straddling a level-10 tile line.
        let mesh = SurfaceMesh {
            lon_lat_deg: vec![[-35.1, -8.1], [-34.8, -8.1], [-34.8, -7.8], [-35.1, -7.8]],
            height_m: vec![10.0, 20.0, 30.0, 40.0],
            normal: vec![[0.0, 0.0, 1.0]; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        let range = TileRange::covering(10, bounds_of(&mesh.lon_lat_deg));
        let patches: Vec<TilePatch> = range.tiles().map(|t| patch(&mesh, t)).collect();
        assert_eq!(patches.len(), range.tile_count());
        for p in &patches {
            let [w, s, e, n] = p.tile.bounds_deg();
            let area: f64 = p
                .mesh
                .triangles
                .iter()
                .map(|&t| {
                    let [a, b, c] = t.map(|v| p.mesh.lon_lat_deg[v as usize]);
                    ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])) / 2.0
                })
                .sum();
            assert!(
                (area - (e - w) * (n - s)).abs() < 1e-9 * (e - w) * (n - s),
                "{:?}",
                p.tile
            );
        }
        let outline = [[-35.1, -8.1], [-34.8, -8.1], [-34.8, -7.8], [-35.1, -7.8]];
        assert!(patches
            .iter()
            .all(|p| water_mask(p, &outline) == WaterMask::Land));
        let next = TileRange::covering(11, bounds_of(&mesh.lon_lat_deg));
        let first = children_available(patches[0].tile, Some(&next));
        assert!(first[0][0]["startX"].as_u64().is_some());
        let far = TileId { z: 10, x: 0, y: 0 };
        assert_eq!(
            children_available(far, Some(&next)),
            serde_json::json!([[]])
        );
        assert_eq!(children_available(far, None), serde_json::json!([]));
    }
}
