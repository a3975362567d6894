//! Export of the view-independent mesh at an object-space tolerance as
//! glTF 2.0 (binary) or Wavefront OBJ, with normals and the drape image as
//! texture.
//!
//! Both formats are written y-up (x east, y up, z south), as glTF requires
//! and most OBJ readers assume. Vertex positions are local to the grid's
//! south-west vertex so that f32 keeps centimetres; the world origin goes in
//! the glTF node's translation and in an OBJ comment.

use super::extract::{walk, MeshWalk};
use super::hierarchy::Hierarchy;
use super::metric::triangle_deviation;
use super::vertices::terrain_position;
use super::window::Rect;
use crate::geo::{GeoTransform, TerrainFrame};
use crate::gltf::{Glb, ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, FLOAT, UNSIGNED_INT};
use crate::grid::vertex_normal_of;
use crate::raster::png::encode_rgba;
use crate::{Error, Result};
use serde_json::json;
use std::borrow::Cow;
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
/// data mask, LP hierarchy and, when there is one, the drape — a single
/// grid in memory. A pyramid is read tile by tile through its own
/// [`MeshSource`] (`crate::pyramid::mesh`).
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
    pub rgba: Cow<'a, [u8]>,
    pub width: usize,
    pub height: usize,
    pub geotransform: GeoTransform,
}

/// What a mesh is exported from, read vertex by vertex: a [`Surface`] in
/// memory, or a pyramid's tiles.
pub trait MeshSource: Sync {
    fn frame(&self) -> TerrainFrame;
    /// Height of vertex (column, row), metres.
    fn height(&self, c: usize, r: usize) -> f32;
    /// Saturated object-space error of the vertex at row-major index `i`.
    fn error(&self, i: usize) -> f32;
    /// Whether the vertex at row-major index `i` holds data.
    fn has_data(&self, i: usize) -> bool;
    /// The largest vertical distance between the grid points inside
    /// triangle `corners` (columns, rows) and the plane through its
    /// corners at `corner_z`, metres (see [`triangle_deviation`]).
    fn deviation(&self, corners: [(i64, i64); 3], corner_z: [f32; 3]) -> f64;
    /// Whether there is a drape to texture the mesh with.
    fn has_drape(&self) -> bool;
    /// The drape over vertices `rect` (and a little around), if there is
    /// one.
    fn drape(&self, rect: Rect) -> Result<Option<DrapeImage<'_>>>;
    /// Drop what the reads so far brought into memory that can be read
    /// again (a pyramid's mapped pages); nothing for a grid in memory.
    fn release(&self) {}
}

impl MeshSource for Surface<'_> {
    fn frame(&self) -> TerrainFrame {
        self.frame
    }
    fn height(&self, c: usize, r: usize) -> f32 {
        self.heights[r * self.frame.side + c]
    }
    fn error(&self, i: usize) -> f32 {
        self.hierarchy.error(i)
    }
    fn has_data(&self, i: usize) -> bool {
        self.mask[i] != 0
    }
    fn deviation(&self, corners: [(i64, i64); 3], corner_z: [f32; 3]) -> f64 {
        triangle_deviation(self.heights, self.frame.side, corners, corner_z, None)
    }
    fn has_drape(&self) -> bool {
        self.drape.is_some()
    }
    fn drape(&self, rect: Rect) -> Result<Option<DrapeImage<'_>>> {
        let Some(d) = &self.drape else {
            return Ok(None);
        };
        if rect == Rect::whole(self.frame.side) {
            return Ok(Some(DrapeImage {
                rgba: Cow::Borrowed(&d.rgba),
                ..*d
            }));
        }
        // The image's pixels under the rectangle's corners, one more around.
        let corner = |c: usize, r: usize| {
            let (x, y) = self.frame.world_from_vertex(c as f64, r as f64);
            d.geotransform.invert(x, y).unwrap_or((0.0, 0.0))
        };
        let (a, b) = (
            corner(rect.c0, rect.r0),
            corner(rect.c0 + rect.width - 1, rect.r0 + rect.height - 1),
        );
        let pixel = |v: f64, n: usize| (v.max(0.0) as usize).min(n - 1);
        let (x0, x1) = (
            pixel(a.0.min(b.0) - 1.0, d.width),
            pixel(a.0.max(b.0) + 1.0, d.width),
        );
        let (y0, y1) = (
            pixel(a.1.min(b.1) - 1.0, d.height),
            pixel(a.1.max(b.1) + 1.0, d.height),
        );
        let (w, h) = (x1 - x0 + 1, y1 - y0 + 1);
        let mut rgba = Vec::with_capacity(w * h * 4);
        for y in y0..=y1 {
            rgba.extend_from_slice(&d.rgba[4 * (y * d.width + x0)..4 * (y * d.width + x1 + 1)]);
        }
        let (ox, oy) = d.geotransform.apply(x0 as f64, y0 as f64);
        let g = d.geotransform.0;
        Ok(Some(DrapeImage {
            rgba: Cow::Owned(rgba),
            width: w,
            height: h,
            geotransform: GeoTransform([ox, g[1], g[2], oy, g[4], g[5]]),
        }))
    }
}

/// Bytes a mesh vertex costs while it is built and written, about: its grid
/// coordinates and number, position, normal and texture coordinates, two
/// triangles' indices twice, and their copy in the output file.
const BYTES_PER_MESH_VERTEX: u64 = 160;

/// Build the mesh of `source` at `max_error` metres, over the whole grid
/// or only the triangles meeting `window` (see [`walk`]).
pub fn build(
    source: &dyn MeshSource,
    max_error: f32,
    keep_padding: bool,
    window: Option<Rect>,
) -> Result<ExportMesh> {
    let frame = source.frame();
    let side = frame.side;
    let error = |i: usize| source.error(i);
    let has_data = |i: usize| source.has_data(i);
    let max_vertices = (crate::memory::budget() / BYTES_PER_MESH_VERTEX) as usize;
    let grid = walk(&MeshWalk {
        side,
        max_error,
        error: &error,
        has_data: (!keep_padding).then_some(&has_data as &(dyn Fn(usize) -> bool + Sync)),
        boundaries: None,
        window,
        max_vertices,
    })
    .ok_or_else(|| {
        Error::Input(format!(
            "the mesh at {max_error} m has more than {max_vertices} vertices, more than the memory \
             budget ({}) holds: raise the tolerance or take a smaller window",
            crate::memory::human(crate::memory::budget())
        ))
    })?;
    source.release();
    if grid.triangles.is_empty() {
        return Err(Error::Input(match window {
            None => "no triangles: the mask covers no data".into(),
            Some(_) => "no triangles: the window holds no data".into(),
        }));
    }
    // Positions are local to the window's south-west vertex (the grid's
    // without a window), the drape cut to the window.
    let anchor = window.unwrap_or(Rect::whole(side));
    let (c0, r1) = (anchor.c0, anchor.r0 + anchor.height - 1);
    let cell = frame.cell_size_m;
    let origin = terrain_position(c0, r1, side, cell, 0.0);
    let position = |c: usize, r: usize| {
        let p = terrain_position(c, r, side, cell, source.height(c, r) as f64);
        [
            (p[0] - origin[0]) as f32,
            p[2] as f32,
            -(p[1] - origin[1]) as f32,
        ]
    };
    // Normals of the full-resolution surface (central differences), so
    // shading does not depend on the tolerance. A chunk of vertices at a
    // time, what the reads brought in released after each.
    let z = |c: usize, r: usize| source.height(c, r);
    let (mut positions, mut normals) = (
        Vec::with_capacity(grid.vertices.len()),
        Vec::with_capacity(grid.vertices.len()),
    );
    for chunk in grid.vertices.chunks(RELEASE_CHUNK) {
        for v in chunk {
            let (c, r) = (v[0] as usize, v[1] as usize);
            positions.push(position(c, r));
            let n = vertex_normal_of(&z, side, cell, c, r);
            // z up → y up (x east, y up, z south).
            normals.push([n[0] as f32, n[2] as f32, -n[1] as f32]);
        }
        source.release();
    }
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
    let (origin_x, origin_y) = frame.world_from_vertex(c0 as f64, r1 as f64);
    let (uvs, texture_png) = match source.drape(anchor)? {
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
                Some(encode_rgba(&color.rgba, color.width, color.height)?),
            )
        }
    };
    source.release();
    let largest_deviation_m = grid.largest_deviation_of(
        &|c, r| source.height(c, r),
        &|corners, z| source.deviation(corners, z),
        &|| source.release(),
    );
    Ok(ExportMesh {
        positions,
        normals,
        uvs,
        triangles,
        origin: [origin_x, origin_y],
        texture_png,
        largest_deviation_m,
    })
}

/// Vertices read between two releases of what the reads brought in.
const RELEASE_CHUNK: usize = 1 << 16;

/// glTF 2.0 binary container.
pub fn to_glb(mesh: &ExportMesh, crs_wkt: &str) -> Result<Vec<u8>> {
    let mut glb = Glb::default();
    let mut attributes = json!({
        "POSITION": glb.vec3(&mesh.positions, Some(ARRAY_BUFFER)),
        "NORMAL": glb.vec3(&mesh.normals, Some(ARRAY_BUFFER)),
    });
    if let Some(uvs) = &mesh.uvs {
        attributes["TEXCOORD_0"] = json!(glb.accessor(
            bytemuck::cast_slice(uvs),
            Some(ARRAY_BUFFER),
            FLOAT,
            uvs.len(),
            "VEC2",
            json!({})
        ));
    }
    let indices = glb.accessor(
        bytemuck::cast_slice(&mesh.triangles),
        Some(ELEMENT_ARRAY_BUFFER),
        UNSIGNED_INT,
        mesh.triangles.len() * 3,
        "SCALAR",
        json!({}),
    );
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
    });
    if let Some(png) = &mesh.texture_png {
        let view = glb.view(png, None);
        doc["images"] = json!([{"bufferView": view, "mimeType": "image/png"}]);
        doc["samplers"] =
            json!([{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}]);
        doc["textures"] = json!([{"sampler": 0, "source": 0}]);
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    }
    glb.finish(doc)
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
