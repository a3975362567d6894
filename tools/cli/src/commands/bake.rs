//! `relevo bake`: (re)bake the vegetation clusters of an existing bundle —
//! class impostors from their models, the quadtree's views, the atlases —
//! replacing its `clusters/` atomically.

use crate::progress;
use anyhow::{bail, Context, Result};
use clap::Args;
use relevo_core::bundle::Bundle;
use relevo_core::cluster::bake::{BakeOptions, BakeReport};
use relevo_core::cluster::cut::{Band, CutOptions};
use relevo_core::cluster::store::{self, NewVegetation};
use relevo_core::cluster::{bake_database, Clusters};
use relevo_core::geo::TerrainFrame;
use relevo_core::veg::db::VegObject;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Type of a list of bands as clap parses it (an alias keeps clap's
/// `Vec` handling off).
type Bands = Vec<Band>;

#[derive(Args, Debug)]
pub struct BakeArgs {
    /// The bundle whose vegetation to cluster (rewritten in place).
    pub bundle: PathBuf,
    /// Model of a class: CLASS=KIND (broadleaf, conifer, dead, stand) or
    /// CLASS=FILE.obj; repeatable. Other classes keep the bundle's models
    /// (or the default for their name).
    #[arg(long = "model", value_name = "CLASS=MODEL")]
    pub models: Vec<String>,
    /// Most atlas texture, MiB (pages with their mip levels).
    #[arg(long, value_name = "MIB")]
    pub budget_mib: Option<f64>,
    /// Distance bands UNTIL_M:MAX_CLUSTER,… the textures are sized for.
    #[arg(long, value_parser = CutOptions::parse_bands)]
    pub bands: Option<Bands>,
    /// Longest side of a cluster view, texels.
    #[arg(long)]
    pub max_frame: Option<u32>,
    /// Print the bake report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What `prep` and `bake` report about the clusters.
#[derive(Debug, Serialize)]
pub struct ClustersSummary {
    pub objects: usize,
    pub nodes: usize,
    pub baked_nodes: usize,
    pub pages: usize,
    pub atlas_bytes: u64,
    /// Clusters left out of the atlas by the budget.
    pub left_out: usize,
    /// Distance from which budget-capped clusters are sharp, metres.
    pub sharp_from_m: Option<f64>,
}

impl ClustersSummary {
    pub fn of(c: &Clusters) -> Self {
        ClustersSummary {
            objects: c.tree.objects.len(),
            nodes: c.tree.nodes.len(),
            baked_nodes: c.frames.len() / 5,
            pages: c.pages.len(),
            atlas_bytes: c.report.atlas_bytes,
            left_out: c.report.left_out(),
            sharp_from_m: c.report.sharp_from_m,
        }
    }
}

/// A bake's progress callback moving `bar` (clusters composed of all).
fn count_on(bar: &indicatif::ProgressBar) -> impl Fn(u64, u64) + Sync + '_ {
    move |n, total| {
        bar.set_length(total);
        bar.inc(n);
    }
}

/// [`bake_database`] with a progress bar over the clusters composed.
pub fn bake_with_progress(
    database: &[VegObject],
    frame: &TerrainFrame,
    heights: &[f32],
    mask: &[u8],
    models: &BTreeMap<String, String>,
    options: &BakeOptions,
) -> Result<(Clusters, usize)> {
    let bar = progress::bar(0, "clusters");
    let result = bake_database(
        database,
        frame,
        heights,
        mask,
        models,
        options,
        &count_on(&bar),
    );
    bar.finish_and_clear();
    Ok(result?)
}

pub fn run(a: BakeArgs) -> Result<()> {
    let bundle = Bundle::open(&a.bundle)?;
    if bundle.vegetation()?.is_none() {
        bail!(
            "{}: the bundle has no vegetation database to cluster (run `relevo veg detect` or prep with samples)",
            a.bundle.display()
        );
    }
    // Start from what the bundle was baked with, then apply the flags.
    let previous = store::read_index(&bundle)?;
    let mut options = previous
        .as_ref()
        .map_or_else(BakeOptions::default, |i| i.options.clone());
    let mut models: BTreeMap<String, String> = previous
        .iter()
        .flat_map(|i| &i.classes)
        .map(|c| {
            let model = c.model.strip_prefix("procedural:").unwrap_or(&c.model);
            (c.name.clone(), model.to_string())
        })
        .collect();
    for m in &a.models {
        let (class, model) = m
            .split_once('=')
            .with_context(|| format!("--model {m:?}: expected CLASS=MODEL"))?;
        models.insert(class.trim().into(), model.trim().into());
    }
    if let Some(mib) = a.budget_mib {
        if !(mib.is_finite() && mib > 0.0) {
            bail!("--budget-mib {mib}: must be a positive number of MiB");
        }
        options.budget_bytes = (mib * (1u64 << 20) as f64) as u64;
    }
    if let Some(bands) = a.bands {
        options.cut.bands = bands;
    }
    if let Some(px) = a.max_frame {
        options.max_frame_px = px;
    }
    let bar = progress::bar(0, "clusters");
    let (path, clusters, off_terrain) = store::rewrite_bundle(
        &bundle,
        &NewVegetation::default(),
        &models,
        &options,
        &count_on(&bar),
    )
    .with_context(|| a.bundle.display().to_string())?;
    bar.finish_and_clear();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&clusters.report)?);
    } else {
        print_report(&clusters.report);
        println!(
            "{}: {} objects clustered ({off_terrain} off the terrain), {} atlas pages",
            path.display(),
            clusters.tree.objects.len(),
            clusters.pages.len()
        );
    }
    Ok(())
}

/// The bake report as a table: per depth, nodes, clusters, baked, bytes.
pub fn print_report(report: &BakeReport) {
    let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
    println!("  depth     nodes  clusters     baked   reduced   atlas MiB");
    for l in &report.levels {
        println!(
            "  {:>5} {:>9} {:>9} {:>9} {:>9} {:>11.2}",
            l.depth,
            l.nodes,
            l.clusters,
            l.baked,
            l.reduced,
            mib(l.atlas_bytes)
        );
    }
    println!(
        "  class impostors {:.2} MiB; pages {:.2} MiB of a {:.0} MiB budget",
        mib(report.class_bytes),
        mib(report.atlas_bytes),
        mib(report.budget_bytes)
    );
    if report.density_cap == Some(0.0) {
        println!("  the budget holds no cluster: every object is drawn one by one");
    }
    if let (Some(cap), Some(from)) = (report.density_cap, report.sharp_from_m) {
        println!(
            "  over budget at full detail: cluster views capped at {cap:.3} texels/m (sharp from {from:.0} m on a 1920-px screen); {} clusters left out, their objects drawn from smaller clusters or one by one",
            report.left_out()
        );
    }
}
