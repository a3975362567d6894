//! Export of the view-independent mesh at an object-space tolerance as
//! glTF 2.0 (binary) or Wavefront OBJ, with normals and the drape image as
//! texture.
//!
//! Both formats are written y-up (x east, y up, z south), as glTF requires
//! and most OBJ readers assume. Vertex positions are local to the grid's
//! south-west vertex so that f32 keeps centimetres; the world origin goes in
//! the glTF node's translation and in an OBJ comment.

use super::extract::extract;
use super::hierarchy::Hierarchy;
use super::vertices::terrain_position;
use crate::geo::{GeoTransform, TerrainFrame};
use crate::grid::vertex_normal;
use crate::raster::png::encode_rgba;
use crate::{Error, Result};
use serde_json::json;
use std::io::Write;

/// Mesh arrays ready to write.
pub struct ExportMesh {
    /// y-up positions, metres from the grid's south-west vertex.
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    /// Texture coordinates into the drape image, when there is one.
    pub uvs: Option<Vec<[f32; 2]>>,
    /// Counter-clockwise seen from above.
    pub triangles: Vec<[u32; 3]>,
    /// World coordinates (CRS units) of the local origin: east, north.
    pub origin: [f64; 2],
    /// The drape image as PNG bytes.
    pub texture_png: Option<Vec<u8>>,
    /// The largest vertical distance between a grid point under the mesh
    /// and the mesh, metres (measured, whatever the bundle's error metric).
    pub largest_deviation_m: f64,
}

/// The terrain a mesh is exported from: the grid's frame, heights (metres),
/// data mask, LP hierarchy and, when there is one, the drape.
pub struct Surface<'a> {
    pub frame: TerrainFrame,
    pub heights: &'a [f32],
    pub mask: &'a [u8],
    pub hierarchy: Hierarchy<'a>,
    pub drape: Option<DrapeImage<'a>>,
}

/// The image an exported mesh is textured with: RGBA8 texels,
/// `width`×`height`, placed in the world by `geotransform`.
pub struct DrapeImage<'a> {
    pub rgba: &'a [u8],
    pub width: usize,
    pub height: usize,
    pub geotransform: GeoTransform,
}

/// Build the mesh of `surface` at `max_error` metres.
pub fn build(surface: &Surface, max_error: f32, keep_padding: bool) -> Result<ExportMesh> {
    let Surface {
        frame,
        heights,
        mask,
        hierarchy,
        drape,
    } = surface;
    let side = frame.side;
    let grid = extract(hierarchy, max_error, (!keep_padding).then_some(mask));
    if grid.triangles.is_empty() {
        return Err(Error::Input("no triangles: the mask covers no data".into()));
    }
    let cell = frame.cell_size_m;
    let position = |c: usize, r: usize| {
        let p = terrain_position(c, r, side, cell, heights[r * side + c] as f64);
        [p[0] as f32, p[2] as f32, -p[1] as f32]
    };
    let positions: Vec<[f32; 3]> = grid
        .vertices
        .iter()
        .map(|v| position(v[0] as usize, v[1] as usize))
        .collect();
    // Normals of the full-resolution surface (central differences), so
    // shading does not depend on the tolerance.
    let normals = grid
        .vertices
        .iter()
        .map(|v| {
            let n = vertex_normal(heights, side, cell, v[0] as usize, v[1] as usize);
            // z up → y up (x east, y up, z south).
            [n[0] as f32, n[2] as f32, -n[1] as f32]
        })
        .collect();
    // Grid (col, row) triangles from martini's traversal are clockwise seen
    // from above with rows growing south; reorder to counter-clockwise y-up.
    let triangles = grid
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| positions[i as usize]);
            // Cross product's y with (x, −z) as the plan coordinates.
            let cross = (b[0] - a[0]) * (-(c[2] - a[2])) - (-(b[2] - a[2])) * (c[0] - a[0]);
            if cross >= 0.0 {
                *t
            } else {
                [t[0], t[2], t[1]]
            }
        })
        .collect();
    let (origin_x, origin_y) = frame.world_origin();
    let (uvs, texture_png) = match drape {
        None => (None, None),
        Some(color) => {
            let uvs = grid
                .vertices
                .iter()
                .map(|v| {
                    let (x, y) = frame.world_from_vertex(v[0] as f64, v[1] as f64);
                    let (u, w) = color.geotransform.invert(x, y).unwrap_or((0.0, 0.0));
                    [
                        (u / color.width as f64) as f32,
                        (w / color.height as f64) as f32,
                    ]
                })
                .collect();
            (
                Some(uvs),
                Some(encode_rgba(color.rgba, color.width, color.height)?),
            )
        }
    };
    Ok(ExportMesh {
        positions,
        normals,
        uvs,
        triangles,
        origin: [origin_x, origin_y],
        texture_png,
        largest_deviation_m: grid.largest_deviation(heights, side),
    })
}

/// glTF 2.0 binary container.
pub fn to_glb(mesh: &ExportMesh, crs_wkt: &str) -> Result<Vec<u8>> {
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut add_view = |bin: &mut Vec<u8>, bytes: &[u8], target: Option<u32>| {
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let mut view = json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        bin.extend_from_slice(bytes);
        views.push(view);
        views.len() - 1
    };
    let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
    for p in &mesh.positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let n = mesh.positions.len();
    let position_view = add_view(&mut bin, bytemuck::cast_slice(&mesh.positions), Some(34962));
    let normal_view = add_view(&mut bin, bytemuck::cast_slice(&mesh.normals), Some(34962));
    let mut accessors = vec![
        json!({"bufferView": position_view, "componentType": 5126, "count": n, "type": "VEC3", "min": lo, "max": hi}),
        json!({"bufferView": normal_view, "componentType": 5126, "count": n, "type": "VEC3"}),
    ];
    let mut attributes = json!({"POSITION": 0, "NORMAL": 1});
    if let Some(uvs) = &mesh.uvs {
        let view = add_view(&mut bin, bytemuck::cast_slice(uvs), Some(34962));
        accessors
            .push(json!({"bufferView": view, "componentType": 5126, "count": n, "type": "VEC2"}));
        attributes["TEXCOORD_0"] = json!(accessors.len() - 1);
    }
    let index_view = add_view(&mut bin, bytemuck::cast_slice(&mesh.triangles), Some(34963));
    accessors.push(json!({"bufferView": index_view, "componentType": 5125, "count": mesh.triangles.len() * 3, "type": "SCALAR"}));
    let indices = accessors.len() - 1;

    let mut doc = json!({
        "asset": {"version": "2.0", "generator": concat!("relevo ", env!("CARGO_PKG_VERSION"))},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{
            "mesh": 0,
            "translation": [mesh.origin[0], 0.0, -mesh.origin[1]],
            "extras": {"crs_wkt": crs_wkt, "origin_east_north": mesh.origin}
        }],
        "meshes": [{"primitives": [{"attributes": attributes, "indices": indices, "mode": 4, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0}}],
        "accessors": accessors,
    });
    if let Some(png) = &mesh.texture_png {
        let view = add_view(&mut bin, png, None);
        doc["images"] = json!([{"bufferView": view, "mimeType": "image/png"}]);
        doc["samplers"] =
            json!([{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}]);
        doc["textures"] = json!([{"sampler": 0, "source": 0}]);
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    doc["bufferViews"] = json!(views);
    doc["buffers"] = json!([{"byteLength": bin.len()}]);
    let mut text = serde_json::to_vec(&doc).map_err(|e| Error::Input(e.to_string()))?;
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    Ok(out)
}

/// Wavefront OBJ text; `material` names the .mtl beside it when textured.
pub fn to_obj(mesh: &ExportMesh, material: Option<&str>) -> Vec<u8> {
    let mut out = Vec::new();
    let _ = writeln!(
        out,
        "# relevo {} mesh, y up, metres from world ({:.3}, {:.3})",
        env!("CARGO_PKG_VERSION"),
        mesh.origin[0],
        mesh.origin[1]
    );
    if let Some(m) = material {
        let _ = writeln!(out, "mtllib {m}.mtl\nusemtl drape");
    }
    for p in &mesh.positions {
        let _ = writeln!(out, "v {} {} {}", p[0], p[1], p[2]);
    }
    for n in &mesh.normals {
        let _ = writeln!(out, "vn {} {} {}", n[0], n[1], n[2]);
    }
    if let Some(uvs) = &mesh.uvs {
        for t in uvs {
            let _ = writeln!(out, "vt {} {}", t[0], 1.0 - t[1]);
        }
    }
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| i + 1);
        if mesh.uvs.is_some() {
            let _ = writeln!(out, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}");
        } else {
            let _ = writeln!(out, "f {a}//{a} {b}//{b} {c}//{c}");
        }
    }
    out
}
