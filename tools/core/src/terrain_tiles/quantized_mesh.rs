//! The quantized-mesh-1.0 tile encoding (Cesium's terrain format): a header
//! of bounding information, vertices as zig-zag deltas of 15-bit u, v and
//! height, indices in high-water-mark order, the vertices on each edge, and
//! the extensions — oct-encoded normals (1), the water mask (2) and
//! metadata with the children's availability (4). All little-endian.

use super::clip::SurfaceMesh;
use super::ellipsoid::{ecef_from_geodetic, horizon_occlusion_point, norm};
use super::tiling::TileId;

/// The largest quantized u, v or height.
pub const MAX_QUANTIZED: u16 = 32767;

/// Extension ids of the format.
const OCT_NORMALS: u8 = 1;
const WATER_MASK: u8 = 2;
const METADATA: u8 = 4;

/// Side of a water mask, texels.
pub const WATER_MASK_SIDE: usize = 256;

/// A tile's water: all land, all water, or 256² texels (255 water, 0 land;
/// rows from the north).
#[derive(Debug, Clone, PartialEq)]
pub enum WaterMask {
    Land,
    Water,
    Texels(Vec<u8>),
}

/// What a tile holds besides its mesh.
pub struct TileExtras<'a> {
    /// Heights every tile quantizes over, metres: one range for all tiles,
    /// so a vertex two tiles share decodes to the same height in both.
    pub height_range_m: [f64; 2],
    pub water: WaterMask,
    /// The available tiles of the next level under this one, as the
    /// metadata extension's `available` list.
    pub children_available: &'a serde_json::Value,
}

/// Encode `patch` as tile `tile`.
pub fn encode(tile: TileId, patch: &SurfaceMesh, extras: &TileExtras) -> Vec<u8> {
    let [west, south, east, north] = tile.bounds_deg();
    // Vertices renumbered by first use, as high-water-mark indices need.
    let mut new_of = vec![u32::MAX; patch.lon_lat_deg.len()];
    let mut order: Vec<u32> = Vec::with_capacity(patch.lon_lat_deg.len());
    let triangles: Vec<[u32; 3]> = patch
        .triangles
        .iter()
        .map(|t| {
            t.map(|v| {
                if new_of[v as usize] == u32::MAX {
                    new_of[v as usize] = order.len() as u32;
                    order.push(v);
                }
                new_of[v as usize]
            })
        })
        .collect();
    let quantize = |value: f64, lo: f64, hi: f64| -> u16 {
        let t = if hi > lo {
            (value - lo) / (hi - lo)
        } else {
            0.0
        };
        (t.clamp(0.0, 1.0) * MAX_QUANTIZED as f64).round() as u16
    };
    let [h0, h1] = extras.height_range_m;
    let uvh: Vec<[u16; 3]> = order
        .iter()
        .map(|&v| {
            let [lon, lat] = patch.lon_lat_deg[v as usize];
            [
                quantize(lon, west, east),
                quantize(lat, south, north),
                quantize(patch.height_m[v as usize], h0, h1),
            ]
        })
        .collect();

    let mut out = Vec::new();
    write_header(&mut out, tile, patch, &order, extras.height_range_m);
    out.extend((uvh.len() as u32).to_le_bytes());
    for k in 0..3 {
        let mut previous = 0i32;
        for q in &uvh {
            let delta = q[k] as i32 - previous;
            previous = q[k] as i32;
            out.extend((zig_zag(delta) as u16).to_le_bytes());
        }
    }
    let wide = uvh.len() > 65536;
    let write_index = |out: &mut Vec<u8>, i: u32| {
        if wide {
            out.extend(i.to_le_bytes());
        } else {
            out.extend((i as u16).to_le_bytes());
        }
    };
    if wide {
        while out.len() % 4 != 0 {
            out.push(0);
        }
    }
    out.extend((triangles.len() as u32).to_le_bytes());
    let mut highest = 0u32;
    for &i in triangles.iter().flatten() {
        write_index(&mut out, highest - i);
        if i == highest {
            highest += 1;
        }
    }
    // West (u = 0), south (v = 0), east, north: along the edge.
    let edges: [(usize, u16, usize); 4] = [
        (0, 0, 1),
        (1, 0, 0),
        (0, MAX_QUANTIZED, 1),
        (1, MAX_QUANTIZED, 0),
    ];
    for (axis, value, along) in edges {
        let mut on: Vec<u32> = (0..uvh.len() as u32)
            .filter(|&i| uvh[i as usize][axis] == value)
            .collect();
        on.sort_by_key(|&i| (uvh[i as usize][along], i));
        out.extend((on.len() as u32).to_le_bytes());
        for i in on {
            write_index(&mut out, i);
        }
    }
    // Extensions.
    let mut normals = Vec::with_capacity(2 * order.len());
    for &v in &order {
        normals.extend(oct_encode(patch.normal[v as usize]));
    }
    write_extension(&mut out, OCT_NORMALS, &normals);
    match &extras.water {
        WaterMask::Land => write_extension(&mut out, WATER_MASK, &[0]),
        WaterMask::Water => write_extension(&mut out, WATER_MASK, &[255]),
        WaterMask::Texels(t) => write_extension(&mut out, WATER_MASK, t),
    }
    let json = serde_json::json!({ "available": extras.children_available }).to_string();
    let mut data = (json.len() as u32).to_le_bytes().to_vec();
    data.extend(json.as_bytes());
    write_extension(&mut out, METADATA, &data);
    out
}

/// The 88-byte header: centre, height range, bounding sphere, horizon
/// occlusion point (doubles and floats).
fn write_header(
    out: &mut Vec<u8>,
    tile: TileId,
    patch: &SurfaceMesh,
    order: &[u32],
    [h0, h1]: [f64; 2],
) {
    let [w, s, e, n] = tile.bounds_deg();
    let centre = ecef_from_geodetic((w + e) / 2.0, (s + n) / 2.0, (h0 + h1) / 2.0);
    let points: Vec<[f64; 3]> = order
        .iter()
        .map(|&v| {
            let [lon, lat] = patch.lon_lat_deg[v as usize];
            ecef_from_geodetic(lon, lat, patch.height_m[v as usize])
        })
        .collect();
    let mut low = [f64::INFINITY; 3];
    let mut high = [f64::NEG_INFINITY; 3];
    for p in &points {
        for k in 0..3 {
            low[k] = low[k].min(p[k]);
            high[k] = high[k].max(p[k]);
        }
    }
    let sphere_centre = [0, 1, 2].map(|k| (low[k] + high[k]) / 2.0);
    let radius = points
        .iter()
        .map(|p| norm([0, 1, 2].map(|k| p[k] - sphere_centre[k])))
        .fold(0.0, f64::max);
    // A tile a point of which sees past the horizon (a level-0 tile) is
    // never occluded: the point at the centre's direction, far out.
    let occlusion = horizon_occlusion_point(&points, sphere_centre).unwrap_or_else(|| {
        let d = super::ellipsoid::unit(sphere_centre).unwrap_or([1.0, 0.0, 0.0]);
        d.map(|c| c * 1e3)
    });
    for v in centre {
        out.extend(v.to_le_bytes());
    }
    out.extend((h0 as f32).to_le_bytes());
    out.extend((h1 as f32).to_le_bytes());
    for v in sphere_centre {
        out.extend(v.to_le_bytes());
    }
    out.extend(radius.to_le_bytes());
    for v in occlusion {
        out.extend(v.to_le_bytes());
    }
}

fn write_extension(out: &mut Vec<u8>, id: u8, data: &[u8]) {
    out.push(id);
    out.extend((data.len() as u32).to_le_bytes());
    out.extend(data);
}

/// Zig-zag: small magnitudes of either sign to small unsigned numbers.
fn zig_zag(v: i32) -> u32 {
    ((v << 1) ^ (v >> 31)) as u32
}

/// A unit vector as two bytes: projected on the octahedron |x|+|y|+|z| = 1,
/// the lower half folded over the upper, each coordinate mapped from
/// [−1, 1] to [0, 255] (Meyer et al. 2010, "On floating-point normal
/// vectors").
pub fn oct_encode(n: [f64; 3]) -> [u8; 2] {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    let (mut x, mut y) = if l1 > 0.0 {
        (n[0] / l1, n[1] / l1)
    } else {
        (0.0, 0.0)
    };
    if n[2] < 0.0 {
        let (fx, fy) = ((1.0 - y.abs()) * sign(x), (1.0 - x.abs()) * sign(y));
        x = fx;
        y = fy;
    }
    [x, y].map(|c| ((c.clamp(-1.0, 1.0) * 0.5 + 0.5) * 255.0).round() as u8)
}

fn sign(v: f64) -> f64 {
    if v < 0.0 {
        -1.0
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zig_zag_and_oct_encoding() {
        assert_eq!([0, -1, 1, -2, 2].map(zig_zag), [0, 1, 2, 3, 4]);
        assert_eq!(oct_encode([0.0, 0.0, 1.0]), [128, 128]);
        assert_eq!(oct_encode([1.0, 0.0, 0.0]), [255, 128]);
        // The lower hemisphere folds to the corners.
        assert_eq!(oct_encode([0.0, 0.0, -1.0]), [255, 255]);
    }

    #[test]
    fn a_tile_encodes_its_parts_in_order() {
        let tile = TileId { z: 0, x: 0, y: 0 };
        let patch = SurfaceMesh {
            lon_lat_deg: vec![[-180.0, -90.0], [0.0, -90.0], [0.0, 90.0], [-180.0, 90.0]],
            height_m: vec![0.0, 100.0, 50.0, 0.0],
            normal: vec![[1.0, 0.0, 0.0]; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        let extras = TileExtras {
            height_range_m: [0.0, 100.0],
            water: WaterMask::Land,
            children_available: &serde_json::json!([]),
        };
        let bytes = encode(tile, &patch, &extras);
        let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
        let u16_at = |i: usize| u16::from_le_bytes(bytes[i..i + 2].try_into().unwrap());
        assert_eq!(u32_at(88), 4);
        // u: 0, 32767, 32767, 0 as zig-zag deltas.
        assert_eq!(
            [u16_at(92), u16_at(94), u16_at(96), u16_at(98)],
            [0, 65534, 0, 65533]
        );
        let triangles_at = 92 + 4 * 6;
        assert_eq!(u32_at(triangles_at), 2);
        // 0 1 2 0 2 3 in high-water-mark codes.
        let codes: Vec<u16> = (0..6).map(|k| u16_at(triangles_at + 4 + 2 * k)).collect();
        assert_eq!(codes, [0, 0, 0, 3, 1, 0]);
        // West edge: vertices 0 and 3.
        let west = triangles_at + 4 + 12;
        assert_eq!(u32_at(west), 2);
        assert_eq!([u16_at(west + 4), u16_at(west + 6)], [0, 3]);
        // Then the water mask's one byte and the metadata.
        let json = br#"{"available":[]}"#;
        let tail = bytes.len() - json.len() - 4 - 5;
        assert_eq!(&bytes[tail - 6..tail], &[WATER_MASK, 1, 0, 0, 0, 0]);
        assert_eq!(bytes[tail], METADATA);
        assert_eq!(&bytes[bytes.len() - json.len()..], json);
    }
}
