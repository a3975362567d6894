//! The pyramid at scale: `relevo prep --tiled` (heights, LP errors and
//! radii, derived drape, every level) on a real DEM of 8193² and on the
//! fractal written as a GeoTIFF at 16385² and 32769², each run's wall time
//! and peak resident memory beside GDAL doing less on the same file in the
//! same run: overviews alone (`gdaladdo`, on a copy) and a cloud-optimised
//! GeoTIFF with its overviews (`gdal_translate -of COG`); then the readers
//! over each pyramid (`relevo mesh`, whole and a window; `relevo render`
//! with the levels as bands; `relevo-view bench`, the viewer paging its
//! tiles on a scripted flight).

use crate::measure::{emit, median, run_measured, run_measured_output, tempfile_dir};
use anyhow::{bail, Context, Result};
use gdal::raster::Buffer;
use relevo_core::pyramid::{Pyramid, TileKey};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Rows of the fractal written at a time.
const WRITE_ROWS: usize = 1024;

/// One input of the benchmark: a single-band GeoTIFF on a projected grid.
struct Input {
    name: String,
    what: &'static str,
    path: PathBuf,
}

pub fn run(repo: &Path, runs: usize, max_side: usize, json_lines: bool) -> Result<()> {
    let relevo = relevo_exe()?;
    let scratch = tempfile_dir()?;
    let mut inputs = vec![Input {
        name: "grenoble 8193²".into(),
        what: "Copernicus GLO-30 over Grenoble warped by gdalwarp to UTM 31N at 20 m (3500×5000 cells)",
        path: grenoble_utm(repo, &scratch, 20.0, [660000.0, 4990000.0, 730000.0, 5090000.0])?,
    }];
    for side in [16385, 32769].into_iter().filter(|&s| s <= max_side) {
        inputs.push(Input {
            name: format!("fractal {side}²"),
            what: "relevo_core::grid::fractal_heights written as a tiled GeoTIFF, 10 m cells",
            path: fractal_tif(&scratch, side)?,
        });
    }
    for input in &inputs {
        let out = scratch.join("pyramid.relevo");
        let mut relevo_ms = Vec::new();
        let mut relevo_mb: f64 = 0.0;
        for _ in 0..runs {
            let _ = std::fs::remove_dir_all(&out);
            let (ms, mb) = run_measured(
                Command::new(&relevo)
                    .args(["prep", "--tiled", "-q", "--dem"])
                    .arg(&input.path)
                    .arg("--out")
                    .arg(&out),
            )?;
            relevo_ms.push(ms);
            relevo_mb = relevo_mb.max(mb);
        }
        let pyramid = Pyramid::open(&out)?;
        let (side, levels, tiles) = (
            pyramid.layout.side,
            pyramid.manifest.tiling.levels,
            pyramid.manifest.tiling.tiles,
        );
        let pyramid_bytes: u64 = pyramid.manifest.files.values().map(|a| a.bytes).sum();
        readers(&relevo, &pyramid, &out, &input.name, runs, json_lines)?;
        drop(pyramid);
        std::fs::remove_dir_all(&out)?;
        // GDAL: the same number of coarser levels as overviews of a copy.
        let factors: Vec<String> = (1..levels).map(|l| (1u32 << l).to_string()).collect();
        let copy = scratch.join("overviews.tif");
        let mut addo_ms = Vec::new();
        let mut addo_mb: f64 = 0.0;
        for _ in 0..runs {
            std::fs::copy(&input.path, &copy).context("copying the input for gdaladdo")?;
            let (ms, mb) = run_measured(
                Command::new("gdaladdo")
                    .args([
                        "-q",
                        "--config",
                        "GDAL_NUM_THREADS",
                        "ALL_CPUS",
                        "-r",
                        "average",
                    ])
                    .arg(&copy)
                    .args(&factors),
            )?;
            addo_ms.push(ms);
            addo_mb = addo_mb.max(mb);
        }
        std::fs::remove_file(&copy)?;
        let cog = scratch.join("cog.tif");
        let mut cog_ms = Vec::new();
        let mut cog_mb: f64 = 0.0;
        for _ in 0..runs {
            let _ = std::fs::remove_file(&cog);
            let (ms, mb) = run_measured(
                Command::new("gdal_translate")
                    .args([
                        "-q",
                        "--config",
                        "GDAL_NUM_THREADS",
                        "ALL_CPUS",
                        "-of",
                        "COG",
                    ])
                    .args(["-co", "COMPRESS=NONE", "-co", "BIGTIFF=YES"])
                    .arg(&input.path)
                    .arg(&cog),
            )?;
            cog_ms.push(ms);
            cog_mb = cog_mb.max(mb);
        }
        std::fs::remove_file(&cog)?;
        let (relevo_ms, addo_ms, cog_ms) = (median(&relevo_ms), median(&addo_ms), median(&cog_ms));
        emit(
            json_lines,
            json!({"bench": "pyramid", "input": input.name, "what": input.what, "side": side,
                   "levels": levels, "tiles": tiles, "runs": runs, "threads": rayon::current_num_threads(),
                   "relevo_prep_tiled_ms": relevo_ms, "relevo_peak_rss_mb": relevo_mb,
                   "pyramid_bytes": pyramid_bytes,
                   "gdaladdo_ms": addo_ms, "gdaladdo_peak_rss_mb": addo_mb,
                   "gdal_cog_ms": cog_ms, "gdal_cog_peak_rss_mb": cog_mb}),
            format!(
                "pyramid {} ({levels} levels, {tiles} tiles): relevo prep --tiled {:.1} s, peak {relevo_mb:.0} MB; \
                 gdaladdo {:.1} s, peak {addo_mb:.0} MB; gdal_translate -of COG {:.1} s, peak {cog_mb:.0} MB",
                input.name,
                relevo_ms / 1e3,
                addo_ms / 1e3,
                cog_ms / 1e3
            ),
        );
    }
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}

/// The readers over the pyramid just built, each command's wall time and
/// peak memory: the whole region's mesh at 5 m, a 1024-cell window's at
/// 0.5 m at the data's centre, and 1280×720 raycasts whose bands are the
/// levels (1 and 2 pixels a cell) from 500 m above the highest point over
/// the data's south-west quarter, looking north-east.
fn readers(
    relevo: &Path,
    pyramid: &Pyramid,
    out: &Path,
    name: &str,
    runs: usize,
    json_lines: bool,
) -> Result<()> {
    let grid = &pyramid.manifest.grid;
    let cell = grid.cell_size_m;
    // Within the data: its extent's centre, and its south-west quarter.
    let [x0, y0, x1, y1] = grid.valid_extent;
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let half = 512.0 * cell;
    let window = format!("{},{},{},{}", cx - half, cy - half, cx + half, cy + half);
    let (ex, ey) = (x0 + (x1 - x0) / 4.0, y0 + (y1 - y0) / 4.0);
    let eye_z = grid.height_range_m[1] as f64 + 500.0;
    let camera = format!("{ex},{ey},{eye_z},45,-10deg");
    let side = grid.side as f64;
    let far = format!("{}", side);
    let glb = out.with_extension("glb");
    let png = out.with_extension("png");
    let out_str = |p: &Path| p.to_string_lossy().to_string();
    let commands: [(&str, Vec<String>); 4] = [
        (
            "mesh, whole region, 5 m",
            vec![
                "mesh".into(),
                "--max-error".into(),
                "5".into(),
                "--out".into(),
                out_str(&glb),
            ],
        ),
        (
            "mesh, 1024² window, 0.5 m",
            vec![
                "mesh".into(),
                "--max-error".into(),
                "0.5".into(),
                "--window".into(),
                window,
                "--out".into(),
                out_str(&glb),
            ],
        ),
        (
            "render 1280×720, 1 px a cell",
            vec![
                "render".into(),
                "--camera".into(),
                camera.clone(),
                "--size".into(),
                "1280x720".into(),
                "--far".into(),
                far.clone(),
                "--max-cell-px".into(),
                "1".into(),
                "--out".into(),
                out_str(&png),
            ],
        ),
        (
            "render 1280×720, 2 px a cell",
            vec![
                "render".into(),
                "--camera".into(),
                camera,
                "--size".into(),
                "1280x720".into(),
                "--far".into(),
                far,
                "--max-cell-px".into(),
                "2".into(),
                "--out".into(),
                out_str(&png),
            ],
        ),
    ];
    for (what, args) in commands {
        let (mut times, mut peak) = (Vec::new(), 0.0f64);
        for _ in 0..runs {
            let (ms, mb) = run_measured(
                Command::new(relevo)
                    .arg(&args[0])
                    .arg(out)
                    .args(&args[1..])
                    .args(["--force", "-q"]),
            )?;
            times.push(ms);
            peak = peak.max(mb);
        }
        let ms = median(&times);
        emit(
            json_lines,
            json!({"bench": "pyramid_reader", "input": name, "what": what, "runs": runs,
                   "threads": rayon::current_num_threads(), "ms": ms, "peak_rss_mb": peak}),
            format!(
                "pyramid {name}: {what} {:.2} s, peak {peak:.0} MB",
                ms / 1e3
            ),
        );
    }
    let _ = std::fs::remove_file(&glb);
    let _ = std::fs::remove_file(&png);
    fly(relevo, out, name, json_lines)
}

/// `relevo-view bench` over the pyramid (1280×720, 30 frames a leg, on
/// whatever GPU `VK_ICD_FILENAMES` picks — lavapipe in the documented
/// runs), with one frame in flight and with two (the next frame refined
/// while the GPU draws the current one): each mode's frame times and
/// paging figures as the viewer reports them, with the whole process's
/// peak memory.
fn fly(relevo: &Path, out: &Path, name: &str, json_lines: bool) -> Result<()> {
    let viewer = relevo.with_file_name("relevo-view");
    if !viewer.is_file() {
        bail!(
            "{}: not built; run `cargo build --release -p relevo-view` first",
            viewer.display()
        );
    }
    for in_flight in ["1", "2"] {
        let (ms, peak, records) = run_measured_output(
            Command::new(&viewer)
                .arg("bench")
                .arg(out)
                .args(["--size", "1280x720", "--frames", "30", "--json"])
                .args(["--in-flight", in_flight]),
        )?;
        emit_flights(&records, name, ms, peak, json_lines)?;
    }
    Ok(())
}

/// The flight records of one `relevo-view bench` run, with the process's
/// time `ms` and peak memory `peak` (MB).
fn emit_flights(records: &str, name: &str, ms: f64, peak: f64, json_lines: bool) -> Result<()> {
    for line in records.lines() {
        let mut record: serde_json::Value = serde_json::from_str(line)
            .with_context(|| format!("relevo-view bench printed {line:?}"))?;
        if record["bench"] != "view-flight" {
            continue;
        }
        record["input"] = json!(name);
        record["process_peak_rss_mb"] = json!(peak);
        record["process_ms"] = json!(ms);
        let text = format!(
            "pyramid {name}: relevo-view bench {} ({} in flight): p50 {:.1} ms, p99 {:.1} ms, {} paging stalls, {} tiles read, {} dropped; process peak {peak:.0} MB",
            record["config"].as_str().unwrap_or(""),
            record["in_flight"],
            record["frame_ms_p50"].as_f64().unwrap_or(f64::NAN),
            record["frame_ms_p99"].as_f64().unwrap_or(f64::NAN),
            record["paging_stalls"],
            record["tiles_loaded"],
            record["tiles_evicted"],
        );
        emit(json_lines, record, text);
    }
    Ok(())
}

/// The `relevo` binary built beside this one.
pub fn relevo_exe() -> Result<PathBuf> {
    let exe = std::env::current_exe()?.with_file_name("relevo");
    if !exe.is_file() {
        bail!(
            "{}: not built; run `cargo build --release -p relevo` first",
            exe.display()
        );
    }
    Ok(exe)
}

/// The committed Grenoble DEM warped to UTM 31N at `cell_m` over `extent`
/// (`[xmin, ymin, xmax, ymax]`, inside the tile: no voids).
pub fn grenoble_utm(repo: &Path, dir: &Path, cell_m: f64, extent: [f64; 4]) -> Result<PathBuf> {
    let out = dir.join(format!("grenoble_utm31n_{cell_m}m.tif"));
    let dem = repo.join("data/grenoble/Copernicus_DSM_10_N45_00_E005_00_DEM.tif");
    let cell = cell_m.to_string();
    let status = Command::new("gdalwarp")
        .args(["-q", "-overwrite", "-t_srs", "EPSG:32631", "-r", "bilinear"])
        .args(["-tr", &cell, &cell, "-co", "TILED=YES", "-te"])
        .args(extent.map(|v| v.to_string()))
        .arg(&dem)
        .arg(&out)
        .status()
        .context("running gdalwarp")?;
    if !status.success() {
        bail!("gdalwarp of {} failed", dem.display());
    }
    Ok(out)
}

/// The fractal of `side`² written as a tiled Float32 GeoTIFF (UTM 31N,
/// 10 m cells).
fn fractal_tif(dir: &Path, side: usize) -> Result<PathBuf> {
    let path = dir.join(format!("fractal_{side}.tif"));
    let heights = relevo_core::grid::fractal_heights(side, 1);
    let driver = gdal::DriverManager::get_driver_by_name("GTiff")?;
    let options = gdal::raster::RasterCreationOptions::from_iter(["TILED=YES", "BIGTIFF=YES"]);
    let mut ds =
        driver.create_with_band_type_with_options::<f32, _>(&path, side, side, 1, &options)?;
    ds.set_geo_transform(&[600000.0, 10.0, 0.0, 5100000.0, 0.0, -10.0])?;
    ds.set_spatial_ref(&gdal::spatial_ref::SpatialRef::from_epsg(32631)?)?;
    let mut band = ds.rasterband(1)?;
    for r0 in (0..side).step_by(WRITE_ROWS) {
        let rows = WRITE_ROWS.min(side - r0);
        let mut buffer = Buffer::new(
            (side, rows),
            heights[r0 * side..(r0 + rows) * side].to_vec(),
        );
        band.write((0, r0 as isize), (side, rows), &mut buffer)?;
    }
    Ok(path)
}

/// docs/images/pyramid_layout.png: the levels of a real pyramid (Grenoble
/// warped to UTM at 30 m, a 1025² grid in tiles of 128 cells) side by side,
/// each level's derived drape with its tiles' borders.
pub fn picture(repo: &Path, out: &Path) -> Result<()> {
    const PANEL: usize = 300;
    const GAP: usize = 12;
    let relevo = relevo_exe()?;
    let scratch = tempfile_dir()?;
    let dem = grenoble_utm(
        repo,
        &scratch,
        30.0,
        [660000.0, 4990000.0, 690000.0, 5020000.0],
    )?;
    let bundle = scratch.join("layout.relevo");
    run_measured(
        Command::new(&relevo)
            .args(["prep", "--tiled", "--tile-size", "128", "-q", "--dem"])
            .arg(&dem)
            .arg("--out")
            .arg(&bundle),
    )?;
    let p = Pyramid::open(&bundle)?;
    let (t, levels) = (p.layout.tile_cells, p.layout.levels() as usize);
    let width = levels * (PANEL + GAP) + GAP;
    let height = PANEL + 2 * GAP;
    let mut rgba: Vec<u8> = [232u8, 238, 240, 255].repeat(width * height);
    for level in 0..levels {
        let n = (p.layout.side - 1) / p.layout.stride(level as u32) + 1;
        let across = p.layout.across(level as u32);
        let x0 = GAP + level * (PANEL + GAP);
        for py in 0..PANEL {
            for px in 0..PANEL {
                let (c, r) = (px * (n - 1) / (PANEL - 1), py * (n - 1) / (PANEL - 1));
                let key = TileKey {
                    level: level as u32,
                    x: (c / t).min(across - 1),
                    y: (r / t).min(across - 1),
                };
                let tile = p.tile(key)?;
                let i = (r - key.y * t) * (t + 1) + (c - key.x * t);
                // A tile border: a sample on it, or the panel's pixel
                // that steps over one.
                let next = |v: usize| (v + 1) * (n - 1) / (PANEL - 1);
                let border =
                    c % t == 0 || r % t == 0 || next(px) / t != c / t || next(py) / t != r / t;
                let o = ((GAP + py) * width + x0 + px) * 4;
                if border {
                    rgba[o..o + 4].copy_from_slice(&[255, 255, 255, 255]);
                } else if tile.mask[i] == 1 {
                    rgba[o..o + 4].copy_from_slice(&tile.drape[4 * i..4 * i + 4]);
                }
            }
        }
    }
    let bytes = relevo_core::raster::png::encode_rgba(&rgba, width, height)?;
    let file = out.join("pyramid_layout.png");
    relevo_core::atomic::write_file(&file, &bytes)?;
    println!("{}", file.display());
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}
