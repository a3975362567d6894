//! `relevo bake`: (re)bake the vegetation clusters of an existing bundle —
//! class impostors from their models, the quadtree's views, the atlases —
//! replacing its `clusters/` atomically.

use crate::clusters::{count_on, print_report};
use crate::progress;
use anyhow::{bail, Context, Result};
use clap::Args;
use relevo_core::bundle::BundleFiles;
use relevo_core::bundle::{Bundle, BundleLock};
use relevo_core::cluster::bake::BakeOptions;
use relevo_core::cluster::cut::{CutBand, CutOptions};
use relevo_core::cluster::model::ModelSource;
use relevo_core::cluster::store::{self, NewVegetation};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Type of a list of bands as clap parses it (an alias keeps clap's
/// `Vec` handling off).
type Bands = Vec<CutBand>;

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

pub fn run(a: BakeArgs) -> Result<()> {
    // Locked before it is read: what is baked is what is replaced.
    let lock = BundleLock::acquire(&a.bundle)?;
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
    let mut models: BTreeMap<String, ModelSource> = previous
        .iter()
        .flat_map(|i| &i.classes)
        .map(|c| (c.name.clone(), c.model.clone()))
        .collect();
    for m in &a.models {
        let (class, model) = m
            .split_once('=')
            .with_context(|| format!("--model {m:?}: expected CLASS=MODEL"))?;
        models.insert(class.trim().into(), ModelSource::parse(model.trim()));
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
        lock,
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
