//! `relevo bake`: (re)bake the vegetation clusters of an existing bundle or
//! pyramid — class impostors from their models, the quadtree's views, the
//! atlases — replacing its `clusters/` atomically (a pyramid's objects
//! stand on its level-0 tiles, read one at a time).

use crate::clusters::{count_on, print_report};
use crate::progress;
use anyhow::{bail, Context, Result};
use clap::Args;
use relevo_core::bundle::{format_of, Bundle, BundleFiles, BundleLock, PYRAMID_FORMAT};
use relevo_core::cluster::bake::BakeOptions;
use relevo_core::cluster::cut::{CutBand, CutOptions};
use relevo_core::cluster::model::ModelSource;
use relevo_core::cluster::stage::bake_database;
use relevo_core::cluster::store::{self, NewVegetation};
use relevo_core::cluster::Clusters;
use relevo_core::pyramid::{self, ground::TiledGround, Pyramid};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Type of a list of bands as clap parses it (an alias keeps clap's
/// `Vec` handling off).
type Bands = Vec<CutBand>;

#[derive(Args, Debug)]
pub struct BakeArgs {
    /// The bundle or pyramid whose vegetation to cluster (rewritten in
    /// place).
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
    let opened = if format_of(&a.bundle).as_deref() == Some(PYRAMID_FORMAT) {
        Opened::Pyramid(Pyramid::open(&a.bundle)?)
    } else {
        Opened::Single(Bundle::open(&a.bundle)?)
    };
    let bundle = opened.files();
    if bundle.vegetation()?.is_none() {
        bail!(
            "{}: the bundle has no vegetation database to cluster (run `relevo veg detect` or prep with samples)",
            a.bundle.display()
        );
    }
    // Start from what the bundle was baked with, then apply the flags.
    let previous = store::read_index(bundle)?;
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
    let (path, clusters, off_terrain) = match &opened {
        Opened::Single(bundle) => store::rewrite_bundle(
            lock,
            bundle,
            &NewVegetation::default(),
            &models,
            &options,
            &count_on(&bar),
        ),
        Opened::Pyramid(p) => rebake_pyramid(lock, p, &models, &options, &count_on(&bar)),
    }
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

/// The bundle being re-baked, of either format.
enum Opened {
    Single(Bundle),
    Pyramid(Pyramid),
}

impl Opened {
    fn files(&self) -> &dyn BundleFiles {
        match self {
            Opened::Single(b) => b,
            Opened::Pyramid(p) => p,
        }
    }
}

/// Bake the clusters of pyramid `p`'s database, its objects standing on the
/// level-0 tiles, and replace its clusters in place (see
/// `pyramid::rewrite`). Returns its path, the clusters and the objects off
/// the terrain.
fn rebake_pyramid(
    lock: BundleLock,
    p: &Pyramid,
    models: &BTreeMap<String, ModelSource>,
    options: &BakeOptions,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> relevo_core::Result<(PathBuf, Clusters, usize)> {
    let database = p.vegetation()?.unwrap_or_default();
    let ground = TiledGround::new(p, p.layout, p.manifest.grid.cell_size_m);
    let (clusters, off_terrain) =
        bake_database(&database, &p.frame(), &ground, models, options, progress)?;
    let path = pyramid::rewrite(
        lock,
        p,
        &store::is_cluster_artifact,
        |files| store::write(files, &clusters, options, off_terrain),
        &|staged| store::validate(staged),
    )?;
    Ok((path, clusters, off_terrain))
}
