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
            .next_power_of_two()
            .clamp(16, MAX_TEXTURE_SIDE)
    };
    (side(e - w), side(n - s))
}

/// The centres of a `width` × `height` texture's texels over `bounds_deg`,
/// row 0 north: longitude, latitude (degrees).
pub fn texel_centres(bounds_deg: [f64; 4], width: usize, height: usize) -> Vec<[f64; 2]> {
    let [w, s, e, n] = bounds_deg;
    (0..width * height)
        .map(|i| {
            let (col, row) = (i % width, i / width);
            [
                w + (col as f64 + 0.5) / width as f64 * (e - w),
                n - (row as f64 + 0.5) / height as f64 * (n - s),
            ]
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

/// The glb of the first `covered` triangles of `mesh` (a tile's patch, on
/// the ellipsoid), positions and normals in `frame` relative to the
/// content's centre, which the node's translation holds; `None` when the
/// tile covers no data. With the glb, the content's region.
pub fn glb(
    mesh: &SurfaceMesh,
    covered: usize,
    frame: &LocalFrame,
    texture: Option<&TileTexture>,
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
    let region = used.iter().fold(Region::EMPTY, |r, &v| {
        let [lon, lat] = mesh.lon_lat_deg[v];
        r.extend(lon, lat, mesh.height_m[v])
    });
    let local: Vec<[f64; 3]> = used
        .iter()
        .map(|&v| {
            let [lon, lat] = mesh.lon_lat_deg[v];
            frame.local(ecef_from_geodetic(lon, lat, mesh.height_m[v]))
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
    let index_accessor = glb.accessor(
        bytemuck::cast_slice(&indices),
        Some(ELEMENT_ARRAY_BUFFER),
        UNSIGNED_INT,
        indices.len() * 3,
        "SCALAR",
        json!({}),
    );
    doc["asset"] =
        json!({"version": "2.0", "generator": concat!("relevo ", env!("CARGO_PKG_VERSION"))});
    doc["scene"] = json!(0);
    doc["scenes"] = json!([{"nodes": [0]}]);
    doc["nodes"] = json!([{"mesh": 0, "translation": y_up(anchor)}]);
    doc["meshes"] = json!([{"primitives": [{
        "attributes": attributes, "indices": index_accessor, "mode": 4, "material": 0,
    }]}]);
    doc["materials"] = json!([material]);
    Ok(Some((glb.finish(doc)?, region)))
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
        let (bytes, region) = glb(&mesh, 2, &frame, None).unwrap().unwrap();
        let doc = document(&bytes).unwrap();
        assert_eq!(doc["accessors"][0]["count"], 4);
        assert_eq!(doc["accessors"][2]["count"], 6);
        assert_eq!((region.min_height_m, region.max_height_m), (10.0, 40.0));
        assert!((region.east_rad - (-34.89f64).to_radians()).abs() < 1e-15);
        // The node sits at the region's centre: ~550 m east, ~550 m north.
        let t = &doc["nodes"][0]["translation"];
        assert!((t[0].as_f64().unwrap() - 551.0).abs() < 3.0, "{t}");
        assert!((t[2].as_f64().unwrap() + 553.0).abs() < 3.0, "{t}");
        assert!(glb(&mesh, 0, &frame, None).unwrap().is_none());
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
        let centres = texel_centres([0.0, 0.0, 2.0, 1.0], 2, 1);
        assert_eq!(centres, [[0.5, 0.5], [1.5, 0.5]]);
        assert_eq!(texture_size([0.0, 0.0, 1.0, 0.01], 0.001), (256, 16));
        assert_eq!(texture_size([0.0, 0.0, 0.1, 0.04], 0.001), (128, 64));
        let jpeg = encode_jpeg(&[128; 16 * 16 * 3], 16, 16).unwrap();
        assert_eq!(&jpeg[..2], &[0xFF, 0xD8]);
    }
}
