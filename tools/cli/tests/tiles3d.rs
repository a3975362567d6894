//! `relevo export 3dtiles` on the sample region: every glb passes the
//! Khronos validator; the tilesets hold together (volumes nest, errors
//! shrink, every content exists); the terrain tiles, decoded here and taken
//! back to longitude, latitude and height by PROJ's command line, lie
//! within their geometric error of the bundle's heights; the vegetation
//! tiles hold every baked object once, where PROJ puts the database's
//! position, upright, with its id, class and score; the output does not
//! depend on the thread count; a folder that is not an export is refused.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{
    file_hashes, gdaltransform, grid_points_on_the_ellipsoid, khronos_validate_all, relevo,
    relevo_ok, sample_bundle,
};
use serde_json::Value;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A decoded glb: its JSON and binary chunk.
struct Glb {
    doc: Value,
    bin: Vec<u8>,
}

impl Glb {
    fn read(path: &Path) -> Glb {
        let bytes = std::fs::read(path).unwrap();
        assert_eq!(&bytes[..4], b"glTF", "{}", path.display());
        let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
        assert_eq!(word(8), bytes.len());
        let json_length = word(12);
        let doc = serde_json::from_slice(&bytes[20..20 + json_length]).unwrap();
        let bin_at = 20 + json_length;
        assert_eq!(&bytes[bin_at + 4..bin_at + 8], b"BIN\0");
        let bin = bytes[bin_at + 8..bin_at + 8 + word(bin_at)].to_vec();
        Glb { doc, bin }
    }

    fn view(&self, index: &Value) -> &[u8] {
        let v = &self.doc["bufferViews"][index.as_u64().unwrap() as usize];
        let at = v["byteOffset"].as_u64().unwrap_or(0) as usize;
        &self.bin[at..at + v["byteLength"].as_u64().unwrap() as usize]
    }

    /// Accessor `index` as rows of f32 (float) or u32 (unsigned int)
    /// components, widened to f64.
    fn accessor(&self, index: &Value) -> Vec<Vec<f64>> {
        let a = &self.doc["accessors"][index.as_u64().unwrap() as usize];
        let width = match a["type"].as_str().unwrap() {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            t => panic!("{t}"),
        };
        let bytes = self.view(&a["bufferView"]);
        let values: Vec<f64> = match a["componentType"].as_u64().unwrap() {
            5126 => bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()) as f64)
                .collect(),
            5125 => bytes
                .chunks_exact(4)
                .map(|b| u32::from_le_bytes(b.try_into().unwrap()) as f64)
                .collect(),
            t => panic!("component type {t}"),
        };
        let count = a["count"].as_u64().unwrap() as usize;
        assert_eq!(values.len(), count * width);
        values.chunks(width).map(<[f64]>::to_vec).collect()
    }
}

/// A tile of a tileset, external tilesets followed.
struct TileInfo {
    region: [f64; 6],
    error_m: f64,
    content: Option<PathBuf>,
    children: Vec<TileInfo>,
}

/// The tree of the tileset at `path`, checking what 3D Tiles asks of it
/// along the way; `transform` is the root's.
fn read_tileset(path: &Path) -> (TileInfo, Option<Vec<f64>>) {
    let doc: Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    assert_eq!(doc["asset"]["version"], "1.1", "{}", path.display());
    let root = &doc["root"];
    assert!(doc["geometricError"].as_f64().unwrap() >= root["geometricError"].as_f64().unwrap());
    let transform = root["transform"]
        .as_array()
        .map(|m| m.iter().map(|v| v.as_f64().unwrap()).collect());
    (tile(root, path.parent().unwrap()), transform)
}

fn tile(json: &Value, folder: &Path) -> TileInfo {
    let region: Vec<f64> = json["boundingVolume"]["region"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(matches!(
        json["refine"].as_str(),
        None | Some("ADD" | "REPLACE")
    ));
    let mut info = TileInfo {
        region: region.try_into().unwrap(),
        error_m: json["geometricError"].as_f64().unwrap(),
        content: None,
        children: Vec::new(),
    };
    if let Some(uri) = json["content"]["uri"].as_str() {
        let path = folder.join(uri);
        assert!(path.is_file(), "{} is missing", path.display());
        if uri.ends_with(".json") {
            // An external tileset: its root stands for this tile.
            let (root, _) = read_tileset(&path);
            assert!(contains(&info.region, &root.region));
            info.children.push(root);
        } else {
            info.content = Some(path);
        }
    }
    for c in json["children"].as_array().into_iter().flatten() {
        info.children.push(tile(c, folder));
    }
    for c in &info.children {
        assert!(
            contains(&info.region, &c.region),
            "a child's volume leaves its parent's"
        );
        assert!(
            c.error_m <= info.error_m,
            "a child's error is larger than its parent's"
        );
    }
    info
}

fn contains(outer: &[f64; 6], inner: &[f64; 6]) -> bool {
    (0..2).all(|k| outer[k] <= inner[k] + 1e-12)
        && (2..4).all(|k| outer[k] >= inner[k] - 1e-12)
        && outer[4] <= inner[4] + 1e-9
        && outer[5] >= inner[5] - 1e-9
}

/// Every tile with content.
fn with_contents(root: &TileInfo) -> Vec<&TileInfo> {
    let mut out = Vec::new();
    let mut stack = vec![root];
    while let Some(t) = stack.pop() {
        if t.content.is_some() {
            out.push(t);
        }
        stack.extend(t.children.iter());
    }
    out
}

/// Points of the root's local frame (glTF y up: east, up, south) in ECEF.
fn to_ecef(transform: &[f64], p: [f64; 3]) -> [f64; 3] {
    let local = [p[0], -p[2], p[1]];
    [0, 1, 2].map(|k| {
        transform[k] * local[0]
            + transform[4 + k] * local[1]
            + transform[8 + k] * local[2]
            + transform[12 + k]
    })
}

/// ECEF points to longitude, latitude (degrees) and ellipsoidal height by
/// PROJ (EPSG:4978 → EPSG:4979).
fn geodetic(points: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let input: String = points
        .iter()
        .map(|p| format!("{:.4} {:.4} {:.4}\n", p[0], p[1], p[2]))
        .collect();
    gdaltransform(&["-s_srs", "EPSG:4978", "-t_srs", "EPSG:4979"], &input)
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

/// `node`'s translation plus `p`.
fn node_point(node: &Value, p: &[f64]) -> [f64; 3] {
    let t = node["translation"].as_array().unwrap();
    [0, 1, 2].map(|k| t[k].as_f64().unwrap() + p[k])
}

fn export(bundle: &Path, out: &Path, threads: &str) {
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_relevo"))
        .args(["export", "3dtiles"])
        .arg(bundle)
        .arg("--out")
        .arg(out)
        .env("RAYON_NUM_THREADS", threads)
        .status()
        .unwrap();
    assert!(status.success());
}

#[test]
fn the_sample_region_as_3d_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = sample_bundle(dir.path());
    let out = dir.path().join("tiles");
    export(&bundle, &out, "3");

    // Every glb passes the Khronos validator.
    let written = file_hashes(&out);
    let glbs: Vec<PathBuf> = written
        .keys()
        .filter(|f| f.ends_with(".glb"))
        .map(|f| out.join(f))
        .collect();
    assert!(glbs.len() > 10, "{glbs:?}");
    for report in khronos_validate_all(&glbs) {
        assert_eq!(report["numErrors"], 0, "{report}");
    }

    // The tileset over both, then each.
    let (top, _) = read_tileset(&out.join("tileset.json"));
    assert_eq!(top.children.len(), 2);
    let (terrain, transform) = read_tileset(&out.join("terrain/tileset.json"));
    let transform = transform.expect("the terrain's root places it on the Earth");
    let (vegetation, veg_transform) = read_tileset(&out.join("vegetation/tileset.json"));
    assert_eq!(veg_transform.as_ref(), Some(&transform));

    terrain_within_its_errors(&bundle, &terrain, &transform);
    vegetation_where_the_database_puts_it(&bundle, &vegetation, &transform);

    // Another thread count writes the same bytes.
    let again = dir.path().join("again");
    export(&bundle, &again, "1");
    assert_eq!(file_hashes(&again), written);
}

/// Each terrain tile's surface, at every grid point it covers, within the
/// tile's geometric error (0 on the finest level) of the bundle's heights
/// taken to the ellipsoid by PROJ, plus 2 cm for f32 positions and PROJ's
/// round trip.
fn terrain_within_its_errors(bundle: &Path, terrain: &TileInfo, transform: &[f64]) {
    let points = grid_points_on_the_ellipsoid(bundle, 1);
    let tiles = with_contents(terrain);
    let finest_error = tiles.iter().map(|t| t.error_m).fold(f64::MAX, f64::min);
    assert_eq!(finest_error, 0.0, "the finest tiles keep every vertex");
    let (mut checked_at_zero, mut skirted) = (0, 0);
    for t in &tiles {
        let glb = Glb::read(t.content.as_ref().unwrap());
        // The surface, then the skirts hanging from the sides it shares.
        let primitives = glb.doc["meshes"][0]["primitives"].as_array().unwrap();
        skirted += usize::from(primitives.len() == 2);
        let node = &glb.doc["nodes"][0];
        let primitive = &glb.doc["meshes"][0]["primitives"][0];
        let positions = glb.accessor(&primitive["attributes"]["POSITION"]);
        let indices = glb.accessor(&primitive["indices"]);
        let ecef: Vec<[f64; 3]> = positions
            .iter()
            .map(|p| to_ecef(transform, node_point(node, p)))
            .collect();
        let vertices = geodetic(&ecef);
        // Every vertex inside the tile's region.
        let r = &t.region;
        for v in &vertices {
            let (lon, lat) = (v[0].to_radians(), v[1].to_radians());
            assert!(
                lon >= r[0] - 1e-9
                    && lon <= r[2] + 1e-9
                    && lat >= r[1] - 1e-9
                    && lat <= r[3] + 1e-9
            );
            assert!(v[2] >= r[4] - 0.01 && v[2] <= r[5] + 0.01);
        }
        for p in &points {
            for tri in indices.chunks(3) {
                let [a, b, c] = [0, 1, 2].map(|k| vertices[tri[k][0] as usize]);
                let det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
                let u = ((p[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (p[1] - a[1])) / det;
                let v = ((b[0] - a[0]) * (p[1] - a[1]) - (p[0] - a[0]) * (b[1] - a[1])) / det;
                // Inclusive: on the finest level the grid points are vertices.
                if u < -1e-9 || v < -1e-9 || u + v > 1.0 + 1e-9 {
                    continue;
                }
                let h = a[2] + u * (b[2] - a[2]) + v * (c[2] - a[2]);
                assert!(
                    (h - p[2]).abs() <= t.error_m + 0.02,
                    "{}: {h} m at {p:?}, error {} m",
                    t.content.as_ref().unwrap().display(),
                    t.error_m
                );
                if t.error_m == 0.0 {
                    checked_at_zero += 1;
                }
                break;
            }
        }
    }
    assert!(
        skirted * 2 > tiles.len(),
        "{skirted} of {} tiles skirted",
        tiles.len()
    );
    assert!(
        checked_at_zero * 10 > points.len() * 9,
        "{checked_at_zero} of {}",
        points.len()
    );
}

/// Every baked object once, at the database's position (PROJ), upright
/// (its model's up along the ellipsoid's normal), its crown the scale, its
/// id, class and score in the feature metadata.
fn vegetation_where_the_database_puts_it(bundle: &Path, vegetation: &TileInfo, transform: &[f64]) {
    let text = std::fs::read_to_string(bundle.join("vegetation.csv")).unwrap();
    let database: HashMap<u64, Vec<String>> = text
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<String> = l.split(';').map(str::to_string).collect();
            (f[0].parse().unwrap(), f)
        })
        .collect();
    let mut seen: HashMap<u64, [f64; 3]> = HashMap::new();
    let mut ups = Vec::new();
    for t in with_contents(vegetation) {
        let glb = Glb::read(t.content.as_ref().unwrap());
        let metadata = &glb.doc["extensions"]["EXT_structural_metadata"];
        let table = &metadata["propertyTables"][0];
        let values = |name: &str| glb.view(&table["properties"][name]["values"]).to_vec();
        let ids: Vec<u64> = values("id")
            .chunks_exact(8)
            .map(|b| u64::from_le_bytes(b.try_into().unwrap()))
            .collect();
        let classes = values("class");
        let scores: Vec<f32> = values("score")
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        let enum_names = &metadata["schema"]["enums"]["vegetation_class"]["values"];
        for node in glb.doc["nodes"].as_array().unwrap() {
            let instancing = &node["extensions"]["EXT_mesh_gpu_instancing"]["attributes"];
            let translation = glb.accessor(&instancing["TRANSLATION"]);
            let rotation = glb.accessor(&instancing["ROTATION"]);
            let scale = glb.accessor(&instancing["SCALE"]);
            let feature = glb.accessor(&instancing["_FEATURE_ID_0"]);
            for k in 0..translation.len() {
                let row = feature[k][0] as usize;
                let id = ids[row];
                let record = &database[&id];
                let class = enum_names
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|e| e["value"] == classes[row] as u64)
                    .unwrap();
                assert_eq!(class["name"], record[3].as_str());
                assert!((scores[row] as f64 - record[5].parse::<f64>().unwrap()).abs() < 1e-4);
                let size: f64 = record[4].parse().unwrap();
                assert!(
                    scale[k].iter().all(|&s| (s - size).abs() < 1e-3),
                    "{scale:?}"
                );
                let foot = to_ecef(transform, node_point(node, &translation[k]));
                assert!(seen.insert(id, foot).is_none(), "object {id} twice");
                // The model's up (glTF y) turned by the instance's rotation.
                let q = &rotation[k];
                let (x, y, z, w) = (q[0], q[1], q[2], q[3]);
                let up = [
                    2.0 * (x * y - w * z),
                    1.0 - 2.0 * (x * x + z * z),
                    2.0 * (y * z + w * x),
                ];
                let origin = to_ecef(transform, [0.0; 3]);
                let tip = to_ecef(transform, up);
                ups.push((id, [0, 1, 2].map(|i| tip[i] - origin[i])));
            }
        }
    }
    assert_eq!(seen.len(), database.len(), "every object, once");
    // Where PROJ puts the database's positions.
    let ids: Vec<u64> = seen.keys().copied().collect();
    let feet: Vec<[f64; 3]> = ids.iter().map(|id| seen[id]).collect();
    let decoded = geodetic(&feet);
    let wkt = bundle.with_extension("wkt");
    let manifest: Value =
        serde_json::from_slice(&std::fs::read(bundle.join("manifest.json")).unwrap()).unwrap();
    std::fs::write(&wkt, manifest["crs"]["wkt"].as_str().unwrap()).unwrap();
    let input: String = ids
        .iter()
        .map(|id| format!("{} {}\n", database[id][1], database[id][2]))
        .collect();
    let expected: Vec<Vec<f64>> = gdaltransform(
        &[
            "-s_srs",
            wkt.to_str().unwrap(),
            "-t_srs",
            "+proj=longlat +datum=WGS84",
        ],
        &input,
    )
    .lines()
    .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
    .collect();
    for (d, e) in decoded.iter().zip(&expected) {
        // 1e-7° is 1 cm.
        assert!(
            (d[0] - e[0]).abs() < 1e-7 && (d[1] - e[1]).abs() < 1e-7,
            "{d:?} {e:?}"
        );
    }
    // Upright: the model's up along the ellipsoid's normal at the foot.
    let normal_at = |lon: f64, lat: f64| {
        let (lon, lat) = (lon.to_radians(), lat.to_radians());
        [lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin()]
    };
    let place: HashMap<u64, [f64; 3]> = ids.iter().copied().zip(decoded).collect();
    for (id, up) in ups {
        let p = place[&id];
        let n = normal_at(p[0], p[1]);
        let dot: f64 = (0..3).map(|k| up[k] * n[k]).sum();
        assert!(dot > 1.0 - 1e-6, "object {id} leans: {dot}");
    }
}

#[test]
fn a_folder_that_is_not_an_export_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("photos");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("keep.jpg"), b"mine").unwrap();
    let r = relevo([
        "export".as_ref(),
        "3dtiles".as_ref(),
        dir.path().join("missing.relevo").as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--force".as_ref(),
    ]);
    assert!(!r.status.success());
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(stderr.contains("holds no tileset.json"), "{stderr}");
    assert_eq!(std::fs::read(out.join("keep.jpg")).unwrap(), b"mine");
    let _ = relevo_ok(["export", "3dtiles", "--help"]);
}
