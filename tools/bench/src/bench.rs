//! The ingest, hierarchy and vegetation runners: measured figures, side by side with reference
//! tools, as text or one JSON object per line. Timings are medians of
//! repeated runs of release builds; nothing here is asserted by tests.

use crate::measure::{emit, median, median_ms, srtm_padded, tempfile_dir};
use anyhow::{bail, Context, Result};
use relevo::ingest::gdalio;
use relevo::ingest::stitch::{stitch, StitchOptions};
use relevo::prep::prep;
use relevo::prep::region::RegionSpec;
use relevo_core::grid::fractal_heights;
use relevo_core::raster::mosaic::Overlap;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Ingest figures: `prep` on the sample region, and `stitch` on the Landsat
/// overlap against gdalwarp doing the same job.
pub fn ingest(repo: &Path, data: &Path, runs: usize, json_lines: bool) -> Result<()> {
    let scratch = tempfile_dir()?;

    // prep on the sample region: first run in this process, then the median.
    let region = RegionSpec::load(&repo.join("data/olinda/REGION.toml"))?;
    let out = scratch.join("olinda.relevo");
    let first = median_ms(1, || prep(&region, &out, true).map(|_| ()))?;
    let median = median_ms(runs, || prep(&region, &out, true).map(|_| ()))?;
    emit(
        json_lines,
        json!({"bench": "prep", "region": "olinda", "first_ms": first, "ms": median, "runs": runs}),
        format!(
            "prep olinda (129² grid, 351² drape): first run {first:.1} ms, median {median:.1} ms"
        ),
    );

    // stitch vs gdalwarp on two Landsat 8 scenes with a 0 collar.
    let dir = data.join("tiles/landsat8_overlap");
    let tiles: Vec<PathBuf> = ["224077", "224078"]
        .iter()
        .map(|s| dir.join(format!("LC08_L1TP_{s}_20200518_20200518_01_RT_B4.TIF")))
        .collect();
    for t in &tiles {
        if !t.exists() {
            bail!(
                "{}: missing (pass --data with the shared data folder)",
                t.display()
            );
        }
    }
    let ours_out = scratch.join("ours.tif");
    for (label, overlap) in [("blend", Overlap::Blend), ("first", Overlap::First)] {
        let opts = StitchOptions {
            src_nodata: Some(0.0),
            overlap,
            ..Default::default()
        };
        let ours = median_ms(runs, || {
            let m = stitch(&tiles, &opts)?;
            let _ = std::fs::remove_file(&ours_out);
            gdalio::write_geotiff(&ours_out, &m.raster, &m.grid, m.band_type, Some(m.nodata))
        })?;
        emit(
            json_lines,
            json!({"bench": "stitch", "input": "landsat8 B4 224077+224078", "overlap": label, "ours_ms": ours}),
            format!("stitch landsat8 B4 (2819×2206), --overlap {label}: {ours:.1} ms"),
        );
    }
    for (label, extra) in [
        ("gdalwarp", &[][..]),
        (
            "gdalwarp -multi",
            &[
                "-multi",
                "-wo",
                "NUM_THREADS=ALL_CPUS",
                "-co",
                "NUM_THREADS=ALL_CPUS",
            ][..],
        ),
    ] {
        let gdal_out = scratch.join("gdalwarp.tif");
        let ms = median_ms(runs, || {
            let _ = std::fs::remove_file(&gdal_out);
            let status = Command::new("gdalwarp")
                .args([
                    "-q",
                    "-srcnodata",
                    "0",
                    "-dstnodata",
                    "0",
                    "-co",
                    "COMPRESS=DEFLATE",
                    "-co",
                    "ZLEVEL=1",
                    "-co",
                    "TILED=YES",
                ])
                .args(extra)
                .args(&tiles)
                .arg(&gdal_out)
                .status()
                .context("cannot run gdalwarp (install gdal-bin)")?;
            if !status.success() {
                bail!("gdalwarp failed");
            }
            Ok(())
        })?;
        emit(
            json_lines,
            json!({"bench": "stitch", "input": "landsat8 B4 224077+224078", "reference": label, "ms": ms}),
            format!("{label} (same tiles, same output options): {ms:.1} ms"),
        );
    }
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}

/// Hierarchy figures: ours beside @mapbox/martini on the same grids, and
/// view-dependent refinement on each grid.
pub fn hierarchy(
    repo: &Path,
    data: &Path,
    runs: usize,
    max_side: usize,
    json_lines: bool,
) -> Result<()> {
    use relevo_core::lp::{ErrorMetric, Hierarchy};

    let scratch = tempfile_dir()?;
    let mut grids: Vec<(String, usize, Vec<f32>)> = [257usize, 1025, 4097, 8193]
        .into_iter()
        .filter(|&s| s <= max_side)
        .map(|s| (format!("fractal {s}²"), s, fractal_heights(s, 1)))
        .collect();
    let square = srtm_padded(data)?;
    grids.push(("srtm_ref padded".into(), square.side, square.heights));

    let script = repo.join("tools/js/martini-bench.mjs");
    for (name, side, heights) in &grids {
        let cell = 30.0;
        // martini's metric against martini; then the bound (the default).
        let ours = median_ms(runs, || {
            std::hint::black_box(Hierarchy::compute(
                heights,
                *side,
                cell,
                ErrorMetric::Midpoint,
            ));
            Ok(())
        })?;
        let bound_ms = median_ms(runs, || {
            std::hint::black_box(Hierarchy::compute(heights, *side, cell, ErrorMetric::Bound));
            Ok(())
        })?;
        let h = Hierarchy::compute(heights, *side, cell, ErrorMetric::Bound);
        let midpoint = Hierarchy::compute(heights, *side, cell, ErrorMetric::Midpoint);
        mesh_bound(name, heights, *side, [&midpoint, &h], json_lines);

        let martini = martini_ms(&script, &scratch, heights, *side, runs)?;

        let Refinement {
            times,
            triangles,
            tiled_ms: refine_tiled_ms,
        } = refinement(&h, heights, *side, cell, runs)?;

        let prep_ms = prep_ms(heights, *side, cell, &scratch)?;

        let refine_ms = median(&times);
        let mtris = (0..8)
            .map(|k| triangles[k] as f64 / times[k] / 1e3)
            .sum::<f64>()
            / 8.0;
        let median_triangles =
            median(&triangles.iter().map(|&t| t as f64).collect::<Vec<_>>()) as usize;
        let msamples = (*side * *side) as f64 / ours / 1e3;
        emit(
            json_lines,
            json!({
                "grid": side, "input": name, "ours_ms": ours, "bound_ms": bound_ms, "martini_ms": martini,
                "speedup": martini.map(|m| m / ours), "msamples_per_s": msamples,
                "refine_ms": refine_ms, "refine_tiled_ms": refine_tiled_ms,
                "triangles": median_triangles, "mtriangles_per_s": mtris, "prep_ms": prep_ms,
            }),
            format!(
                "{name:>16}: errors+radii {ours:8.1} ms ({msamples:6.1} Msamples/s; bound metric {bound_ms:.1} ms), martini createTile {}, refine τ=1px {refine_ms:6.2} ms (tiled {refine_tiled_ms:6.2}) for {median_triangles} triangles ({mtris:.1} M/s), prep {prep_ms:.0} ms",
                martini.map_or("n/a".to_string(), |m| format!("{m:8.1} ms ({:.0}×)", m / ours))
            ),
        );
    }
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}

/// Meshes extracted at 1, 5 and 20 m from the midpoint (martini's) and the
/// bound errors: triangles, extraction time and the largest vertical
/// distance from a grid point to the mesh.
fn mesh_bound(
    name: &str,
    heights: &[f32],
    side: usize,
    [midpoint, bound]: [&relevo_core::lp::Hierarchy; 2],
    json_lines: bool,
) {
    use relevo_core::lp::extract::extract;
    for max_error in [1.0f32, 5.0, 20.0] {
        let figures = [midpoint, bound].map(|h| {
            let start = Instant::now();
            let mesh = extract(h, max_error, None);
            let ms = start.elapsed().as_secs_f64() * 1e3;
            (
                mesh.triangles.len(),
                ms,
                mesh.largest_deviation(heights, side),
            )
        });
        let [(mid_tris, mid_ms, mid_dev), (tris, ms, dev)] = figures;
        emit(
            json_lines,
            json!({"bench": "mesh-bound", "input": name, "max_error_m": max_error,
                   "midpoint": {"triangles": mid_tris, "extract_ms": mid_ms, "largest_deviation_m": mid_dev},
                   "bound": {"triangles": tris, "extract_ms": ms, "largest_deviation_m": dev}}),
            format!(
                "{name:>16}: mesh at {max_error} m — midpoint {mid_tris} triangles ({mid_ms:.1} ms), {mid_dev:.2} m off; bound {tris} triangles ({ms:.1} ms), {dev:.2} m off"
            ),
        );
    }
}

/// Vegetation figures: detection accuracy on the annotated NEON crops beside
/// the excess-green baseline, then split-and-merge and detection speed on
/// images up to `max_side`² beside scikit-image's felzenszwalb (when Python
/// with scikit-image is installed).
pub fn veg(repo: &Path, data: &Path, runs: usize, max_side: usize, json_lines: bool) -> Result<()> {
    use relevo_core::veg::eval;
    use relevo_core::veg::pipeline::{
        extract, extract_watched, RegionMap, VegImage, VegOptions, Watch,
    };

    let options = VegOptions::default();
    let yellowstone = veg_accuracy(repo, data, &options, json_lines)?;

    // Speed: the Yellowstone crop, and the crop mirrored into larger
    // images, with its truth boxes mirrored the same way.
    let (crop, samples, crop_truth) = yellowstone.context("no Yellowstone crop")?;
    let scratch = tempfile_dir()?;
    let script = repo.join("tools/py/felzenszwalb_bench.py");
    let relevo = relevo_binary()?;
    let watch = Watch::default();
    let mut sides = vec![0usize];
    sides.extend(
        [2500usize, 5000, 10000]
            .into_iter()
            .filter(|&s| s <= max_side),
    );
    for side in sides {
        let (image, truth) = if side == 0 {
            (crop.image.clone(), crop_truth.clone())
        } else {
            (
                mirror_tile(&crop.image, side)?,
                mirror_boxes(&crop_truth, crop.image.width, crop.image.height, side),
            )
        };
        let (w, h) = (image.width, image.height);
        let mpx = (w * h) as f64 / 1e6;
        let veg_image = VegImage {
            image,
            crs_wkt: String::new(),
            geotransform: None,
            pixel_m: 0.1,
            valid: None,
        };
        let mut runs_done = Vec::new();
        for _ in 0..runs {
            // As `veg detect` without a labels raster: no region map.
            let start = Instant::now();
            let r = extract_watched(&veg_image, &samples, &options, RegionMap::Skip, &watch)?;
            runs_done.push((start.elapsed().as_secs_f64() * 1e3, r));
        }
        runs_done.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (total_ms, tiled) = runs_done.swap_remove(runs_done.len() / 2);
        drop(runs_done);
        let report = &tiled.report;
        let steps = tiled.steps;
        let f1 = |e: &relevo_core::veg::pipeline::Extraction| {
            eval::evaluate(
                &eval::Detection::of_objects(&e.objects, 1.0),
                &truth,
                eval::Criterion::Centre,
            )
            .f1
        };
        let tiled_f1 = f1(&tiled);
        // The same image analysed whole (one tile), up to 25 Mpx: how far
        // the tiled result is from it.
        let whole = if report.tiles > 1 && mpx <= 25.0 {
            let whole_options = VegOptions {
                tile_px: w.max(h),
                ..options.clone()
            };
            let start = Instant::now();
            let r = extract(&veg_image, &samples, &whole_options)?;
            let ms = start.elapsed().as_secs_f64() * 1e3;
            let again = r
                .objects
                .iter()
                .filter(|o| {
                    tiled
                        .objects
                        .iter()
                        .any(|t| (t.x - o.x).abs() <= 1.0 && (t.y - o.y).abs() <= 1.0)
                })
                .count();
            Some(
                json!({"ms": ms, "objects": r.objects.len(), "found_again_by_tiles": again,
                        "f1": f1(&r)}),
            )
        } else {
            None
        };
        // The command itself on the image as a file: wall time and peak memory.
        let cli = relevo_detect(&relevo, &scratch, &veg_image.image, repo)?;
        // felzenszwalb runs at about 0.3 Mpx/s here: once above 2 Mpx, and
        // not at all above 25 Mpx (it would take minutes per run).
        let fz_runs = if mpx > 2.0 { 1 } else { runs.min(3) };
        let felzenszwalb = felzenszwalb(&script, &scratch, &veg_image.image, fz_runs, mpx)?;
        let fz_ms = felzenszwalb.as_ref().and_then(|v| v["ms"].as_f64());
        emit(
            json_lines,
            json!({"bench": "veg-speed", "width": w, "height": h, "mpx": mpx,
                   "threads": rayon::current_num_threads(), "tiles": report.tiles,
                   "total_ms": total_ms, "total_mpx_s": mpx / total_ms * 1e3,
                   "segment_ms_summed": report.segment_ms, "classify_ms_summed": report.classify_ms,
                   "place_ms_summed": report.detect_ms, "segment_steps_summed": steps,
                   "objects": report.objects, "f1": tiled_f1, "whole": whole,
                   "cli": cli,
                   "felzenszwalb": felzenszwalb,
                   "felzenszwalb_mpx_s": fz_ms.map(|ms| mpx / ms * 1e3)}),
            format!(
                "veg speed {w}×{h} ({mpx:.1} Mpx, {} tile(s)): extraction {total_ms:.0} ms ({:.1} Mpx/s), {} objects, F1 {:.3} | summed over tiles: split-and-merge {:.0} (split {:.0}, adjacency {:.0}, merge {:.0}, small regions {:.0}, describe {:.0}), classify {:.0}, place {:.0} ms | whole image: {} | relevo veg detect: {:.0} ms, peak {:.0} MB | skimage felzenszwalb {}",
                report.tiles,
                mpx / total_ms * 1e3,
                report.objects,
                tiled_f1,
                report.segment_ms,
                steps.split_ms,
                steps.adjacency_ms,
                steps.merge_ms,
                steps.small_regions_ms,
                steps.describe_ms,
                report.classify_ms,
                report.detect_ms,
                whole.as_ref().map_or("—".into(), |v| format!(
                    "{:.0} ms, {} objects ({} found again by the tiles), F1 {:.3}",
                    v["ms"].as_f64().unwrap_or(0.0), v["objects"], v["found_again_by_tiles"],
                    v["f1"].as_f64().unwrap_or(0.0)
                )),
                cli["ms"].as_f64().unwrap_or(0.0),
                cli["peak_mb"].as_f64().unwrap_or(0.0),
                fz_ms.map_or("not run (above 25 Mpx, or scikit-image not installed)".into(), |ms| format!("{ms:.0} ms ({:.1} Mpx/s)", mpx / ms * 1e3)),
            ),
        );
    }
    Ok(())
}

/// The `relevo` binary beside this one (`cargo build --release` builds both).
fn relevo_binary() -> Result<PathBuf> {
    let path = std::env::current_exe()?
        .parent()
        .context("no folder for the bench binary")?
        .join("relevo");
    anyhow::ensure!(
        path.exists(),
        "{} is missing: build it first (cargo build --release -p relevo)",
        path.display()
    );
    Ok(path)
}

/// `relevo veg detect` on `image` written as a raw ENVI file with the
/// Yellowstone samples: its wall time (reading included) and its peak
/// resident memory (the kernel's high-water mark, polled while it runs).
fn relevo_detect(
    relevo: &Path,
    scratch: &Path,
    image: &relevo_core::veg::Image,
    repo: &Path,
) -> Result<serde_json::Value> {
    let raw = scratch.join("image.raw");
    std::fs::write(&raw, &image.pixels)?;
    std::fs::write(
        scratch.join("image.hdr"),
        format!(
            "ENVI\nsamples = {}\nlines = {}\nbands = {}\nheader offset = 0\nfile type = ENVI Standard\ndata type = 1\ninterleave = bip\nbyte order = 0\n",
            image.width, image.height, image.bands
        ),
    )?;
    let start = Instant::now();
    let mut child = Command::new(relevo)
        .args([
            "veg",
            "detect",
            "-q",
            "--force",
            "--pixel-size",
            "0.1",
            "--samples",
        ])
        .arg(repo.join("data/trees/yellowstone_samples.csv"))
        .arg("--out")
        .arg(scratch.join("objects.csv"))
        .arg(&raw)
        .stdout(std::process::Stdio::null())
        .spawn()?;
    let status_path = format!("/proc/{}/status", child.id());
    let mut peak_kib = 0u64;
    let status = loop {
        if let Ok(text) = std::fs::read_to_string(&status_path) {
            let hwm = text
                .lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.split_whitespace().next()?.parse::<u64>().ok());
            peak_kib = peak_kib.max(hwm.unwrap_or(0));
        }
        if let Some(status) = child.try_wait()? {
            break status;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    };
    let ms = start.elapsed().as_secs_f64() * 1e3;
    let _ = std::fs::remove_file(&raw);
    anyhow::ensure!(
        status.success(),
        "relevo veg detect failed on the {}×{} image",
        image.width,
        image.height
    );
    Ok(json!({"ms": ms, "peak_mb": peak_kib as f64 / 1024.0}))
}

/// Truth boxes of a `w`×`h` image repeated as [`mirror_tile`] repeats it.
fn mirror_boxes(boxes: &[[f64; 4]], w: usize, h: usize, side: usize) -> Vec<[f64; 4]> {
    let (w, h) = (w as f64, h as f64);
    let mut out = Vec::new();
    for ty in 0..side.div_ceil(h as usize) {
        for tx in 0..side.div_ceil(w as usize) {
            let (ox, oy) = (tx as f64 * w, ty as f64 * h);
            for b in boxes {
                let (x0, x1) = if tx % 2 == 1 {
                    (w - b[2], w - b[0])
                } else {
                    (b[0], b[2])
                };
                let (y0, y1) = if ty % 2 == 1 {
                    (h - b[3], h - b[1])
                } else {
                    (b[1], b[3])
                };
                let clipped = [
                    ox + x0,
                    oy + y0,
                    (ox + x1).min(side as f64),
                    (oy + y1).min(side as f64),
                ];
                if clipped[0] < side as f64 && clipped[1] < side as f64 {
                    out.push(clipped);
                }
            }
        }
    }
    out
}

/// A `side`×`side` image tiled from `image`, every other copy mirrored so
/// that tiles join without seams.
fn mirror_tile(image: &relevo_core::veg::Image, side: usize) -> Result<relevo_core::veg::Image> {
    let (w, h, b) = (image.width, image.height, image.bands);
    let mut pixels = vec![0u8; side * side * b];
    for (y, row) in pixels.chunks_mut(side * b).enumerate() {
        let (ty, sy) = (y / h, y % h);
        let sy = if ty % 2 == 1 { h - 1 - sy } else { sy };
        for x in 0..side {
            let (tx, sx) = (x / w, x % w);
            let sx = if tx % 2 == 1 { w - 1 - sx } else { sx };
            let at = (sy * w + sx) * b;
            row[x * b..(x + 1) * b].copy_from_slice(&image.pixels[at..at + b]);
        }
    }
    Ok(relevo_core::veg::Image::new(side, side, b, pixels)?)
}

/// @mapbox/martini's `createTile` on the same heights, median ms (node,
/// `tools/js/martini-bench.mjs`); `None` past its largest grid.
fn martini_ms(
    script: &Path,
    scratch: &Path,
    heights: &[f32],
    side: usize,
    runs: usize,
) -> Result<Option<f64>> {
    if side > 4097 {
        // 8193² exceeds martini's u16 coordinates.
        return Ok(None);
    }
    // martini reads the terrain as raw float32.
    {
        let file = scratch.join(format!("{side}.f32"));
        std::fs::write(&file, bytemuck::cast_slice::<f32, u8>(heights))?;
        let out = Command::new("node")
            .arg(script)
            .arg(runs.min(5).to_string())
            .arg(&file)
            .arg(side.to_string())
            .output()
            .context("cannot run node (scripts/setup-test installs it and martini)")?;
        if !out.status.success() {
            bail!(
                "martini benchmark failed: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        let v: serde_json::Value = serde_json::from_slice(&out.stdout)?;
        Ok(v["create_ms"].as_f64())
    }
}

/// Refinement timings over one grid: per heading the median ms and the
/// triangles, row-major; and the median over headings with every
/// per-vertex array in 64×64 tiles.
struct Refinement {
    times: Vec<f64>,
    triangles: Vec<usize>,
    tiled_ms: f64,
}

/// Refinement at 1920×1080, τ = 1 px, culling on, eight headings, from
/// above the middle of the grid looking 20° down.
fn refinement(
    h: &relevo_core::lp::Hierarchy,
    heights: &[f32],
    side: usize,
    cell: f64,
    runs: usize,
) -> Result<Refinement> {
    use relevo_core::camera::Camera;
    use relevo_core::lp::refine::{GridArrays, RefineParams, Refiner};
    use relevo_core::lp::Layout;
    let extent = (side - 1) as f64 * cell;
    let top = heights.iter().cloned().fold(f32::MIN, f32::max) as f64;
    let mut refiner = Refiner::new();
    let mut times = Vec::new();
    let mut triangles = Vec::new();
    let view = |k: usize| Camera {
        position: glam::DVec3::new(extent * 0.5, extent * 0.5, top + 300.0),
        heading_deg: k as f64 * 45.0,
        pitch_deg: -20.0,
        incl_px: 540.0,
        fov_x_deg: 60.0,
        width: 1920,
        height: 1080,
        near_m: 1.0,
        far_m: extent * 2.0,
    };
    for k in 0..8 {
        let params = RefineParams::for_camera(&view(k), 1.0, None, true);
        refiner.refine(h, heights, &params); // warm the buffers
        let ms = median_ms(runs, || {
            std::hint::black_box(refiner.refine(h, heights, &params));
            Ok(())
        })?;
        times.push(ms);
        triangles.push(refiner.refine(h, heights, &params).triangles().count());
    }
    // The same views with every per-vertex array in 64×64 tiles.
    let tiled_er = Layout::Tiled.arrange(side, &h.error_radius);
    let tiled_z = Layout::Tiled.arrange(side, heights);
    let tiled = GridArrays {
        layout: Layout::Tiled,
        side,
        cell_size_m: cell,
        error_radius: &tiled_er,
        heights: &tiled_z,
    };
    let mut tiled_times = Vec::new();
    for k in 0..8 {
        let params = RefineParams::for_camera(&view(k), 1.0, None, true);
        tiled_times.push(median_ms(runs, || {
            std::hint::black_box(refiner.refine_source(&tiled, &params));
            Ok(())
        })?);
    }
    let refine_tiled_ms = median(&tiled_times);
    Ok(Refinement {
        times,
        triangles,
        tiled_ms: refine_tiled_ms,
    })
}

/// The whole `prep` of the grid written as a GeoTIFF (30 m cells, UTM
/// 33N), ms.
fn prep_ms(heights: &[f32], side: usize, cell: f64, scratch: &Path) -> Result<f64> {
    let tif = scratch.join(format!("{side}.tif"));
    let raster = relevo_core::raster::Raster::from_data(
        side,
        side,
        1,
        heights.iter().map(|&v| v as f64).collect(),
    );
    let spec = gdalio::GridSpec {
        crs_wkt: relevo::ingest::crs::to_wkt(&relevo::ingest::crs::parse("EPSG:32633")?)?,
        geotransform: relevo_core::geo::GeoTransform::north_up(500_000.0, 5_000_000.0, cell, cell),
        width: side,
        height: side,
    };
    gdalio::write_geotiff(
        &tif,
        &raster,
        &spec,
        gdal::raster::GdalDataType::Float32,
        None,
    )?;
    let region: RegionSpec = toml::from_str(&format!(
        "[dem]\nfiles = [{:?}]\n",
        tif.display().to_string()
    ))?;
    let out = scratch.join(format!("{side}.relevo"));
    median_ms(1, || prep(&region, &out, true).map(|_| ()))
}

/// An annotated crop: the image, the samples marked on it, the truth boxes.
type MarkedCrop = (
    relevo_core::veg::pipeline::VegImage,
    Vec<relevo_core::veg::samples::Sample>,
    Vec<[f64; 4]>,
);

/// Crown accuracy on each annotated crop with its committed samples,
/// beside excess green, overall and away from the samples; returns the
/// Yellowstone crop, its samples and boxes for the speed runs.
fn veg_accuracy(
    repo: &Path,
    data: &Path,
    options: &relevo_core::veg::pipeline::VegOptions,
    json_lines: bool,
) -> Result<Option<MarkedCrop>> {
    use relevo_core::veg::detect::Placement;
    use relevo_core::veg::pipeline::extract;
    use relevo_core::veg::{baseline, eval};
    let mut yellowstone = None;
    for crop in relevo::veg_io::annotated_crops(repo, data)? {
        let (name, image, samples, truth) = (crop.name, crop.image, crop.samples, crop.truth);
        let result = extract(&image, &samples, options)?;
        let ours = eval::Detection::of_objects(&result.objects, image.pixel_m);
        // The baseline places crowns as the extraction did (spacing, radius).
        let Placement::Crowns {
            spacing_px,
            min_radius_px,
            ..
        } = result.report.placement
        else {
            anyhow::bail!("{name}: crowns were not placed");
        };
        let theirs = baseline::excess_green_crowns(&image.image, spacing_px, min_radius_px);
        let centre = eval::Criterion::Centre;
        let e = eval::evaluate(&ours, &truth, centre);
        let b = eval::evaluate(&theirs, &truth, centre);
        // The same away from the samples: boxes and detections whose centre
        // lies in a marked rectangle are left out (a marked crown is easy).
        let marked = |x: f64, y: f64| samples.iter().any(|s| s.contains(x, y));
        let unmarked_truth: Vec<[f64; 4]> = truth
            .iter()
            .filter(|b| !marked((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0))
            .copied()
            .collect();
        let unmarked = |d: &[eval::Detection]| -> Vec<eval::Detection> {
            d.iter().filter(|p| !marked(p.x, p.y)).copied().collect()
        };
        let e_away = eval::evaluate(&unmarked(&ours), &unmarked_truth, centre);
        let b_away = eval::evaluate(&unmarked(&theirs), &unmarked_truth, centre);
        emit(
            json_lines,
            json!({"bench": "veg-accuracy", "image": name, "boxes": truth.len(),
                   "haar": e, "excess_green": b,
                   "away_from_samples": {"boxes": unmarked_truth.len(), "haar": e_away, "excess_green": b_away}}),
            format!(
                "veg accuracy {name} ({} boxes): Haar P {:.3} R {:.3} F1 {:.3} ({} objects) | excess green P {:.3} R {:.3} F1 {:.3} ({} objects) | away from the samples ({} boxes): Haar F1 {:.3}, excess green F1 {:.3}",
                truth.len(), e.precision, e.recall, e.f1, e.detections,
                b.precision, b.recall, b.f1, b.detections,
                unmarked_truth.len(), e_away.f1, b_away.f1
            ),
        );
        if name == "yellowstone" {
            yellowstone = Some((image, samples, truth));
        }
    }
    Ok(yellowstone)
}

/// scikit-image's felzenszwalb on the same pixels (`runs` runs, median ms
/// and segments as JSON); not run above 25 Mpx (it would take minutes).
fn felzenszwalb(
    script: &Path,
    scratch: &Path,
    image: &relevo_core::veg::Image,
    runs: usize,
    mpx: f64,
) -> Result<Option<serde_json::Value>> {
    if mpx > 25.0 {
        return Ok(None);
    }
    {
        let raw = scratch.join("image.u8");
        std::fs::write(&raw, &image.pixels)?;
        let out = Command::new("python3")
            .arg(script)
            .arg(&raw)
            .args([image.width, image.height, image.bands, runs].map(|v| v.to_string()))
            .output();
        let _ = std::fs::remove_file(&raw);
        Ok(match out {
            Ok(o) if o.status.success() => {
                serde_json::from_slice::<serde_json::Value>(&o.stdout).ok()
            }
            _ => None,
        })
    }
}
