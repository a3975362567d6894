//! `relevo info`: describe a bundle.

use crate::clusters::print_report;
use anyhow::Result;
use clap::Args;
use relevo_core::bundle::BundleFiles;
use relevo_core::bundle::{Bundle, Crs};
use relevo_core::cluster::store;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// The bundle to describe.
    pub bundle: PathBuf,
    /// Print the whole manifest as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: InfoArgs) -> Result<()> {
    describe(&a.bundle, a.json)
}

fn describe(path: &Path, json: bool) -> Result<()> {
    if relevo_core::bundle::format_of(path).as_deref() == Some(relevo_core::bundle::PYRAMID_FORMAT)
    {
        return describe_pyramid(path, json);
    }
    let bundle = Bundle::open(path)?;
    let m = &bundle.manifest;
    if json {
        println!("{}", serde_json::to_string_pretty(m)?);
        return Ok(());
    }
    print_header(path, &m.region, &m.format, m.format_version, &m.crs);
    let g = &m.grid;
    println!(
        "  grid         {0}×{0} vertices, {1:.3} m cells, z scale {2}",
        g.side, g.cell_size_m, g.z_scale
    );
    println!(
        "  data         {} vertices, heights {:.2}..{:.2} m",
        g.valid_vertices, g.height_range_m[0], g.height_range_m[1]
    );
    println!("  extent       {:?}", g.valid_extent);
    if let Some(c) = &m.color {
        println!(
            "  colour       {}×{} pixels, bands {:?}",
            c.width, c.height, c.bands
        );
    }
    print_vegetation(&bundle)?;
    for (name, a) in m.artifacts.iter().chain(&m.exports) {
        println!(
            "  {name:<12} {} {:?} {:?} {} bytes",
            a.file, a.dtype, a.shape, a.bytes
        );
    }
    for t in &m.timings {
        println!("  stage {:<6} {:.1} ms", t.stage, t.ms);
    }
    Ok(())
}

/// The vegetation database by class and its clusters, of either kind of
/// bundle, when it has them.
fn print_vegetation(bundle: &dyn BundleFiles) -> Result<()> {
    if let Some(objects) = bundle.vegetation()? {
        let mut per_class = std::collections::BTreeMap::new();
        for o in &objects {
            *per_class.entry(o.class.as_str()).or_insert(0usize) += 1;
        }
        println!("  vegetation   {} objects {per_class:?}", objects.len());
    }
    if let Some(index) = store::read_index(bundle)? {
        let o = &index.options;
        let bands: Vec<String> = o
            .cut
            .bands
            .iter()
            .map(|b| format!("{}:{}", b.until_m, b.max_cluster))
            .collect();
        println!(
            "  clusters     {} objects ({} off the terrain), {} nodes, {} pages; bands {}",
            index.objects,
            index.off_terrain,
            index.nodes,
            index.pages.len(),
            bands.join(",")
        );
        for c in &index.classes {
            println!(
                "    class {:<12} model {} (height {:.2} × diameter)",
                c.name, c.model, c.aspect
            );
        }
        print_report(&index.report);
    }
    Ok(())
}

/// The first lines of either kind of bundle: path, region, format, CRS.
fn print_header(path: &Path, region: &str, format: &str, version: u32, crs: &Crs) {
    println!(
        "{} — region {region:?}, format {format} v{version}",
        path.display()
    );
    match crs.epsg {
        Some(code) => println!("  CRS          EPSG:{code}"),
        None if crs.wkt.is_empty() => println!("  CRS          none (grid units)"),
        None => println!("  CRS          custom (WKT in manifest)"),
    }
}

/// `relevo info` of a pyramid: the grid, the tiling level by level, the files.
fn describe_pyramid(path: &Path, json: bool) -> Result<()> {
    let p = relevo_core::pyramid::Pyramid::open(path)?;
    let m = &p.manifest;
    if json {
        println!("{}", serde_json::to_string_pretty(m)?);
        return Ok(());
    }
    print_header(path, &m.region, &m.format, m.format_version, &m.crs);
    let g = &m.grid;
    println!(
        "  grid         {0}×{0} vertices, {1:.3} m cells",
        g.side, g.cell_size_m
    );
    println!(
        "  data         {} vertices, heights {:.2}..{:.2} m",
        g.valid_vertices, g.height_range_m[0], g.height_range_m[1]
    );
    println!(
        "  tiles        {} of {}² vertices in {} levels, LP errors: {:?}",
        m.tiling.tiles,
        m.tiling.tile_cells + 1,
        m.tiling.levels,
        m.lp_error_metric
    );
    for level in 0..p.layout.levels() {
        let across = p.layout.across(level);
        println!(
            "    level {level:<2}   {across}×{across} tiles, a sample every {} vertices ({:.1} m)",
            p.layout.stride(level),
            g.cell_size_m * p.layout.stride(level) as f64
        );
    }
    print_vegetation(&p)?;
    for (key, a) in &m.files {
        println!("  {key:<12} {} ({:.1} MB)", a.file, a.bytes as f64 / 1e6);
    }
    for t in &m.timings {
        println!("  pass {:<16} {:.1} s", t.stage, t.ms / 1e3);
    }
    Ok(())
}
