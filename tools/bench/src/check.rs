//! Regression checks (`relevo check`, `relevo diff`) on the sample region
//! and Grenoble: blessing a record, checking an unchanged bundle (hashes
//! only), checking one whose every grid must be compared with its
//! reference vertex by vertex, and a diff — beside `relevo validate` on
//! the same bundle, which reads and hashes every file once.

use crate::measure::{emit, median_ms, tempfile_dir};
use anyhow::Result;
use relevo::prep::prep;
use relevo::prep::region::RegionSpec;
use relevo_core::bundle::Bundle;
use relevo_core::golden::diff::{diff, DiffOptions};
use relevo_core::golden::{check, record, CheckOptions, Tolerances};
use relevo_core::validation::validate;
use serde_json::json;
use std::path::Path;

pub fn run(repo: &Path, runs: usize, json_lines: bool) -> Result<()> {
    let scratch = tempfile_dir()?;
    for region in ["olinda", "grenoble"] {
        let spec = RegionSpec::load(&repo.join(format!("data/{region}/REGION.toml")))?;
        let out = scratch.join(format!("{region}.relevo"));
        prep(&spec, &out, true)?;
        let bundle = Bundle::open(&out)?;
        let side = bundle.manifest.grid.side;
        let mut blessed = None;
        let bless_ms = median_ms(runs, || {
            blessed = Some(record::record_bundle(
                &bundle,
                Tolerances::default(),
                region,
            )?);
            Ok(())
        })?;
        let Some((golden, beside)) = blessed else {
            continue;
        };
        for (name, bytes) in &beside {
            std::fs::write(scratch.join(name), bytes)?;
        }
        let record_bytes = record::to_text(&golden)?.len();
        let beside_bytes: usize = beside.iter().map(|(_, b)| b.len()).sum();
        let options = CheckOptions::default();
        let unchanged_ms = median_ms(runs, || {
            check(&bundle, &golden, &scratch, &options)
                .map(|_| ())
                .map_err(Into::into)
        })?;
        // Every hash altered: each grid is compared with its reference.
        let mut altered = golden.clone();
        for a in altered.artifacts.values_mut() {
            a.sha256 = "0".repeat(64);
        }
        let compared_ms = median_ms(runs, || {
            check(&bundle, &altered, &scratch, &options)
                .map(|_| ())
                .map_err(Into::into)
        })?;
        let diff_options = DiffOptions {
            threshold_m: 0.0,
            match_radius_m: 30.0,
            renders: Vec::new(),
        };
        let diff_ms = median_ms(runs, || {
            diff(&bundle, &bundle, &diff_options)
                .map(|_| ())
                .map_err(Into::into)
        })?;
        let validate_ms = median_ms(runs, || {
            validate(&bundle);
            Ok(())
        })?;
        emit(
            json_lines,
            json!({"bench": "check", "region": region, "side": side, "runs": runs,
                   "bless_ms": bless_ms, "check_unchanged_ms": unchanged_ms,
                   "check_every_grid_compared_ms": compared_ms, "diff_ms": diff_ms,
                   "validate_ms": validate_ms, "record_bytes": record_bytes,
                   "reference_png_bytes": beside_bytes}),
            format!(
                "check {region} ({side}²): bless {bless_ms:.0} ms (record {:.0} KB + references {:.0} KB), \
                 check unchanged {unchanged_ms:.1} ms, every grid compared {compared_ms:.0} ms, \
                 diff {diff_ms:.0} ms; relevo validate {validate_ms:.0} ms",
                record_bytes as f64 / 1e3,
                beside_bytes as f64 / 1e3
            ),
        );
    }
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}
