//! A terrain tile as glb: the triangles of its level's mesh that the tile
//! covers (the quantized-mesh tile's, without the fill: 3D Tiles content
//! may leave the globe showing where there is no data), in the tileset's
//! [`LocalFrame`], with the drape as a JPEG texture.

use super::{y_up, LocalFrame, Region};
use crate::gltf::{Glb, ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, FLOAT, UNSIGNED_INT};
use crate::lp::export::DrapeImage;
use crate::terrain_tiles::clip::SurfaceMesh;
use crate::terrain_tiles::ellipsoid::ecef_from_geodetic;
use crate::{Error, Result};
use serde_json::json;

/// A tile's texture: JPEG bytes spanning `bounds_deg` (`[west, south, east,
/// north]`), north up.
pub struct TileTexture {
    pub jpeg: Vec<u8>,
    pub bounds_deg: [f64; 4],
}

/// Largest side of a tile's texture, texels (CesiumJS's imagery tiles are
/// 256; the drape's own resolution is not exceeded).
pub const MAX_TEXTURE_SIDE: usize = 256;

/// JPEG quality of textures: 85 keeps a Landsat drape's detail at about a
/// tenth of PNG's bytes.
const JPEG_QUALITY: u8 = 85;

/// Texture size for a tile spanning `bounds_deg`, when the drape's pixels
/// are `drape_pixel_deg` wide: as many texels as the drape has pixels across
/// the tile, rounded up to a power of two (which WebGL 1 clients need to
/// mipmap), from 16 to [`MAX_TEXTURE_SIDE`] a side.
pub fn texture_size(bounds_deg: [f64; 4], drape_pixel_deg: f64) -> (usize, usize) {
    let [w, s, e, n] = bounds_deg;
    let side = |span: f64| {
        ((span / drape_pixel_deg).ceil() as usize)
            .clamp(16, MAX_TEXTURE_SIDE)
            .next_power_of_two()
    };
    (side(e - w), side(n - s))
}

/// Cells a side of the lattice texels are placed by: their CRS positions
/// are interpolated between the exact transforms of its
/// (`LATTICE_CELLS` + 1)² points (as GDAL's warper approximates its
/// transforms), instead of one PROJ call a texel.
pub const LATTICE_CELLS: usize = 16;

/// The lattice's points over `bounds_deg`: longitude, latitude (degrees),
/// row 0 north, [`LATTICE_CELLS`] + 1 a row.
pub fn lattice(bounds_deg: [f64; 4]) -> Vec<[f64; 2]> {
    let [w, s, e, n] = bounds_deg;
    let side = LATTICE_CELLS + 1;
    (0..side * side)
        .map(|i| {
            let (col, row) = (i % side, i / side);
            [
                w + col as f64 / LATTICE_CELLS as f64 * (e - w),
                n - row as f64 / LATTICE_CELLS as f64 * (n - s),
            ]
        })
        .collect()
}

/// The CRS positions of a `width` × `height` texture's texel centres (row 0
/// north), bilinear between `lattice_world`: the [`lattice`]'s points in
/// the CRS.
pub fn texel_world(width: usize, height: usize, lattice_world: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let side = LATTICE_CELLS + 1;
    let at = |col: usize, row: usize| lattice_world[row * side + col];
    (0..width * height)
        .map(|i| {
            let u = ((i % width) as f64 + 0.5) / width as f64 * LATTICE_CELLS as f64;
            let v = ((i / width) as f64 + 0.5) / height as f64 * LATTICE_CELLS as f64;
            let (c, r) = (
                (u as usize).min(LATTICE_CELLS - 1),
                (v as usize).min(LATTICE_CELLS - 1),
            );
            let (fu, fv) = (u - c as f64, v - r as f64);
            let [a, b, d, e] = [at(c, r), at(c + 1, r), at(c, r + 1), at(c + 1, r + 1)];
            [0, 1].map(|k| {
                let top = a[k] * (1.0 - fu) + b[k] * fu;
                let bottom = d[k] * (1.0 - fu) + e[k] * fu;
                top * (1.0 - fv) + bottom * fv
            })
        })
        .collect()
}

/// RGB of `drape` at world points (the drape's CRS), bilinear between its
/// pixel centres, clamped at its edges.
pub fn drape_rgb(drape: &DrapeImage, world: &[[f64; 2]]) -> Vec<u8> {
    let mut out = Vec::with_capacity(world.len() * 3);
    let (w, h) = (drape.width, drape.height);
    for p in world {
        let (x, y) = drape.geotransform.invert(p[0], p[1]).unwrap_or((0.0, 0.0));
        let (x, y) = (
            (x - 0.5).clamp(0.0, (w - 1) as f64),
            (y - 0.5).clamp(0.0, (h - 1) as f64),
        );
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let texel = |x: usize, y: usize, k: usize| drape.rgba[4 * (y * w + x) + k] as f64;
        for k in 0..3 {
            let top = texel(x0, y0, k) * (1.0 - fx) + texel(x1, y0, k) * fx;
            let bottom = texel(x0, y1, k) * (1.0 - fx) + texel(x1, y1, k) * fx;
            out.push((top * (1.0 - fy) + bottom * fy).round() as u8);
        }
    }
    out
}

/// RGB texels as JPEG.
pub fn encode_jpeg(rgb: &[u8], width: usize, height: usize) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, JPEG_QUALITY)
        .encode(
            rgb,
            width as u32,
            height as u32,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| Error::Input(format!("JPEG encoding: {e}")))?;
    Ok(out)
}

/// Where a tile's skirts go: walls hanging from the mesh's edges along the
/// tile's sides, which hide the gaps between neighbours drawn at
/// different levels (a client's refinement picks each tile's level).
#[derive(Debug, Clone, Copy)]
pub struct Skirt {
    /// The tile's `[west, south, east, north]`, degrees: edges on these
    /// lines get a skirt.
    pub bounds_deg: [f64; 4],
    /// How far down the walls hang, metres.
    pub depth_m: f64,
}

/// Skirt depth for a tile of a level with geometric error `level_error_m`:
/// five times it, CesiumJS's convention for its own terrain's skirts (a
/// neighbour a couple of levels coarser stays covered).
pub fn skirt_depth_m(level_error_m: f64) -> f64 {
    5.0 * level_error_m
}

/// The glb of the first `covered` triangles of `mesh` (a tile's patch, on
/// the ellipsoid), positions and normals in `frame` relative to the
/// content's centre, which the node's translation holds, and its skirts
/// as a second primitive; `None` when the tile covers no data. With the
/// glb, the content's region.
pub fn glb(
    mesh: &SurfaceMesh,
    covered: usize,
    frame: &LocalFrame,
    texture: Option<&TileTexture>,
    skirt: Skirt,
) -> Result<Option<(Vec<u8>, Region)>> {
    let triangles = &mesh.triangles[..covered.min(mesh.triangles.len())];
    if triangles.is_empty() {
        return Ok(None);
    }
    // The vertices the covered triangles use, renumbered in first use.
    let mut number = vec![u32::MAX; mesh.lon_lat_deg.len()];
    let mut used = Vec::new();
    let indices: Vec<[u32; 3]> = triangles
        .iter()
        .map(|t| {
            t.map(|v| {
                let slot = &mut number[v as usize];
                if *slot == u32::MAX {
                    *slot = used.len() as u32;
                    used.push(v as usize);
                }
                *slot
            })
        })
        .collect();
    // Vertices `used` (mesh numbering) with their heights: the surface's,
    // then each skirt vertex below its edge vertex.
    let (skirt_triangles, below) = skirts(mesh, &indices, &used, skirt.bounds_deg);
    let mut heights: Vec<f64> = used.iter().map(|&v| mesh.height_m[v]).collect();
    let surface_count = used.len();
    for &k in &below {
        heights.push(heights[k as usize] - skirt.depth_m);
        used.push(used[k as usize]);
    }
    let skirt_triangles: Vec<[u32; 3]> = skirt_triangles
        .iter()
        .map(|t| {
            t.map(|k| {
                if k < 0 {
                    surface_count as u32 + (-k - 1) as u32
                } else {
                    k as u32
                }
            })
        })
        .collect();
    let region = used
        .iter()
        .zip(&heights)
        .fold(Region::EMPTY, |r, (&v, &h)| {
            let [lon, lat] = mesh.lon_lat_deg[v];
            r.extend(lon, lat, h)
        });
    let local: Vec<[f64; 3]> = used
        .iter()
        .zip(&heights)
        .map(|(&v, &h)| {
            let [lon, lat] = mesh.lon_lat_deg[v];
            frame.local(ecef_from_geodetic(lon, lat, h))
        })
        .collect();
    let anchor = {
        let c = region.centre();
        frame.local(ecef_from_geodetic(c[0], c[1], c[2]))
    };
    let positions: Vec<[f32; 3]> = local
        .iter()
        .map(|p| y_up([0, 1, 2].map(|k| p[k] - anchor[k])).map(|v| v as f32))
        .collect();
    let normals: Vec<[f32; 3]> = used
        .iter()
        .map(|&v| y_up(frame.local_direction(mesh.normal[v])).map(|v| v as f32))
        .collect();

    let mut glb = Glb::default();
    let mut attributes = json!({
        "POSITION": glb.vec3(&positions, Some(ARRAY_BUFFER)),
        "NORMAL": glb.vec3(&normals, Some(ARRAY_BUFFER)),
    });
    let mut material = json!({
        "pbrMetallicRoughness": {"baseColorFactor": [0.55, 0.55, 0.55, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
    });
    let mut doc = json!({});
    if let Some(t) = texture {
        let [w, s, e, n] = t.bounds_deg;
        let uvs: Vec<[f32; 2]> = used
            .iter()
            .map(|&v| {
                let [lon, lat] = mesh.lon_lat_deg[v];
                [((lon - w) / (e - w)) as f32, ((n - lat) / (n - s)) as f32]
            })
            .collect();
        attributes["TEXCOORD_0"] = json!(glb.accessor(
            bytemuck::cast_slice(&uvs),
            Some(ARRAY_BUFFER),
            FLOAT,
            uvs.len(),
            "VEC2",
            json!({})
        ));
        let view = glb.view(&t.jpeg, None);
        doc["images"] = json!([{"bufferView": view, "mimeType": "image/jpeg"}]);
        doc["samplers"] =
            json!([{"magFilter": 9729, "minFilter": 9729, "wrapS": 33071, "wrapT": 33071}]);
        doc["textures"] = json!([{"sampler": 0, "source": 0}]);
        material["pbrMetallicRoughness"]["baseColorFactor"] = json!([1.0, 1.0, 1.0, 1.0]);
        material["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    }
    let mut primitives = Vec::new();
    for triangles in [&indices, &skirt_triangles] {
        if triangles.is_empty() {
            continue;
        }
        let accessor = glb.accessor(
            bytemuck::cast_slice(triangles),
            Some(ELEMENT_ARRAY_BUFFER),
            UNSIGNED_INT,
            triangles.len() * 3,
            "SCALAR",
            json!({}),
        );
        primitives
            .push(json!({"attributes": attributes, "indices": accessor, "mode": 4, "material": 0}));
    }
    doc["asset"] =
        json!({"version": "2.0", "generator": concat!("relevo ", env!("CARGO_PKG_VERSION"))});
    doc["scene"] = json!(0);
    doc["scenes"] = json!([{"nodes": [0]}]);
    doc["nodes"] = json!([{"mesh": 0, "translation": y_up(anchor)}]);
    doc["meshes"] = json!([{ "primitives": primitives }]);
    doc["materials"] = json!([material]);
    Ok(Some((glb.finish(doc)?, region)))
}

/// The skirt of a tile's triangles `indices` (over vertices `used`, the
/// mesh's numbering): triangles with skirt vertices numbered −1, −2, …
/// (the vertex below surface vertex `below[k]` is −(k + 1)), and `below`.
/// A wall hangs from every edge that one triangle alone has and that lies
/// on a side of `bounds_deg`, facing out.
fn skirts(
    mesh: &SurfaceMesh,
    indices: &[[u32; 3]],
    used: &[usize],
    [w, s, e, n]: [f64; 4],
) -> (Vec<[i64; 3]>, Vec<u32>) {
    let mut uses: std::collections::BTreeMap<(u32, u32), (usize, [u32; 2])> =
        std::collections::BTreeMap::new();
    for t in indices {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            uses.entry((a.min(b), a.max(b))).or_insert((0, [a, b])).0 += 1;
        }
    }
    let on_side = |a: u32, b: u32| {
        let [p, q] = [a, b].map(|k| mesh.lon_lat_deg[used[k as usize]]);
        (p[0] == w && q[0] == w)
            || (p[0] == e && q[0] == e)
            || (p[1] == s && q[1] == s)
            || (p[1] == n && q[1] == n)
    };
    let mut below: Vec<u32> = Vec::new();
    let mut slot = std::collections::BTreeMap::new();
    let mut under = |k: u32| -> i64 {
        let next = below.len();
        let i = *slot.entry(k).or_insert_with(|| {
            below.push(k);
            next
        });
        -(i as i64) - 1
    };
    let mut triangles = Vec::new();
    for (count, [a, b]) in uses.values() {
        if *count != 1 || !on_side(*a, *b) {
            continue;
        }
        // a → b has the surface on its left; seen from outside, the wall
        // runs a′, b′, b, a counter-clockwise.
        let (a2, b2) = (under(*a), under(*b));
        triangles.push([a2, b2, *b as i64]);
        triangles.push([a2, *b as i64, *a as i64]);
    }
    (triangles, below)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::GeoTransform;
    use crate::gltf::document;
    use std::borrow::Cow;

    #[test]
    fn a_tile_keeps_its_covered_triangles_in_the_local_frame() {
        // Two triangles covered, one of the fill after them.
        let mesh = SurfaceMesh {
            lon_lat_deg: vec![
                [-34.90, -8.00],
                [-34.89, -8.00],
                [-34.89, -7.99],
                [-34.90, -7.99],
                [-34.88, -7.98],
            ],
            height_m: vec![10.0, 20.0, 30.0, 40.0, 0.0],
            normal: vec![[0.0, 0.0, 1.0]; 5],
            triangles: vec![[0, 1, 2], [0, 2, 3], [2, 1, 4]],
        };
        let frame = LocalFrame::at(-34.9, -8.0, 0.0);
        // The tile's west and south sides run along the square's.
        let skirt = Skirt {
            bounds_deg: [-34.90, -8.00, -34.85, -7.95],
            depth_m: 50.0,
        };
        let (bytes, region) = glb(&mesh, 2, &frame, None, skirt).unwrap().unwrap();
        let doc = document(&bytes).unwrap();
        // 4 surface vertices and 3 below the two sides' 3 vertices; 2
        // surface triangles, then 2 walls of 2 triangles.
        assert_eq!(doc["accessors"][0]["count"], 7);
        assert_eq!(doc["accessors"][2]["count"], 6);
        assert_eq!(doc["accessors"][3]["count"], 12);
        assert_eq!((region.min_height_m, region.max_height_m), (-40.0, 40.0));
        assert!((region.east_rad - (-34.89f64).to_radians()).abs() < 1e-15);
        // The node sits at the region's centre: ~550 m east, ~550 m north.
        let t = &doc["nodes"][0]["translation"];
        assert!((t[0].as_f64().unwrap() - 551.0).abs() < 3.0, "{t}");
        assert!((t[2].as_f64().unwrap() + 553.0).abs() < 3.0, "{t}");
        assert!(glb(&mesh, 0, &frame, None, skirt).unwrap().is_none());
    }

    #[test]
    fn textures_sample_the_drape_between_pixel_centres() {
        // A 2 × 1 drape, black then white, 10 m pixels from (0, 10).
        let drape = DrapeImage {
            rgba: Cow::Owned(vec![0, 0, 0, 255, 255, 255, 255, 255]),
            width: 2,
            height: 1,
            geotransform: GeoTransform([0.0, 10.0, 0.0, 10.0, 0.0, -10.0]),
        };
        let rgb = drape_rgb(&drape, &[[5.0, 5.0], [10.0, 5.0], [15.0, 5.0], [-3.0, 5.0]]);
        assert_eq!(rgb, [0, 0, 0, 128, 128, 128, 255, 255, 255, 0, 0, 0]);
        // Through an affine map, interpolation is exact.
        let bounds = [10.0, 40.0, 12.0, 41.0];
        let world: Vec<[f64; 2]> = lattice(bounds)
            .iter()
            .map(|p| [1000.0 * p[0] + 5.0, -2000.0 * p[1]])
            .collect();
        let texels = texel_world(4, 2, &world);
        assert!((texels[0][0] - (1000.0 * 10.25 + 5.0)).abs() < 1e-6);
        assert!((texels[0][1] - (-2000.0 * 40.75)).abs() < 1e-6);
        assert!((texels[7][0] - (1000.0 * 11.75 + 5.0)).abs() < 1e-6);
        assert!((texels[7][1] - (-2000.0 * 40.25)).abs() < 1e-6);
        assert_eq!(texture_size([0.0, 0.0, 1.0, 0.01], 0.001), (256, 16));
        assert_eq!(texture_size([0.0, 0.0, 0.1, 0.04], 0.001), (128, 64));
        assert_eq!(texture_size([0.0, 0.0, 1.0, 1.0], 0.0), (256, 256));
        let jpeg = encode_jpeg(&[128; 16 * 16 * 3], 16, 16).unwrap();
        assert_eq!(&jpeg[..2], &[0xFF, 0xD8]);
    }
}
