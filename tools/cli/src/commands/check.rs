//! `relevo check`: a bundle against the golden record a user commits —
//! exit 0 when every artifact is within its tolerance, 1 when one changed
//! beyond it, 2 when the two cannot be compared; `--bless` writes the
//! record (and its reference renders) instead.

use super::report;
use super::Exit;
use crate::output;
use anyhow::{Context, Result};
use clap::Args;
use relevo_core::bundle::Bundle;
use relevo_core::golden::{self, record, GoldenRecord, RenderRecord, Tolerances};
use relevo_core::raster::png::encode_rgba;
use relevo_core::scene::View;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct CheckArgs {
    /// The bundle to check.
    pub bundle: PathBuf,
    /// The golden record (JSON; its reference renders lie beside it).
    #[arg(long)]
    pub golden: PathBuf,
    /// Write (or replace) the record from this bundle instead of checking:
    /// the tolerances given here (else the old record's), its cameras.
    #[arg(long)]
    pub bless: bool,
    /// With --bless: reference renders (default: the old record's
    /// cameras, else the home view).
    #[command(flatten)]
    pub renders: super::args::NamedCameras,
    /// With --bless: no reference renders.
    #[arg(long)]
    pub no_renders: bool,
    #[command(flatten)]
    pub tolerances: ToleranceArgs,
    /// Do not compare this artifact (a manifest key, a prefix ending in
    /// `*` such as `clusters*`, or `render:NAME`); repeatable.
    #[arg(long, value_name = "KEY")]
    pub skip: Vec<String>,
    /// Also write the result as JUnit XML (one test case per artifact).
    #[arg(long, value_name = "FILE")]
    pub junit: Option<PathBuf>,
    /// Also write the result as Markdown (a pull-request comment).
    #[arg(long, value_name = "FILE")]
    pub markdown: Option<PathBuf>,
    /// Print the result as JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Tolerances on the command line; each overrides the record's.
#[derive(Args, Debug, Default)]
pub struct ToleranceArgs {
    /// Heights: absolute tolerance, metres.
    #[arg(long, value_name = "M")]
    pub height_m: Option<f64>,
    /// Heights: tolerance relative to the recorded height (0.001 = 0.1 %).
    #[arg(long, value_name = "FRACTION")]
    pub height_relative: Option<f64>,
    /// LP object-space errors, metres.
    #[arg(long, value_name = "M")]
    pub lp_error_m: Option<f64>,
    /// Drape colour, levels (0–255).
    #[arg(long, value_name = "LEVELS")]
    pub drape_levels: Option<f64>,
    /// Vegetation: how far a class's mean position in a block may move, metres.
    #[arg(long, value_name = "M")]
    pub vegetation_position_m: Option<f64>,
    /// Vegetation: objects a class may gain or lose (overall and per block).
    #[arg(long, value_name = "N")]
    pub vegetation_count: Option<usize>,
    /// Renders: levels a channel may differ before a pixel counts as off.
    #[arg(long, value_name = "LEVELS")]
    pub render_threshold: Option<u8>,
    /// Renders: share of pixels that may be off (0–1).
    #[arg(long, value_name = "SHARE")]
    pub render_pixels_off: Option<f64>,
    /// Renders: largest mean difference, levels.
    #[arg(long, value_name = "LEVELS")]
    pub render_mean: Option<f64>,
}

impl ToleranceArgs {
    /// `base` with every tolerance given on the command line.
    pub fn over(&self, base: Tolerances) -> Tolerances {
        Tolerances {
            height_m: self.height_m.unwrap_or(base.height_m),
            height_relative: self.height_relative.unwrap_or(base.height_relative),
            lp_error_m: self.lp_error_m.unwrap_or(base.lp_error_m),
            drape_levels: self.drape_levels.unwrap_or(base.drape_levels),
            vegetation_position_m: self
                .vegetation_position_m
                .unwrap_or(base.vegetation_position_m),
            vegetation_count: self.vegetation_count.unwrap_or(base.vegetation_count),
            render_threshold: self.render_threshold.unwrap_or(base.render_threshold),
            render_pixels_off: self.render_pixels_off.unwrap_or(base.render_pixels_off),
            render_mean: self.render_mean.unwrap_or(base.render_mean),
        }
    }
}

/// An error that makes the inputs unusable: exit status 2.
fn unusable(e: anyhow::Error) -> anyhow::Error {
    Exit::with(2, format!("{e:#}")).into()
}

pub fn run(a: CheckArgs) -> Result<()> {
    let reports: Vec<&Path> = a
        .junit
        .iter()
        .chain(&a.markdown)
        .map(PathBuf::as_path)
        .collect();
    let mut outputs = reports.clone();
    outputs.push(&a.golden);
    output::check(&outputs, true).map_err(unusable)?;
    let bundle = Bundle::open(&a.bundle).map_err(|e| unusable(e.into()))?;
    if a.bless {
        return bless(&a, &bundle).map_err(unusable);
    }
    let record = record::read(&a.golden).map_err(|e| unusable(e.into()))?;
    let tolerances = a.tolerances.over(record.tolerances);
    tolerances
        .check()
        .map_err(|p| unusable(anyhow::anyhow!(p)))?;
    let dir = a.golden.parent().unwrap_or(Path::new("."));
    let options = golden::CheckOptions {
        tolerances,
        skip: a.skip.clone(),
    };
    let result = golden::check(&bundle, &record, dir, &options)
        .with_context(|| format!("{} against {}", a.bundle.display(), a.golden.display()))
        .map_err(unusable)?;
    let name = a.bundle.display().to_string();
    let mut files: Vec<(PathBuf, String)> = Vec::new();
    if let Some(path) = &a.junit {
        files.push((path.clone(), report::junit(&result, &name)));
    }
    if let Some(path) = &a.markdown {
        files.push((path.clone(), report::markdown(&result, &name)));
    }
    let pairs: Vec<(&Path, &[u8])> = files
        .iter()
        .map(|(p, t)| (p.as_path(), t.as_bytes()))
        .collect();
    relevo_core::atomic::write_files(&pairs).map_err(|e| unusable(e.into()))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&result)?);
    } else {
        print!("{}", report::text(&result));
    }
    let failed = result
        .findings
        .iter()
        .filter(|f| f.outcome == golden::Outcome::Changed)
        .count();
    if failed > 0 {
        return Err(Exit::with(
            1,
            format!(
                "{}: {failed} of {} artifact(s) changed beyond tolerance (record {})",
                a.bundle.display(),
                result.findings.len(),
                a.golden.display()
            ),
        )
        .into());
    }
    eprintln!(
        "{}: every artifact within tolerance of {}",
        a.bundle.display(),
        a.golden.display()
    );
    Ok(())
}

/// Write the record of `bundle` and its renders, all together or none.
fn bless(a: &CheckArgs, bundle: &Bundle) -> Result<()> {
    let old: Option<GoldenRecord> = if a.golden.exists() {
        Some(record::read(&a.golden)?)
    } else {
        None
    };
    let base = old
        .as_ref()
        .map_or_else(Tolerances::default, |r| r.tolerances);
    let tolerances = a.tolerances.over(base);
    tolerances.check().map_err(|p| anyhow::anyhow!(p))?;
    let stem = a
        .golden
        .file_stem()
        .map_or_else(|| "golden".into(), |s| s.to_string_lossy().to_string());
    let (mut record, references) = record::record_bundle(bundle, tolerances, &stem)?;
    let mut pngs: Vec<(PathBuf, Vec<u8>)> = references
        .into_iter()
        .map(|(name, png)| (a.golden.with_file_name(name), png))
        .collect();
    let cameras: Vec<RenderRecord> = if a.no_renders {
        Vec::new()
    } else if !a.renders.cameras.is_empty() {
        a.renders.renders()?
    } else if let Some(old) = old.as_ref().filter(|r| !r.renders.is_empty()) {
        old.renders.clone()
    } else {
        let home = View::home(&bundle.manifest.grid, a.renders.render_size);
        vec![RenderRecord {
            name: "home".into(),
            camera: home.pose().to_string(),
            size: a.renders.render_size,
            file: String::new(),
        }]
    };
    for camera in cameras {
        let size = camera.size;
        let render = RenderRecord {
            file: format!("{stem}.{}.png", camera.name),
            ..camera
        };
        let rgba = golden::check::render_reference(bundle, &render)?;
        let png = encode_rgba(&rgba, size[0] as usize, size[1] as usize)?;
        pngs.push((a.golden.with_file_name(&render.file), png));
        record.renders.push(render);
    }
    let text = record::to_text(&record)?;
    let mut files: Vec<(&Path, &[u8])> = vec![(&a.golden, text.as_bytes())];
    files.extend(pngs.iter().map(|(p, b)| (p.as_path(), b.as_slice())));
    relevo_core::atomic::write_files(&files)?;
    println!(
        "{}: blessed from {} ({} artifacts, {} render(s))",
        a.golden.display(),
        a.bundle.display(),
        record.artifacts.len(),
        record.renders.len()
    );
    Ok(())
}
