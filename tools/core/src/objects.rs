//! Objects placed on the terrain and composited with it through the shared
//! depth buffer (Szenberg 1997, ch. 8: houses, vehicles, power lines),
//! read from a GeoJSON placement file into one triangle list in the
//! terrain frame. See `docs/formats.md` for the file.
//!
//! - `LineString` of `[x, y, h]`: a cable `h` metres above the ground at
//!   each vertex, drawn as a vertical ribbon `width_m` wide (default 1 m).
//! - `Polygon` with `height_m`: a building, its outer ring extruded from the
//!   lowest ground under it to `height_m` above that (roof by ear clipping).
//! - `Point` with `model` (an OBJ file, relative to the placement file),
//!   `scale` (default 1) and `heading_deg` (default 0): the model, y up, its
//!   origin on the ground.
//!
//! Any feature may give `color` as `[r, g, b]` (0–255).

use crate::geo::TerrainFrame;
use crate::{Error, Result};
use serde_json::Value;
use std::path::Path;

/// Triangles in the terrain frame, three vertices each.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ObjectMesh {
    /// Terrain frame, metres.
    pub positions: Vec<[f64; 3]>,
    /// Unit normals, one per vertex.
    pub normals: Vec<[f32; 3]>,
    /// RGBA8, one per vertex.
    pub colours: Vec<[u8; 4]>,
    /// Features read.
    pub features: usize,
}

impl ObjectMesh {
    pub fn triangles(&self) -> usize {
        self.positions.len() / 3
    }

    /// Add triangle `abc` (counter-clockwise seen from outside) with its
    /// flat normal.
    fn triangle(&mut self, a: [f64; 3], b: [f64; 3], c: [f64; 3], colour: [u8; 4]) {
        let (u, v) = (sub(b, a), sub(c, a));
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if len == 0.0 || !len.is_finite() {
            return;
        }
        let n = n.map(|x| (x / len) as f32);
        self.positions.extend([a, b, c]);
        self.normals.extend([n; 3]);
        self.colours.extend([colour; 3]);
    }

    /// A cable through `line` (terrain frame, metres): a vertical ribbon
    /// `2·half` metres wide, seen from both sides.
    fn add_cable(&mut self, line: &[[f64; 3]], half: f64, colour: [u8; 4]) {
        let lower = |p: [f64; 3]| [p[0], p[1], p[2] - half];
        let upper = |p: [f64; 3]| [p[0], p[1], p[2] + half];
        for w in line.windows(2) {
            let (a, b) = (w[0], w[1]);
            self.quad(lower(a), lower(b), upper(b), upper(a), colour);
            self.quad(lower(b), lower(a), upper(a), upper(b), colour);
        }
    }

    /// A building: the `footprint` ring (terrain frame, without the closing
    /// position) extruded from `base` to `top` metres, walls facing out,
    /// the roof triangulated by ear clipping and facing up.
    fn add_building(&mut self, mut footprint: Vec<[f64; 2]>, base: f64, top: f64, colour: [u8; 4]) {
        let area2: f64 = (0..footprint.len())
            .map(|i| {
                let (a, b) = (footprint[i], footprint[(i + 1) % footprint.len()]);
                a[0] * b[1] - b[0] * a[1]
            })
            .sum();
        // Counter-clockwise seen from above, so walls face outwards.
        if area2 < 0.0 {
            footprint.reverse();
        }
        for i in 0..footprint.len() {
            let (a, b) = (footprint[i], footprint[(i + 1) % footprint.len()]);
            self.quad(
                [a[0], a[1], base],
                [b[0], b[1], base],
                [b[0], b[1], top],
                [a[0], a[1], top],
                colour,
            );
        }
        let mut roof: Vec<u32> = Vec::new();
        earcut::Earcut::new().earcut(footprint.iter().copied(), &[], &mut roof);
        for t in roof.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| {
                let p = footprint[i as usize];
                [p[0], p[1], top]
            });
            // The roof faces up whatever order ear clipping returns.
            if (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) > 0.0 {
                self.triangle(a, b, c, colour);
            } else {
                self.triangle(a, c, b, colour);
            }
        }
    }

    /// A quad `abcd` as two triangles.
    fn quad(&mut self, a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3], colour: [u8; 4]) {
        self.triangle(a, b, c, colour);
        self.triangle(a, c, d, colour);
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Default colours: buildings light, cables dark, models grey.
const BUILDING: [u8; 4] = [214, 196, 170, 255];
const CABLE: [u8; 4] = [40, 40, 46, 255];
const MODEL: [u8; 4] = [170, 170, 170, 255];

/// Read the placement file at `path` onto the terrain of `frame`, with
/// `ground(x, y)` the terrain height (metres) at a terrain-frame point, or
/// `None` off the data. Errors name the file and the feature.
pub fn read_placement(
    path: &Path,
    frame: &TerrainFrame,
    ground: &dyn Fn(f64, f64) -> Option<f64>,
) -> Result<ObjectMesh> {
    let text = crate::files::read_to_string(path)?;
    let folder = path.parent().unwrap_or(Path::new("."));
    parse_placement(&text, folder, frame, ground).map_err(|message| Error::invalid(path, message))
}

/// [`read_placement`] on text; models are found relative to `folder`.
pub fn parse_placement(
    text: &str,
    folder: &Path,
    frame: &TerrainFrame,
    ground: &dyn Fn(f64, f64) -> Option<f64>,
) -> std::result::Result<ObjectMesh, String> {
    let doc: Value = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
    let features = doc
        .get("features")
        .and_then(Value::as_array)
        .ok_or("not a GeoJSON FeatureCollection")?;
    let mut mesh = ObjectMesh::default();
    for (k, feature) in features.iter().enumerate() {
        let fail = |message: &str| format!("feature {k}: {message}");
        let geometry = feature.get("geometry").ok_or_else(|| fail("no geometry"))?;
        let kind = geometry.get("type").and_then(Value::as_str).unwrap_or("");
        let coordinates = geometry
            .get("coordinates")
            .ok_or_else(|| fail("no coordinates"))?;
        let properties = feature.get("properties").cloned().unwrap_or(Value::Null);
        let number = |name: &str| properties.get(name).and_then(Value::as_f64);
        let colour = |default: [u8; 4]| match properties.get("color").and_then(Value::as_array) {
            Some(c) if c.len() == 3 => {
                let v: Vec<u8> = c
                    .iter()
                    .filter_map(Value::as_f64)
                    .map(|x| x.clamp(0.0, 255.0) as u8)
                    .collect();
                if v.len() == 3 {
                    [v[0], v[1], v[2], 255]
                } else {
                    default
                }
            }
            _ => default,
        };
        // World (east, north) → terrain (x, y), and the ground there.
        let place = |p: &Value| -> std::result::Result<(f64, f64, f64, Option<f64>), String> {
            let c = p
                .as_array()
                .ok_or_else(|| fail("a position is not an array"))?;
            let (Some(e), Some(n)) = (
                c.first().and_then(Value::as_f64),
                c.get(1).and_then(Value::as_f64),
            ) else {
                return Err(fail("a position is not a pair of numbers"));
            };
            let (x, y) = frame
                .terrain_from_world(e, n)
                .ok_or_else(|| fail("the bundle's geotransform cannot be inverted"))?;
            let z = ground(x, y).ok_or_else(|| fail(&format!("({e}, {n}) is off the terrain")))?;
            Ok((x, y, z, c.get(2).and_then(Value::as_f64)))
        };
        match kind {
            "LineString" => {
                let points = coordinates
                    .as_array()
                    .filter(|p| p.len() >= 2)
                    .ok_or_else(|| fail("a line needs 2 positions"))?;
                let half = number("width_m").unwrap_or(1.0).max(0.01) / 2.0;
                let mut line = Vec::with_capacity(points.len());
                for p in points {
                    let (x, y, z, h) = place(p)?;
                    let h = h.ok_or_else(|| fail("a cable position needs a height [x, y, h]"))?;
                    line.push([x, y, z + h]);
                }
                mesh.add_cable(&line, half, colour(CABLE));
            }
            "Polygon" => {
                let ring = coordinates
                    .as_array()
                    .and_then(|rings| rings.first())
                    .and_then(Value::as_array)
                    .filter(|r| r.len() >= 4)
                    .ok_or_else(|| fail("a building needs a ring of at least 4 positions"))?;
                let height = number("height_m")
                    .filter(|h| h.is_finite() && *h > 0.0)
                    .ok_or_else(|| fail("a building needs a positive height_m"))?;
                let mut footprint = Vec::with_capacity(ring.len());
                let mut base = f64::INFINITY;
                for p in &ring[..ring.len() - 1] {
                    let (x, y, z, _) = place(p)?;
                    base = base.min(z);
                    footprint.push([x, y]);
                }
                mesh.add_building(footprint, base, base + height, colour(BUILDING));
            }
            "Point" => {
                let (x, y, z, _) = place(coordinates)?;
                let model = properties
                    .get("model")
                    .and_then(Value::as_str)
                    .ok_or_else(|| fail("a point needs a model (OBJ file)"))?;
                let scale = number("scale").unwrap_or(1.0);
                let heading = number("heading_deg").unwrap_or(0.0).to_radians();
                add_model(
                    &mut mesh,
                    &folder.join(model),
                    [x, y, z],
                    scale,
                    heading,
                    colour(MODEL),
                )
                .map_err(|e| fail(&e))?;
            }
            other => {
                return Err(fail(&format!(
                    "geometry {other:?} is not LineString, Polygon or Point"
                )))
            }
        }
        mesh.features += 1;
    }
    Ok(mesh)
}

/// An OBJ model (y up, metres × `scale`) turned by `heading` (clockwise
/// from north) with its origin at `at`.
fn add_model(
    mesh: &mut ObjectMesh,
    path: &Path,
    at: [f64; 3],
    scale: f64,
    heading: f64,
    colour: [u8; 4],
) -> std::result::Result<(), String> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _) =
        tobj::load_obj(path, &options).map_err(|e| format!("{}: {e}", path.display()))?;
    let (s, c) = heading.sin_cos();
    let before = mesh.triangles();
    for model in &models {
        let m = &model.mesh;
        let vertex = |i: u32| {
            let i = i as usize * 3;
            // OBJ: x right, y up, z towards the viewer (south when unturned).
            let (ox, oy, oz) = (
                m.positions[i] as f64,
                m.positions[i + 1] as f64,
                m.positions[i + 2] as f64,
            );
            let (east, north) = (ox * scale, -oz * scale);
            [
                at[0] + east * c + north * s,
                at[1] - east * s + north * c,
                at[2] + oy * scale,
            ]
        };
        for t in m.indices.chunks_exact(3) {
            mesh.triangle(vertex(t[0]), vertex(t[1]), vertex(t[2]), colour);
        }
    }
    if mesh.triangles() == before {
        return Err(format!("{}: no faces", path.display()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::GeoTransform;

    fn frame() -> TerrainFrame {
        TerrainFrame {
            side: 129,
            cell_size_m: 10.0,
            geotransform: GeoTransform::north_up(1000.0, 3280.0, 10.0, 10.0),
        }
    }

    fn flat(_: f64, _: f64) -> Option<f64> {
        Some(100.0)
    }

    #[test]
    fn buildings_are_closed_boxes_on_the_lowest_ground_and_cables_hang_above_it() {
        let text = r#"{"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": {"height_m": 12},
             "geometry": {"type": "Polygon", "coordinates": [[[1100, 2500], [1100, 2520], [1130, 2520], [1130, 2500], [1100, 2500]]]}},
            {"type": "Feature", "properties": {"width_m": 0.5},
             "geometry": {"type": "LineString", "coordinates": [[1200, 2600, 30], [1400, 2600, 25]]}}
        ]}"#;
        let mesh = parse_placement(text, Path::new("."), &frame(), &flat).unwrap();
        assert_eq!(mesh.features, 2);
        // 4 walls × 2 + roof 2 = 10 triangles; the cable 2 sides × 2 = 4.
        assert_eq!(mesh.triangles(), 14);
        let building = &mesh.positions[..30];
        let zs: Vec<f64> = building.iter().map(|p| p[2]).collect();
        assert!(zs.iter().all(|&z| z == 100.0 || z == 112.0));
        // Every wall normal points away from the footprint's centre.
        let (cx, cy) = frame().terrain_from_world(1115.0, 2510.0).unwrap();
        for t in 0..8 {
            let p = mesh.positions[3 * t];
            let n = mesh.normals[3 * t];
            let out = (p[0] - cx) * n[0] as f64 + (p[1] - cy) * n[1] as f64;
            assert!(out > 0.0, "wall {t} faces inwards");
        }
        for t in 8..10 {
            assert!(mesh.normals[3 * t][2] > 0.99, "the roof faces up");
        }
        let cable = &mesh.positions[30..];
        assert!(cable.iter().all(|p| p[2] > 124.0 && p[2] < 131.0));
    }

    #[test]
    fn bad_placements_name_the_feature_and_the_problem() {
        let cases = [
            ("{", "not JSON"),
            (r#"{"type": "Feature"}"#, "FeatureCollection"),
            (
                r#"{"features": [{"geometry": {"type": "Polygon", "coordinates": [[[1100, 2500], [1100, 2520], [1130, 2520], [1100, 2500]]]}}]}"#,
                "feature 0: a building needs a positive height_m",
            ),
            (
                r#"{"features": [{"geometry": {"type": "LineString", "coordinates": [[1200, 2600], [1400, 2600]]}}]}"#,
                "needs a height",
            ),
            (
                r#"{"features": [{"geometry": {"type": "LineString", "coordinates": [[99999, 2600, 5], [1400, 2600, 5]]}}]}"#,
                "off the terrain",
            ),
            (
                r#"{"features": [{"properties": {"model": "nowhere.obj"}, "geometry": {"type": "Point", "coordinates": [1200, 2600]}}]}"#,
                "nowhere.obj",
            ),
            (
                r#"{"features": [{"geometry": {"type": "MultiPoint", "coordinates": []}}]}"#,
                "not LineString",
            ),
        ];
        let ground =
            |x: f64, y: f64| (x >= 0.0 && y >= 0.0 && x <= 1280.0 && y <= 1280.0).then_some(0.0);
        for (text, needle) in cases {
            let e = parse_placement(text, Path::new("."), &frame(), &ground).unwrap_err();
            assert!(e.contains(needle), "{text}: {e}");
        }
    }

    /// A model whose faces name vertices it does not have (or none at all)
    /// is an error naming the file, not a panic.
    #[test]
    fn broken_models_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let ground =
            |x: f64, y: f64| (x >= 0.0 && y >= 0.0 && x <= 1280.0 && y <= 1280.0).then_some(0.0);
        for (name, obj) in [
            ("beyond.obj", "v 0 0 0\nv 1 0 0\nf 1 2 9\n"),
            ("negative.obj", "v 0 0 0\nf -5 -6 -7\n"),
            ("empty.obj", ""),
        ] {
            std::fs::write(dir.path().join(name), obj).unwrap();
            let text = format!(
                r#"{{"features": [{{"properties": {{"model": "{name}"}}, "geometry": {{"type": "Point", "coordinates": [1200, 2600]}}}}]}}"#
            );
            let e = parse_placement(&text, dir.path(), &frame(), &ground).unwrap_err();
            assert!(e.contains(name), "{name}: {e}");
        }
    }
}
