//! What every runner measures with: medians of repeated runs, one figure
//! printed as text or as a JSON line, a scratch folder, and the padded SRTM
//! grid several runners time on.

use anyhow::{Context, Result};
use relevo::ingest::gdalio;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Median of a non-empty set of values (mean of the middle two when even).
pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// Median wall time in milliseconds of `runs` calls of `f`.
pub fn median_ms(runs: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    let mut times = Vec::with_capacity(runs);
    for _ in 0..runs {
        let start = Instant::now();
        f()?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    Ok(median(&times))
}

/// Print one figure: its JSON object when `json_lines`, else its text.
pub fn emit(json_lines: bool, value: serde_json::Value, text: String) {
    if json_lines {
        println!("{value}");
    } else {
        println!("{text}");
    }
}

/// A fresh scratch folder under the system temp dir.
pub fn tempfile_dir() -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("relevo-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| dir.display().to_string())?;
    Ok(dir)
}

/// The raw srtm_ref DEM (1000², no reprojection) padded to 1025².
pub fn srtm_padded(data: &Path) -> Result<relevo_core::grid::HeightGrid> {
    use relevo_core::grid::{HeightGrid, Squaring};
    let srtm = gdalio::open(&data.join("dem/srtm_ref.tif"))?;
    let raw = srtm.read(srtm.nodata)?;
    Ok(HeightGrid::square(
        raw.band(0),
        raw.width,
        raw.height,
        relevo_core::geo::GeoTransform::IDENTITY,
        Squaring::Pad,
    ))
}

/// Run `program` with `args` to its end, its output discarded, under GNU
/// time: wall time in milliseconds and the child's peak resident memory in
/// MB, failing on a non-zero exit. (A child forked from this process would
/// report this process's own peak too: Linux carries the parent's
/// high-water mark across fork and exec; GNU time's child starts small.)
pub fn run_measured(command: &std::process::Command) -> Result<(f64, f64)> {
    let (ms, mb, _) = run_measured_output(command)?;
    Ok((ms, mb))
}

/// [`run_measured`], keeping what the child wrote to its standard output.
pub fn run_measured_output(command: &std::process::Command) -> Result<(f64, f64, String)> {
    let (program, args): (&std::ffi::OsStr, Vec<&std::ffi::OsStr>) =
        (command.get_program(), command.get_args().collect());
    let report = std::env::temp_dir().join(format!("relevo-bench-time-{}", std::process::id()));
    let start = Instant::now();
    let output = std::process::Command::new("/usr/bin/time")
        .args(["-f", "%M", "-o"])
        .arg(&report)
        .arg(program)
        .args(&args)
        .stderr(std::process::Stdio::inherit())
        .output()
        .context("running /usr/bin/time (Debian package `time`)")?;
    let ms = start.elapsed().as_secs_f64() * 1e3;
    if !output.status.success() {
        anyhow::bail!("{program:?} {args:?} failed ({})", output.status);
    }
    let text = std::fs::read_to_string(&report).with_context(|| report.display().to_string())?;
    let _ = std::fs::remove_file(&report);
    let kib: f64 = text
        .lines()
        .last()
        .and_then(|l| l.trim().parse().ok())
        .with_context(|| format!("GNU time's report {text:?}"))?;
    Ok((
        ms,
        kib / 1024.0,
        String::from_utf8_lossy(&output.stdout).into_owned(),
    ))
}
