//! `relevo-bench view-inputs`: the bundles behind the viewer's figures,
//! written to a folder so that `relevo-view bench` (which needs no GDAL)
//! can fly over them on a machine that has a GPU and nothing else: the
//! sample regions, the 4097² fractal, and the sample region with a
//! million objects tiled from its own detections, as a single grid and as
//! a pyramid of 32-cell tiles.

use crate::view::bench_bundles;
use crate::view_vegetation::densify;
use anyhow::{Context, Result};
use relevo::prep::prep;
use relevo::prep::region::RegionSpec;
use std::path::Path;

/// Write the bundles into `out` and print the benchmark's commands.
pub fn run(repo: &Path, data: &Path, out: &Path, objects: usize) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| out.display().to_string())?;
    let bundles = bench_bundles(repo, data, out, 4097)?;
    let dense = out.join(format!("olinda_{objects}_objects.relevo"));
    prep(
        &RegionSpec::load(&repo.join("data/olinda/REGION.toml"))?,
        &dense,
        true,
    )?;
    densify(&dense, objects)?;
    let dense_pyramid = out.join(format!("olinda_{objects}_objects_tiled.relevo"));
    let tiled = relevo::prep::tiled::TiledOptions {
        tile_cells: Some(32),
        force: true,
        resume: false,
    };
    relevo::prep::tiled::prep_tiled(
        &RegionSpec::load(&repo.join("data/olinda/REGION.toml"))?,
        &dense_pyramid,
        tiled,
    )?;
    densify(&dense_pyramid, objects)?;
    println!(
        "Copy {} (and data/olinda/objects.geojson) to the machine, then:",
        out.display()
    );
    for (_, path, placements) in &bundles {
        let objects = placements
            .as_ref()
            .map(|p| format!(" --objects {}", p.display()))
            .unwrap_or_default();
        println!(
            "  relevo-view bench {}{objects} --size 1920x1080 --json",
            path.display()
        );
    }
    println!(
        "  relevo-view bench {} --size 1920x1080 --json",
        dense.display()
    );
    println!(
        "  relevo-view bench {} --size 1920x1080 --json",
        dense_pyramid.display()
    );
    Ok(())
}
