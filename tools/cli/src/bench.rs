//! `relevo bench`: measured figures, side by side with reference tools, as
//! text or one JSON object per line. Timings are medians of repeated runs of
//! release builds; nothing here is asserted by tests.

use crate::gdalio;
use crate::prep::prep;
use crate::region::Region;
use crate::stitch::{stitch, StitchOptions};
use anyhow::{bail, Context, Result};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Median wall time in milliseconds of `runs` calls of `f`.
pub fn median_ms(runs: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    let mut times = Vec::with_capacity(runs);
    for _ in 0..runs {
        let start = Instant::now();
        f()?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    Ok(times[times.len() / 2])
}

fn emit(json_lines: bool, value: serde_json::Value, text: String) {
    if json_lines {
        println!("{value}");
    } else {
        println!("{text}");
    }
}

/// Ingest figures: `prep` on the sample region, and `stitch` on the Landsat
/// overlap against gdalwarp doing the same job.
pub fn ingest(repo: &Path, data: &Path, runs: usize, json_lines: bool) -> Result<()> {
    let scratch = tempfile_dir()?;

    // prep on the sample region: first run in this process, then the median.
    let region = Region::load(&repo.join("data/olinda/REGION.toml"))?;
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
    for (label, overlap) in [
        ("blend", crate::cli::OverlapArg::Blend),
        ("first", crate::cli::OverlapArg::First),
    ] {
        let opts = StitchOptions {
            src_nodata: Some(0.0),
            overlap: overlap.into(),
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

/// A fresh scratch folder under the system temp dir.
fn tempfile_dir() -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("relevo-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| dir.display().to_string())?;
    Ok(dir)
}
