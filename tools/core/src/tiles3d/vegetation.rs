//! The vegetation as 3D Tiles: the database's objects split by a quadtree
//! over longitude and latitude, each tile one glb with a mesh per class
//! (the class's model, as the cluster bake renders its impostors from)
//! drawn once per object with `EXT_mesh_gpu_instancing`, and each object's
//! database id, class, crown and score as feature metadata
//! (`EXT_instance_features`, `EXT_structural_metadata`).
//!
//! Tiles refine by adding: a tile holds the largest objects of its cell (at
//! most a tile's capacity, a spread sample of equals), its children the
//! rest, so a far view shows the tallest trees, thinned, and a near one
//! every tree. A tile's geometric error is what leaving its descendants out
//! costs: the larger of the kept objects' spacing (the gaps between them)
//! and the height of the tallest object left out.

use super::tileset::Tile;
use super::{y_up, LocalFrame, Region};
use crate::cluster::model::Model;
use crate::gltf::{Glb, ARRAY_BUFFER, FLOAT};
use crate::terrain_tiles::ellipsoid::{east_north_up, ecef_from_geodetic};
use crate::Result;
use serde_json::json;

/// One object of the database, placed on the ellipsoid.
#[derive(Debug, Clone, PartialEq)]
pub struct Instance {
    /// The database's id.
    pub id: u64,
    /// Index into the classes.
    pub class: u8,
    /// Foot of the trunk: longitude, latitude (degrees), height above the
    /// ellipsoid (metres).
    pub lon_deg: f64,
    pub lat_deg: f64,
    pub foot_height_m: f64,
    /// Crown diameter and height, metres.
    pub diameter_m: f32,
    pub height_m: f32,
    /// The classifier's score.
    pub score: f32,
}

/// A class's mesh in glTF's axes (x east, y up, z south), scaled to a crown
/// diameter of 1: a triangle soup with flat normals and the model's colours,
/// simplified to at most [`MAX_CLASS_TRIANGLES`].
#[derive(Debug, Clone, PartialEq)]
pub struct ClassMesh {
    pub name: String,
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    /// Linear RGB, 0–1: the model's corner colour times its texture's texel
    /// at the corner (the texture itself is not carried).
    pub colours: Vec<[f32; 3]>,
}

/// Triangles a class's mesh keeps at most: every instance draws them, and a
/// tile holds thousands of instances (the built-in stand has 6 356, which
/// at 4 096 a tile would be 26 M triangles).
pub const MAX_CLASS_TRIANGLES: usize = 256;

/// A corner of the model's triangle soup: position and colour.
type Corner = ([f32; 3], [f32; 3]);

impl ClassMesh {
    /// The mesh of `model` (x east, y north, z up, foot at the origin).
    pub fn of(name: &str, model: &Model) -> ClassMesh {
        let (diameter, _) = model.size();
        let scale = if diameter > 0.0 { 1.0 / diameter } else { 1.0 };
        let gltf = |p: [f32; 3]| [p[0] * scale, p[2] * scale, -p[1] * scale];
        let soup: Vec<[Corner; 3]> = model
            .triangles
            .iter()
            .map(|t| {
                [0, 1, 2].map(|k| {
                    let texel = t
                        .texture
                        .and_then(|i| model.textures.get(i as usize))
                        .map_or([255; 4], |tex| tex.sample(t.uv[k][0], t.uv[k][1]));
                    let colour = [0, 1, 2].map(|j| t.colour[k][j] * srgb_to_linear(texel[j]));
                    (gltf(t.corners[k]), colour)
                })
            })
            .collect();
        // The finest clustering that meets the budget.
        let simplified = [48, 32, 24, 16, 12, 8, 6, 4, 3, 2]
            .into_iter()
            .map(|cells| cluster_vertices(&soup, cells))
            .find(|t| t.len() <= MAX_CLASS_TRIANGLES);
        let triangles = if soup.len() <= MAX_CLASS_TRIANGLES {
            soup
        } else {
            simplified.unwrap_or_default()
        };
        let mut mesh = ClassMesh {
            name: name.to_string(),
            positions: Vec::with_capacity(triangles.len() * 3),
            normals: Vec::with_capacity(triangles.len() * 3),
            colours: Vec::with_capacity(triangles.len() * 3),
        };
        for t in &triangles {
            let [a, b, c] = t.map(|corner| corner.0);
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let n = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            let length = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if length == 0.0 {
                continue;
            }
            for corner in t {
                mesh.positions.push(corner.0);
                mesh.normals.push(n.map(|x| x / length));
                mesh.colours.push(corner.1);
            }
        }
        mesh
    }
}

/// Vertex clustering (Rossignac and Borrel, 1993): the soup's corners
/// snapped to the mean of their cell in a `cells`³ grid over its box,
/// triangles whose corners fall in fewer than three cells dropped, each
/// remaining set of three cells kept once, and the result stretched back
/// to the soup's box.
fn cluster_vertices(soup: &[[Corner; 3]], cells: usize) -> Vec<[Corner; 3]> {
    let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
    for corner in soup.iter().flatten() {
        for k in 0..3 {
            lo[k] = lo[k].min(corner.0[k]);
            hi[k] = hi[k].max(corner.0[k]);
        }
    }
    let cell_of = |p: [f32; 3]| {
        let index = |k: usize| {
            let span = (hi[k] - lo[k]).max(f32::MIN_POSITIVE);
            (((p[k] - lo[k]) / span * cells as f32) as usize).min(cells - 1)
        };
        (index(2) * cells + index(1)) * cells + index(0)
    };
    // Each cell's mean corner.
    let mut sums: std::collections::BTreeMap<usize, ([f64; 3], [f64; 3], f64)> =
        std::collections::BTreeMap::new();
    for &(p, c) in soup.iter().flatten() {
        let e = sums.entry(cell_of(p)).or_insert(([0.0; 3], [0.0; 3], 0.0));
        for k in 0..3 {
            e.0[k] += p[k] as f64;
            e.1[k] += c[k] as f64;
        }
        e.2 += 1.0;
    }
    let mean = |cell: usize| -> Corner {
        let (p, c, n) = sums[&cell];
        (p.map(|v| (v / n) as f32), c.map(|v| (v / n) as f32))
    };
    let mut seen = std::collections::BTreeSet::new();
    let mut out = Vec::new();
    for t in soup {
        let ids = t.map(|corner| cell_of(corner.0));
        if ids[0] == ids[1] || ids[1] == ids[2] || ids[0] == ids[2] {
            continue;
        }
        let mut key = ids;
        key.sort_unstable();
        if seen.insert(key) {
            out.push(ids.map(mean));
        }
    }
    // Means pull the outline in; stretch the result back to the model's
    // box, about the foot, so that the crown keeps its size.
    let (mut new_lo, mut new_hi) = ([f32::MAX; 3], [f32::MIN; 3]);
    for corner in out.iter().flatten() {
        for k in 0..3 {
            new_lo[k] = new_lo[k].min(corner.0[k]);
            new_hi[k] = new_hi[k].max(corner.0[k]);
        }
    }
    let stretch = |p: [f32; 3]| {
        [0, 1, 2].map(|k| {
            let span = new_hi[k] - new_lo[k];
            if span > 0.0 {
                lo[k] + (p[k] - new_lo[k]) / span * (hi[k] - lo[k])
            } else {
                p[k]
            }
        })
    };
    for t in &mut out {
        for corner in t.iter_mut() {
            corner.0 = stretch(corner.0);
        }
    }
    out
}

/// An 8-bit sRGB value as linear 0–1.
fn srgb_to_linear(v: u8) -> f32 {
    let c = v as f32 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Objects a tile holds at most.
pub const TILE_CAPACITY: usize = 4096;

/// Depth past which a cell is not split (objects that share a place).
const MAX_DEPTH: u32 = 20;

/// A tile of the quadtree with its objects.
pub struct VegTile {
    /// Depth, column and row in the quadtree over the region's box.
    pub depth: u32,
    pub x: u32,
    pub y: u32,
    /// Ordered by class, then id: an object's feature id is its place here.
    pub objects: Vec<Instance>,
    pub children: Vec<VegTile>,
    /// What leaving the descendants out costs, metres: the larger of the
    /// kept objects' spacing and the tallest descendant's height; 0 for a
    /// leaf.
    pub geometric_error_m: f64,
}

impl VegTile {
    /// The content's path: `{depth}/{x}/{y}.glb`.
    pub fn path(&self) -> String {
        format!("{}/{}/{}.glb", self.depth, self.x, self.y)
    }
}

/// The quadtree of `objects` over `bounds_deg` (`[west, south, east,
/// north]`), at most `capacity` objects a tile: a tile keeps its cell's
/// largest (by crown; a spread sample of equals) and splits the rest into
/// quarters.
pub fn quadtree(objects: Vec<Instance>, bounds_deg: [f64; 4], capacity: usize) -> VegTile {
    split(objects, bounds_deg, capacity.max(1), (0, 0, 0))
}

fn split(
    mut objects: Vec<Instance>,
    [w, s, e, n]: [f64; 4],
    capacity: usize,
    (depth, x, y): (u32, u32, u32),
) -> VegTile {
    let mut rest = Vec::new();
    if objects.len() > capacity && depth < MAX_DEPTH {
        // Ties in size go by a hash of the id, so that a tile keeps a
        // sample spread over its cell rather than the first ids' corner.
        objects.sort_by(|a, b| {
            b.diameter_m
                .total_cmp(&a.diameter_m)
                .then(spread(a.id).cmp(&spread(b.id)))
                .then(a.id.cmp(&b.id))
        });
        rest = objects.split_off(capacity);
    }
    // Leaving the rest out leaves gaps as wide as the kept objects'
    // spacing and misses objects as tall as the tallest of the rest.
    let geometric_error_m = if rest.is_empty() {
        0.0
    } else {
        let metres_per_deg = 111_320.0;
        let cell_m2 = (e - w)
            * metres_per_deg
            * ((s + n) / 2.0).to_radians().cos()
            * (n - s)
            * metres_per_deg;
        let spacing_m = (cell_m2 / objects.len() as f64).sqrt();
        rest.iter()
            .map(|o| o.height_m as f64)
            .fold(spacing_m, f64::max)
    };
    let (mid_lon, mid_lat) = ((w + e) / 2.0, (s + n) / 2.0);
    let mut quarters: [Vec<Instance>; 4] = Default::default();
    for o in rest {
        let q = usize::from(o.lon_deg >= mid_lon) + 2 * usize::from(o.lat_deg < mid_lat);
        quarters[q].push(o);
    }
    let children = quarters
        .into_iter()
        .enumerate()
        .filter(|(_, q)| !q.is_empty())
        .map(|(q, objects)| {
            let (east, south) = (q % 2 == 1, q / 2 == 1);
            let cell = [
                if east { mid_lon } else { w },
                if south { s } else { mid_lat },
                if east { e } else { mid_lon },
                if south { mid_lat } else { n },
            ];
            let id = (depth + 1, 2 * x + east as u32, 2 * y + south as u32);
            split(objects, cell, capacity, id)
        })
        .collect();
    objects.sort_by(|a, b| a.class.cmp(&b.class).then(a.id.cmp(&b.id)));
    VegTile {
        depth,
        x,
        y,
        objects,
        children,
        geometric_error_m,
    }
}

/// A pseudo-random order of ids (SplitMix64's finaliser).
fn spread(id: u64) -> u64 {
    let mut z = id.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The region `objects` fill: their feet to their tops, and their crowns'
/// reach around the feet.
pub fn region_of(objects: &[Instance]) -> Region {
    let metres_per_deg = 111_320.0;
    objects.iter().fold(Region::EMPTY, |r, o| {
        let radius = o.diameter_m as f64 / 2.0;
        let d_lat = radius / metres_per_deg;
        let d_lon = d_lat / o.lat_deg.to_radians().cos().max(0.01);
        r.extend(o.lon_deg - d_lon, o.lat_deg - d_lat, o.foot_height_m)
            .extend(
                o.lon_deg + d_lon,
                o.lat_deg + d_lat,
                o.foot_height_m + o.height_m as f64,
            )
    })
}

/// The tile tree of `root` for `tileset.json`.
pub fn tiles(root: &VegTile) -> Tile {
    let children = root.children.iter().map(tiles).collect();
    Tile::over(
        format!("{}/{}/{}", root.depth, root.x, root.y),
        (!root.objects.is_empty()).then(|| (root.path(), region_of(&root.objects))),
        root.geometric_error_m,
        children,
    )
}

/// The glb of `objects` (ordered by class): a node per class present,
/// instancing its mesh at each object's foot, upright on the ellipsoid,
/// turned by an angle from its id, scaled to its crown; node translations
/// at the objects' centre in `frame`.
pub fn glb(objects: &[Instance], classes: &[ClassMesh], frame: &LocalFrame) -> Result<Vec<u8>> {
    let feet: Vec<[f64; 3]> = objects
        .iter()
        .map(|o| frame.local(ecef_from_geodetic(o.lon_deg, o.lat_deg, o.foot_height_m)))
        .collect();
    let anchor = {
        let n = feet.len().max(1) as f64;
        [0, 1, 2].map(|k| feet.iter().map(|p| p[k]).sum::<f64>() / n)
    };
    let mut glb = Glb::default();
    let (mut meshes, mut nodes) = (Vec::new(), Vec::new());
    let mut start = 0;
    while start < objects.len() {
        let class = objects[start].class;
        let end = start
            + objects[start..]
                .iter()
                .take_while(|o| o.class == class)
                .count();
        let Some(mesh) = classes.get(class as usize) else {
            return Err(crate::Error::Input(format!(
                "vegetation class {class} has no model"
            )));
        };
        let primitive = json!({
            "attributes": {
                "POSITION": glb.vec3(&mesh.positions, Some(ARRAY_BUFFER)),
                "NORMAL": glb.vec3(&mesh.normals, Some(ARRAY_BUFFER)),
                "COLOR_0": glb.vec3(&mesh.colours, Some(ARRAY_BUFFER)),
            },
            "mode": 4,
            "material": 0,
        });
        meshes.push(json!({"name": mesh.name, "primitives": [primitive]}));
        let range = &objects[start..end];
        let translations: Vec<[f32; 3]> = feet[start..end]
            .iter()
            .map(|p| y_up([0, 1, 2].map(|k| p[k] - anchor[k])).map(|v| v as f32))
            .collect();
        let rotations: Vec<[f32; 4]> = range.iter().map(|o| upright(o, frame)).collect();
        let scales: Vec<[f32; 3]> = range.iter().map(|o| [o.diameter_m; 3]).collect();
        let feature_ids: Vec<f32> = (start..end).map(|i| i as f32).collect();
        let attributes = json!({
            "TRANSLATION": glb.vec3(&translations, None),
            "ROTATION": glb.accessor(bytemuck::cast_slice(&rotations), None, FLOAT, rotations.len(), "VEC4", json!({})),
            "SCALE": glb.vec3(&scales, None),
            "_FEATURE_ID_0": glb.accessor(bytemuck::cast_slice(&feature_ids), None, FLOAT, feature_ids.len(), "SCALAR", json!({})),
        });
        nodes.push(json!({
            "name": mesh.name,
            "mesh": meshes.len() - 1,
            "translation": y_up(anchor),
            "extensions": {
                "EXT_mesh_gpu_instancing": {"attributes": attributes},
                "EXT_instance_features": {"featureIds": [
                    {"featureCount": end - start, "attribute": 0, "propertyTable": 0}
                ]},
            },
        }));
        start = end;
    }
    let metadata = property_table(&mut glb, objects, classes);
    let doc = json!({
        "asset": {"version": "2.0", "generator": concat!("relevo ", env!("CARGO_PKG_VERSION"))},
        "extensionsUsed": ["EXT_mesh_gpu_instancing", "EXT_instance_features", "EXT_structural_metadata"],
        "extensionsRequired": ["EXT_mesh_gpu_instancing"],
        "extensions": {"EXT_structural_metadata": metadata},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": [{
            "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0},
            "doubleSided": true,
        }],
    });
    glb.finish(doc)
}

/// The schema and the property table of `objects`: id, class, crown
/// diameter, height and score, one row per feature id.
fn property_table(glb: &mut Glb, objects: &[Instance], classes: &[ClassMesh]) -> serde_json::Value {
    let ids: Vec<u64> = objects.iter().map(|o| o.id).collect();
    let class: Vec<u8> = objects.iter().map(|o| o.class).collect();
    let diameter: Vec<f32> = objects.iter().map(|o| o.diameter_m).collect();
    let height: Vec<f32> = objects.iter().map(|o| o.height_m).collect();
    let score: Vec<f32> = objects.iter().map(|o| o.score).collect();
    let enum_values: Vec<_> = classes
        .iter()
        .enumerate()
        .map(|(i, c)| json!({"name": c.name, "value": i}))
        .collect();
    json!({
        "schema": {
            "id": "relevo_vegetation",
            "enums": {"vegetation_class": {"valueType": "UINT8", "values": enum_values}},
            "classes": {"vegetation_object": {"properties": {
                "id": {"description": "The object's id in the vegetation database.", "type": "SCALAR", "componentType": "UINT64"},
                "class": {"type": "ENUM", "enumType": "vegetation_class"},
                "crown_diameter_m": {"type": "SCALAR", "componentType": "FLOAT32"},
                "height_m": {"type": "SCALAR", "componentType": "FLOAT32"},
                "score": {"description": "The classifier's score, 0.5–1.", "type": "SCALAR", "componentType": "FLOAT32"},
            }}},
        },
        "propertyTables": [{
            "class": "vegetation_object",
            "count": objects.len(),
            "properties": {
                "id": {"values": glb.view(bytemuck::cast_slice(&ids), None)},
                "class": {"values": glb.view(&class, None)},
                "crown_diameter_m": {"values": glb.view(bytemuck::cast_slice(&diameter), None)},
                "height_m": {"values": glb.view(bytemuck::cast_slice(&height), None)},
                "score": {"values": glb.view(bytemuck::cast_slice(&score), None)},
            },
        }],
    })
}

/// The rotation (a unit quaternion, x y z w, in glTF's axes of `frame`)
/// that stands an object upright at its foot — its model's up along the
/// ellipsoid's normal there — turned about that normal by an angle its id
/// gives, so that neighbours do not all face one way.
fn upright(o: &Instance, frame: &LocalFrame) -> [f32; 4] {
    let [e, n, u] = east_north_up(o.lon_deg, o.lat_deg);
    let turn = (o.id.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11) as f64 / (1u64 << 53) as f64
        * std::f64::consts::TAU;
    let (s, c) = turn.sin_cos();
    let (e, n) = (
        [0, 1, 2].map(|k| c * e[k] + s * n[k]),
        [0, 1, 2].map(|k| -s * e[k] + c * n[k]),
    );
    // Columns: the model's glTF axes (x east, y up, z south) in the
    // frame's glTF axes.
    let column = |ecef: [f64; 3]| y_up(frame.local_direction(ecef));
    let x = column(e);
    let y = column(u);
    let z = column(n.map(|v| -v));
    quaternion([[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]])
}

/// The unit quaternion (x, y, z, w) of rotation matrix `m` (rows).
fn quaternion(m: [[f64; 3]; 3]) -> [f32; 4] {
    let trace = m[0][0] + m[1][1] + m[2][2];
    let q = if trace > 0.0 {
        let s = (trace + 1.0).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
            s / 4.0,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            s / 4.0,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[2][1] - m[1][2]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][1] + m[1][0]) / s,
            s / 4.0,
            (m[1][2] + m[2][1]) / s,
            (m[0][2] - m[2][0]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            s / 4.0,
            (m[1][0] - m[0][1]) / s,
        ]
    };
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    q.map(|v| (v / norm) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::model::TreeKind;
    use crate::gltf::document;

    fn object(id: u64, lon: f64, lat: f64, diameter: f32) -> Instance {
        Instance {
            id,
            class: (id % 2) as u8,
            lon_deg: lon,
            lat_deg: lat,
            foot_height_m: 10.0,
            diameter_m: diameter,
            height_m: diameter * 0.8,
            score: 0.75,
        }
    }

    #[test]
    fn the_quadtree_keeps_the_largest_and_splits_the_rest() {
        let objects: Vec<Instance> = (0..1000)
            .map(|i| {
                object(
                    i,
                    (i % 40) as f64 * 0.01,
                    (i / 40) as f64 * 0.01,
                    1.0 + (i % 7) as f32,
                )
            })
            .collect();
        let root = quadtree(objects, [0.0, 0.0, 0.4, 0.25], 100);
        fn walk(t: &VegTile, ids: &mut Vec<u64>, smallest_above: f32) {
            assert!(t.objects.len() <= 100);
            assert!(t
                .objects
                .windows(2)
                .all(|w| (w[0].class, w[0].id) < (w[1].class, w[1].id)));
            let below = t.children.iter().flat_map(|c| c.objects.iter());
            let tallest_below = below.map(|o| o.height_m).fold(0.0, f32::max);
            assert!(t.geometric_error_m >= tallest_below as f64);
            for o in &t.objects {
                assert!(o.diameter_m <= smallest_above);
                ids.push(o.id);
            }
            let smallest = t
                .objects
                .iter()
                .map(|o| o.diameter_m)
                .fold(f32::MAX, f32::min);
            for c in &t.children {
                walk(c, ids, smallest);
            }
        }
        let mut ids = Vec::new();
        walk(&root, &mut ids, f32::MAX);
        ids.sort_unstable();
        assert_eq!(ids, (0..1000).collect::<Vec<_>>());
        let tree = tiles(&root);
        assert_eq!(tree.content.as_deref(), Some("0/0/0.glb"));
        let r = tree.region;
        assert!(r.west_rad < 0.0 && r.min_height_m == 10.0);
        assert!((r.max_height_m - (10.0 + 7.0 * 0.8)).abs() < 1e-5, "{r:?}");
    }

    #[test]
    fn instances_stand_upright_with_their_metadata() {
        let classes = [
            ClassMesh::of("broadleaf", &TreeKind::Broadleaf.model(1)),
            ClassMesh::of("conifer", &TreeKind::Conifer.model(1)),
        ];
        let (lo, hi) = classes[0]
            .positions
            .iter()
            .fold((f32::MAX, f32::MIN), |(lo, hi), p| {
                (lo.min(p[0]), hi.max(p[0]))
            });
        assert!(hi - lo <= 1.0 + 1e-4 && hi - lo > 0.5, "{lo} {hi}");
        // The stand, 6 356 triangles, simplified within the budget and
        // keeping the model's box (model x east, y north, z up).
        let model = TreeKind::Stand.model(1);
        let stand = ClassMesh::of("forest", &model);
        let triangles = stand.positions.len() / 3;
        assert!(
            triangles <= MAX_CLASS_TRIANGLES && triangles > MAX_CLASS_TRIANGLES / 4,
            "{triangles}"
        );
        let extent = |k: usize| {
            let v = stand.positions.iter().map(|p| p[k]);
            v.clone().fold(f32::MIN, f32::max) - v.fold(f32::MAX, f32::min)
        };
        let b = model.bounds();
        let scale = 1.0 / model.size().0;
        for (gltf_axis, model_axis) in [(0, 0), (1, 2), (2, 1)] {
            let expected = (b[model_axis][1] - b[model_axis][0]) * scale;
            assert!(
                (extent(gltf_axis) - expected).abs() < 1e-4,
                "axis {gltf_axis}"
            );
        }
        let mut objects = vec![object(1, -34.9, -8.0, 12.0), object(2, -34.8, -8.1, 20.0)];
        objects.sort_by_key(|o| (o.class, o.id));
        let frame = LocalFrame::at(-34.9, -8.0, 0.0);
        let doc = document(&glb(&objects, &classes, &frame).unwrap()).unwrap();
        assert_eq!(doc["nodes"].as_array().unwrap().len(), 2);
        let table = &doc["extensions"]["EXT_structural_metadata"]["propertyTables"][0];
        assert_eq!(table["count"], 2);
        // At the frame's origin, up is the frame's up (glTF y): the
        // rotation turns only about y.
        let q = upright(&objects[1], &frame);
        assert!(q[0].abs() < 1e-6 && q[2].abs() < 1e-6, "{q:?}");
        // 0.1° away, up leans 0.1° off the frame's.
        let q = upright(&objects[0], &frame);
        let lean = (q[0] * q[0] + q[2] * q[2]).sqrt();
        assert!(lean > 1e-4 && lean < 2e-3, "{q:?}");
    }
}
