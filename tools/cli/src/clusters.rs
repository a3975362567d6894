//! Baking vegetation clusters as the commands do it: with a progress bar,
//! and reported the same way by `prep`, `bake` and `info`.

use crate::progress;
use anyhow::Result;
use relevo_core::cluster::bake::BakeOptions;
use relevo_core::cluster::model::ModelSource;
use relevo_core::cluster::stage::{bake_database, Ground};
use relevo_core::cluster::{BakeReport, Clusters};
use relevo_core::geo::TerrainFrame;
use relevo_core::veg::db::VegObject;
use serde::Serialize;
use std::collections::BTreeMap;

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
pub fn count_on(bar: &indicatif::ProgressBar) -> impl Fn(u64, u64) + Sync + '_ {
    move |n, total| {
        bar.set_length(total);
        bar.inc(n);
    }
}

/// [`bake_database`] with a progress bar over the clusters composed.
pub fn bake_with_progress(
    database: &[VegObject],
    frame: &TerrainFrame,
    ground: &dyn Ground,
    models: &BTreeMap<String, ModelSource>,
    options: &BakeOptions,
) -> Result<(Clusters, usize)> {
    let bar = progress::bar(0, "clusters");
    let result = bake_database(database, frame, ground, models, options, &count_on(&bar));
    bar.finish_and_clear();
    Ok(result?)
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
