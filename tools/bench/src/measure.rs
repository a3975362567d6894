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

/// Run `command` to its end with its output discarded: wall time in
/// milliseconds and peak resident memory in MB (the kernel's own count
/// for that child), failing on a non-zero exit.
pub fn run_measured(command: &mut std::process::Command) -> Result<(f64, f64)> {
    let start = Instant::now();
    let child = command
        .stdout(std::process::Stdio::null())
        .spawn()
        .with_context(|| format!("starting {command:?}"))?;
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    // SAFETY: `rusage` is a plain C struct that wait4 fills; `pid` is this
    // process's child, not yet waited for, and both pointers are valid
    // for the call.
    let (waited, usage) = unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        (libc::wait4(pid, &mut status, 0, &mut usage), usage)
    };
    let ms = start.elapsed().as_secs_f64() * 1e3;
    if waited != pid || !libc::WIFEXITED(status) || libc::WEXITSTATUS(status) != 0 {
        anyhow::bail!("{command:?} failed (wait status {status})");
    }
    Ok((ms, usage.ru_maxrss as f64 / 1024.0))
}
