//! Helpers shared by the end-to-end tests: running the `relevo` binary,
//! locating the shared real inputs, and reading rasters back with GDAL.
#![allow(dead_code)]

use gdal::raster::Buffer;
use gdal::Dataset;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

#[path = "../../../../tests/src/forge.rs"]
mod forge;
#[path = "../../../../tests/src/paths.rs"]
mod paths;
#[allow(unused_imports)] // each test file uses its own part
pub use forge::{forged, rehash};
#[allow(unused_imports)] // each test file uses its own part
pub use paths::{repo, shared};

/// Run `relevo ARGS…` and return its output.
pub fn relevo<I, S>(args: I) -> Output
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    Command::new(env!("CARGO_BIN_EXE_relevo"))
        .args(args)
        .output()
        .expect("relevo runs")
}

/// Run `relevo`, asserting success, and return stdout.
pub fn relevo_ok<I, S>(args: I) -> String
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    let out = relevo(args);
    assert!(
        out.status.success(),
        "relevo failed: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// `relevo prep` of the sample region into `dir/olinda.relevo`.
pub fn sample_bundle(dir: &Path) -> PathBuf {
    let out = dir.join("olinda.relevo");
    relevo_ok([
        "prep".as_ref(),
        repo("data/olinda/REGION.toml").as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    out
}

/// Run a GDAL command-line program (gdal-bin), asserting success.
pub fn gdal_tool(program: &str, args: &[&str]) {
    let out = Command::new(program)
        .args(args)
        .output()
        .expect("gdal-bin is installed");
    assert!(
        out.status.success(),
        "{program} {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A raster read back: size, geotransform, nodata and band 1..n as f64.
pub struct Read {
    pub width: usize,
    pub height: usize,
    pub geotransform: [f64; 6],
    pub nodata: Option<f64>,
    pub bands: Vec<Vec<f64>>,
}

pub fn read(path: &Path) -> Read {
    let ds = Dataset::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let (width, height) = ds.raster_size();
    let nodata = ds.rasterband(1).unwrap().no_data_value();
    let bands = (1..=ds.raster_count())
        .map(|b| {
            let buf: Buffer<f64> = ds
                .rasterband(b)
                .unwrap()
                .read_as((0, 0), (width, height), (width, height), None)
                .unwrap();
            buf.data().to_vec()
        })
        .collect();
    Read {
        width,
        height,
        geotransform: ds.geo_transform().unwrap_or([0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
        nodata,
        bands,
    }
}

/// SHA-256 of a file, hex.
pub fn sha256(path: &Path) -> String {
    relevo_core::bundle::sha256_file(path).unwrap().1
}

/// Write a one-band Float32 GeoTIFF (EPSG:32633, 30 m cells) for bad-input cases.
pub fn write_f32_tif(path: &Path, width: usize, height: usize, data: &[f32], nodata: Option<f64>) {
    use gdal::DriverManager;
    let driver = DriverManager::get_driver_by_name("GTiff").unwrap();
    let mut ds = driver
        .create_with_band_type::<f32, _>(path, width, height, 1)
        .unwrap();
    ds.set_geo_transform(&[500000.0, 30.0, 0.0, 4000000.0, 0.0, -30.0])
        .unwrap();
    ds.set_spatial_ref(&gdal::spatial_ref::SpatialRef::from_epsg(32633).unwrap())
        .unwrap();
    let mut band = ds.rasterband(1).unwrap();
    if let Some(nd) = nodata {
        band.set_no_data_value(Some(nd)).unwrap();
    }
    let mut buf = Buffer::new((width, height), data.to_vec());
    band.write((0, 0), (width, height), &mut buf).unwrap();
}

/// Names of the entries of a folder, sorted.
pub fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .collect();
    names.sort();
    names
}

/// The three Terrain-RGB / Terrarium tiles martini's digests describe:
/// (name in martini_js.json, file, `--encoding`).
pub const MARTINI_TILES: [(&str, &str, &str); 3] = [
    ("fuji", "fuji.png", "terrain-rgb"),
    ("mapbox_st_helens", "mapbox_st_helens.png", "terrain-rgb"),
    ("terrarium", "terrarium.png", "terrarium"),
];

/// martini_js.json: the digests @mapbox/martini produced from those tiles.
pub fn martini_reference() -> serde_json::Value {
    serde_json::from_str(
        &std::fs::read_to_string(shared("terrain_rgb_martini/martini_js.json")).unwrap(),
    )
    .unwrap()
}

/// `relevo prep` of one martini tile into `dir`; returns the bundle path.
pub fn prep_martini_tile(dir: &Path, file: &str, encoding: &str) -> PathBuf {
    let out = dir.join(format!("{file}.relevo"));
    let png = shared(&format!("terrain_rgb_martini/{file}"));
    relevo_ok([
        "prep".as_ref(),
        "--dem".as_ref(),
        png.as_os_str(),
        "--encoding".as_ref(),
        encoding.as_ref(),
        // Tiles without georeferencing: one metre per pixel, as martini.
        "--cell-size".as_ref(),
        "1".as_ref(),
        // martini's errors, so its meshes can be compared vertex for vertex.
        "--error-metric".as_ref(),
        "midpoint".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    out
}

/// The sample region copied into `dir/region` (so its inputs can be edited).
pub fn region_copy(dir: &Path) -> PathBuf {
    let region = dir.join("region");
    std::fs::create_dir_all(&region).unwrap();
    for entry in std::fs::read_dir(repo("data/olinda")).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), region.join(entry.file_name())).unwrap();
    }
    region
}

/// Add `metres` to `raster` inside the rectangle of `cells` (column, row,
/// columns, rows) of its grid, with GDAL's own tools.
pub fn burn(raster: &Path, epsg: u32, cells: [usize; 4], metres: f64, band: Option<u32>) {
    rasterize(raster, epsg, cells, metres, band, true);
}

/// Set `raster`'s cells inside the rectangle of `cells` (column, row,
/// columns, rows) to `value` (its no-data value makes a void).
pub fn set_cells(raster: &Path, epsg: u32, cells: [usize; 4], value: f64) {
    rasterize(raster, epsg, cells, value, None, false);
}

/// `gdal_rasterize` of the rectangle of `cells` into `raster`: `value`
/// added (`add`) or written, in `band` or all.
fn rasterize(
    raster: &Path,
    epsg: u32,
    [c, r, w, h]: [usize; 4],
    value: f64,
    band: Option<u32>,
    add: bool,
) {
    let info = Dataset::open(raster).unwrap().geo_transform().unwrap();
    let at = |col: usize, row: usize| {
        [
            info[0] + col as f64 * info[1],
            info[3] + row as f64 * info[5],
        ]
    };
    let (p0, p1) = (at(c, r), at(c + w, r + h));
    let polygon = raster.with_extension("burn.geojson");
    std::fs::write(
        &polygon,
        format!(
            r#"{{"type":"FeatureCollection","crs":{{"type":"name","properties":{{"name":"EPSG:{epsg}"}}}},
            "features":[{{"type":"Feature","properties":{{}},"geometry":{{"type":"Polygon",
            "coordinates":[[[{x0},{y0}],[{x1},{y0}],[{x1},{y1}],[{x0},{y1}],[{x0},{y0}]]]}}}}]}}"#,
            x0 = p0[0],
            y0 = p0[1],
            x1 = p1[0],
            y1 = p1[1]
        ),
    )
    .unwrap();
    let burn = value.to_string();
    let band_arg = band.map(|b| b.to_string());
    let mut args = vec!["-q", "-burn", &burn];
    if add {
        args.push("-add");
    }
    if let Some(b) = &band_arg {
        args.extend(["-b", b]);
    }
    args.extend([polygon.to_str().unwrap(), raster.to_str().unwrap()]);
    gdal_tool("gdal_rasterize", &args);
    std::fs::remove_file(polygon).unwrap();
}

/// Run the Khronos validator (installed by scripts/setup-test) on a .glb.
pub fn khronos_validate(path: &Path) -> serde_json::Value {
    khronos_validate_all(&[path.to_path_buf()]).remove(0)
}

/// Run the Khronos validator on .glb files, in one process: each file's
/// report, asserting none has errors.
pub fn khronos_validate_all(paths: &[PathBuf]) -> Vec<serde_json::Value> {
    let script = repo("tools/js/validate-gltf.mjs");
    let out = Command::new("node")
        .arg(script)
        .args(paths)
        .output()
        .expect("node is installed by scripts/setup-test");
    let reports: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|line| {
            serde_json::from_str(line).unwrap_or_else(|_| {
                panic!(
                    "validator output: {line}\n{}",
                    String::from_utf8_lossy(&out.stderr)
                )
            })
        })
        .collect();
    assert_eq!(
        reports.len(),
        paths.len(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.status.success(),
        "glTF validator found errors: {:?}",
        reports
            .iter()
            .filter(|r| r["numErrors"] != 0)
            .collect::<Vec<_>>()
    );
    reports
}

/// The real Grenoble DEM (Copernicus GLO-30, geographic).
pub fn grenoble_dem() -> PathBuf {
    repo("data/grenoble/Copernicus_DSM_10_N45_00_E005_00_DEM.tif")
}

/// The Grenoble DEM warped by GDAL to UTM 31N at 30 m (1000² cells, no
/// voids): a DEM already on the target grid, which `prep --tiled` reads
/// window by window.
pub fn projected_dem(dir: &Path) -> PathBuf {
    projected_dem_named(dir, "grenoble_utm31n_30m.tif", &[])
}

/// [`projected_dem`] written as `name` with gdalwarp's `extra` options.
pub fn projected_dem_named(dir: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let out = dir.join(name);
    let mut args = vec![
        "-q",
        "-t_srs",
        "EPSG:32631",
        "-tr",
        "30",
        "30",
        "-r",
        "bilinear",
        "-te",
        "660000",
        "4990000",
        "690000",
        "5020000",
    ];
    args.extend(extra);
    let input = grenoble_dem();
    args.extend([input.to_str().unwrap(), out.to_str().unwrap()]);
    gdal_tool("gdalwarp", &args);
    out
}

/// What must be equal between two pyramids built alike: the tile files'
/// hashes and the manifest without its wall times.
pub fn pyramid_contents(p: &Path) -> (Vec<String>, serde_json::Value) {
    let tiles = ["height.f32", "mask.u8", "lp.f32x2", "drape.rgba8"]
        .iter()
        .map(|f| sha256(&p.join("tiles").join(f)))
        .collect();
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(p.join("manifest.json")).unwrap()).unwrap();
    manifest.as_object_mut().unwrap().remove("timings");
    (tiles, manifest)
}

/// Bundle grid points (every `step`-th, away from no-data) as longitude,
/// latitude and ellipsoidal height, by `gdaltransform` (PROJ): the bundle's
/// CRS to WGS84, then EGM96 heights to ellipsoidal ones.
pub fn grid_points_on_the_ellipsoid(bundle: &Path, step: usize) -> Vec<[f64; 3]> {
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(bundle.join("manifest.json")).unwrap()).unwrap();
    let side = manifest["grid"]["side"].as_u64().unwrap() as usize;
    let gt = manifest["grid"]["geotransform"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect::<Vec<f64>>();
    let heights: Vec<f32> = std::fs::read(bundle.join("height.f32"))
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let mask = std::fs::read(bundle.join("mask.u8")).unwrap();
    let mut input = String::new();
    for r in (1..side - 1).step_by(step) {
        for c in (1..side - 1).step_by(step) {
            let all_data =
                (r - 1..=r + 1).all(|j| (c - 1..=c + 1).all(|i| mask[j * side + i] != 0));
            if all_data {
                let (x, y) = (
                    gt[0] + (c as f64 + 0.5) * gt[1],
                    gt[3] + (r as f64 + 0.5) * gt[5],
                );
                input += &format!("{x} {y} {}\n", heights[r * side + c]);
            }
        }
    }
    let wkt = bundle.with_extension("wkt");
    std::fs::write(&wkt, manifest["crs"]["wkt"].as_str().unwrap()).unwrap();
    let geographic = gdaltransform(
        &[
            "-s_srs",
            wkt.to_str().unwrap(),
            "-t_srs",
            "+proj=longlat +datum=WGS84",
        ],
        &input,
    );
    // gdaltransform keeps longitude first for geographic CRSs.
    let ellipsoidal = gdaltransform(
        &["-s_srs", "EPSG:4326+5773", "-t_srs", "EPSG:4979"],
        &geographic,
    );
    ellipsoidal
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

/// `gdaltransform ARGS` (PROJ's transforms from the command line) on the
/// points of `input`, one `x y [z]` a line: its output lines.
pub fn gdaltransform(args: &[&str], input: &str) -> String {
    use std::io::Write;
    let mut child = Command::new("gdaltransform")
        .args(args)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("gdal-bin is installed");
    // Written from another thread: the output fills its pipe while a long
    // input is still being written.
    let mut stdin = child.stdin.take().unwrap();
    let input = input.to_string();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()).unwrap());
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    assert!(out.status.success());
    String::from_utf8(out.stdout).unwrap()
}

/// Every file under `dir`, relative, with its SHA-256.
pub fn file_hashes(dir: &Path) -> std::collections::BTreeMap<String, String> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let name = path.strip_prefix(dir).unwrap().display().to_string();
                out.insert(name, sha256(&path));
            }
        }
    }
    out
}
