//! `relevo diff A B`: what changed from bundle A to bundle B — per
//! artifact, and for the same grid the largest height change and where,
//! the RMS and the area changed; vegetation matched object to object;
//! renders compared — as text or JSON, with pictures on request. Exit 0
//! when the bundles are identical, 1 when they differ, 2 when they cannot
//! be read (as `diff` does).

use super::Exit;
use anyhow::{Context, Result};
use clap::Args;
use relevo_core::bundle::Bundle;
use relevo_core::golden::diff::{diff, diff_images, DiffOptions, DiffReport, GridChange, Location};
use std::fmt::Write;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct DiffArgs {
    /// The bundle before.
    pub before: PathBuf,
    /// The bundle after.
    pub after: PathBuf,
    /// Height changes beyond this count towards the area changed, metres.
    #[arg(long, default_value_t = 0.0, value_name = "M")]
    pub threshold_m: f64,
    /// Objects of one class closer than this are one object moved, metres.
    #[arg(long, default_value_t = 30.0, value_name = "M")]
    pub match_radius_m: f64,
    /// Renders of both bundles to compare.
    #[command(flatten)]
    pub renders: super::args::NamedCameras,
    /// Write pictures of the changes into this folder (created if missing):
    /// height_change.png, vegetation_change.png, render_NAME_{before,after,difference}.png.
    #[arg(long, value_name = "DIR")]
    pub images: Option<PathBuf>,
    /// Print the differences as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: DiffArgs) -> Result<()> {
    let trouble = |e: anyhow::Error| -> anyhow::Error { Exit::with(2, format!("{e:#}")).into() };
    if !(a.threshold_m.is_finite() && a.threshold_m >= 0.0) {
        return Err(trouble(anyhow::anyhow!(
            "--threshold-m must be a non-negative number of metres"
        )));
    }
    if !(a.match_radius_m.is_finite() && a.match_radius_m >= 0.0) {
        return Err(trouble(anyhow::anyhow!(
            "--match-radius-m must be a non-negative number of metres"
        )));
    }
    let renders = a.renders.renders().map_err(trouble)?;
    let (before, after) = (
        Bundle::open(&a.before).map_err(|e| trouble(e.into()))?,
        Bundle::open(&a.after).map_err(|e| trouble(e.into()))?,
    );
    let options = DiffOptions {
        threshold_m: a.threshold_m,
        match_radius_m: a.match_radius_m,
        renders,
    };
    let report = diff(&before, &after, &options).map_err(|e| trouble(e.into()))?;
    if let Some(dir) = &a.images {
        write_images(dir, &before, &after, &report, &options).map_err(trouble)?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", text(&report));
    }
    if report.identical() {
        Ok(())
    } else {
        Err(Exit::with(
            1,
            format!("{} and {} differ", a.before.display(), a.after.display()),
        )
        .into())
    }
}

fn write_images(
    dir: &Path,
    before: &Bundle,
    after: &Bundle,
    report: &DiffReport,
    options: &DiffOptions,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let images = diff_images(before, after, report, options)?;
    let paths: Vec<PathBuf> = images.iter().map(|(name, _)| dir.join(name)).collect();
    let files: Vec<(&Path, &[u8])> = paths
        .iter()
        .zip(&images)
        .map(|(p, (_, bytes))| (p.as_path(), bytes.as_slice()))
        .collect();
    relevo_core::atomic::write_files(&files)?;
    for p in &paths {
        eprintln!("{}", p.display());
    }
    Ok(())
}

fn at(l: &Option<Location>) -> String {
    match l {
        Some(l) => format!(
            " at E {:.2} N {:.2} (column {}, row {})",
            l.x, l.y, l.col, l.row
        ),
        None => String::new(),
    }
}

fn grid_line(name: &str, g: &GridChange, threshold: f64) -> String {
    if g.changed_cells == 0 {
        return format!("{name}: unchanged\n");
    }
    format!(
        "{name}: {} vertices changed, largest {:.3} m{}: {:.3} → {:.3} m; RMS {:.4} m; \
         {} vertices ({:.0} m²) beyond {threshold} m\n",
        g.changed_cells,
        g.largest,
        at(&g.at),
        g.before,
        g.after,
        g.rms,
        g.cells_beyond_threshold,
        g.area_beyond_threshold_m2
    )
}

/// The report as text, one line per artifact.
fn text(r: &DiffReport) -> String {
    let mut out = String::new();
    if r.identical() {
        out.push_str("identical: every artifact byte for byte\n");
    }
    if !r.same_grid {
        let _ = writeln!(
            out,
            "grid: {}² → {}² cells or moved; heights and errors not compared cell by cell",
            r.sides[0], r.sides[1]
        );
    }
    if let Some(h) = &r.height {
        out.push_str(&grid_line("heights", h, r.threshold_m));
    }
    if r.same_grid {
        let _ = writeln!(
            out,
            "mask: {} vertices gained data, {} lost it",
            r.mask_gained, r.mask_lost
        );
    }
    if let Some(e) = &r.lp_error {
        out.push_str(&grid_line("LP errors", e, r.threshold_m));
    }
    if let Some(d) = &r.drape {
        let _ = writeln!(
            out,
            "drape: {} pixels changed, largest {} levels{}",
            d.changed_pixels,
            d.largest_levels,
            at(&d.at)
        );
    }
    for (class, c) in &r.vegetation {
        let _ = writeln!(
            out,
            "vegetation {class}: {} → {} objects: {} kept, {} moved (farthest {:.3} m), {} added, {} removed",
            c.before, c.after, c.kept, c.moved, c.largest_move_m, c.added, c.removed
        );
    }
    let _ = writeln!(
        out,
        "clusters: {}",
        if r.clusters_rebaked {
            "baked again"
        } else {
            "unchanged"
        }
    );
    for (label, keys) in [
        ("changed", &r.changed),
        ("only before", &r.only_before),
        ("only after", &r.only_after),
    ] {
        if !keys.is_empty() {
            let _ = writeln!(out, "{label}: {}", keys.join(", "));
        }
    }
    for render in &r.renders {
        let d = &render.difference;
        let _ = writeln!(
            out,
            "render {}: PSNR {:.1} dB, {:.2} % of pixels more than {} levels off, mean {:.3} levels",
            render.name,
            d.psnr_db,
            100.0 * d.share_off(),
            d.threshold,
            d.mean
        );
    }
    out
}
