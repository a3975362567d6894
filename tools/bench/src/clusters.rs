//! Vegetation clusters: draws per frame of the plain list, the seed's blobs
//! and the quadtree cut — under the seed's table 4.4 conditions on the
//! sample region, and at 10k–1M objects over a 4097² terrain — with the
//! selection time, and the bake's time and atlas bytes.

use crate::measure::{emit, median, tempfile_dir};
use anyhow::{Context, Result};
use glam::DVec3;
use relevo::prep::region::RegionSpec;
use relevo_core::bundle::Bundle;
use relevo_core::bundle::BundleFiles;
use relevo_core::camera::Camera;
use relevo_core::cluster::bake::BakeOptions;
use relevo_core::cluster::cut::{Blobs, CutOptions, DrawList, ObjectList, QuadtreeCut, Selection};
use relevo_core::cluster::stage::bake_database;
use relevo_core::cluster::Clusters;
use relevo_core::geo::{GeoTransform, TerrainFrame};
use relevo_core::grid::{fractal_heights, HeightGrid};
use relevo_core::horizon::Terrain;
use relevo_core::pyramid::ground::TiledGround;
use relevo_core::pyramid::{TileLayout, DEFAULT_TILE_CELLS};
use relevo_core::veg::db::VegObject;
use serde_json::json;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

/// The seed's table 4.4 (objects, then drawn billboards of configurations
/// 1, 2 and 3 — averages over its flight points; list and blobs draw all).
const SEED_TABLE_4_4: [(usize, [u32; 3]); 10] = [
    (100, [25, 60, 78]),
    (200, [49, 125, 157]),
    (300, [71, 166, 219]),
    (400, [120, 219, 300]),
    (500, [143, 266, 417]),
    (600, [163, 327, 486]),
    (700, [171, 394, 556]),
    (800, [197, 479, 608]),
    (900, [197, 531, 660]),
    (1000, [201, 641, 729]),
];

pub fn clusters(
    repo: &Path,
    runs: usize,
    max_objects: usize,
    budget_mib: u64,
    json_lines: bool,
) -> Result<()> {
    relevo::ingest::gdalio::init();
    let dir = tempfile_dir()?;
    let region = RegionSpec::load(&repo.join("data/olinda/REGION.toml"))?;
    let bundle = relevo::prep::prep(&region, &dir.join("olinda.relevo"), true)?.bundle;
    let bundle = Bundle::open(&bundle)?;
    let database = bundle
        .vegetation()?
        .context("the sample region has no vegetation")?;
    seed_table(&bundle, &database, json_lines)?;
    large(
        &database,
        &bundle.frame(),
        runs,
        max_objects,
        budget_mib,
        json_lines,
    )?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// Table 4.4: 100–1000 of the sample region's real detections (every k-th),
/// one fixed camera seeing the whole region, d₃ beyond the diagonal, 3000 m
/// blobs, 64-texel cluster views as in the seed.
fn seed_table(bundle: &Bundle, database: &[VegObject], json_lines: bool) -> Result<()> {
    let frame = bundle.frame();
    let side_m = (frame.side - 1) as f64 * frame.cell_size_m;
    let diagonal = side_m * std::f64::consts::SQRT_2;
    let (heights, mask) = (bundle.heights()?, bundle.mask()?);
    let ground = Terrain::new(frame.side, frame.cell_size_m, &heights[..], &mask[..], None);
    // South of the region, 4 km up, looking north and down over all of it.
    let camera = Camera {
        position: DVec3::new(side_m / 2.0, -3_000.0, 4_000.0),
        heading_deg: 0.0,
        pitch_deg: -35.0,
        incl_px: 540.0,
        fov_x_deg: 100.0,
        width: 1920,
        height: 1080,
        near_m: 1.0,
        far_m: 100_000.0,
    };
    if !json_lines {
        println!(
            "objects | visible | list | blobs 3000 m | quadtree 1 (seed) | 2 (seed) | 3 (seed)"
        );
    }
    for (count, seed) in SEED_TABLE_4_4 {
        let step = database.len() / count;
        let subset: Vec<VegObject> = database.iter().step_by(step).take(count).cloned().collect();
        let mut draws = Vec::new();
        for config in 1..=3u8 {
            let cut = CutOptions::seed_configuration(config, diagonal).context("configuration")?;
            let options = BakeOptions {
                cut: cut.clone(),
                class_frame_px: 64,
                max_frame_px: 64,
                ..BakeOptions::default()
            };
            let (clusters, _) = bake_database(
                &subset,
                &frame,
                &ground,
                &BTreeMap::new(),
                &options,
                &|_, _| {},
            )?;
            let mut list = DrawList::default();
            if config == 1 {
                ObjectList(&clusters).select(&camera, &cut, &mut list);
                draws.push(list.len());
                Blobs::new(&clusters, 3_000.0).select(&camera, &cut, &mut list);
                draws.push(list.len());
            }
            QuadtreeCut(&clusters).select(&camera, &cut, &mut list);
            draws.push(list.len());
        }
        emit(
            json_lines,
            json!({"bench": "clusters-table-4.4", "objects": count, "list": draws[0], "blobs": draws[1],
                   "quadtree": [draws[2], draws[3], draws[4]], "seed_quadtree": seed}),
            format!(
                "{count} | {} | {} | {} | {} ({}) | {} ({}) | {} ({})",
                draws[0],
                draws[0],
                draws[1],
                draws[2],
                seed[0],
                draws[3],
                seed[1],
                draws[4],
                seed[2]
            ),
        );
    }
    Ok(())
}

/// 10k, 100k and 1M objects: the real detections tiled k×k over a 4097²
/// fractal terrain of 10 m cells (41 km), 8 headings from the centre at
/// 1920×1080.
fn large(
    database: &[VegObject],
    source: &TerrainFrame,
    runs: usize,
    max_objects: usize,
    budget_mib: u64,
    json_lines: bool,
) -> Result<()> {
    let side = 4097;
    let cell = 10.0;
    let extent = (side - 1) as f64 * cell;
    let geotransform = GeoTransform::north_up(-cell / 2.0, extent + cell / 2.0, cell, cell);
    let grid = HeightGrid {
        side,
        heights: fractal_heights(side, 1),
        mask: vec![1u8; side * side],
        geotransform,
    };
    let (heights, mask) = (&grid.heights, &grid.mask);
    let frame = TerrainFrame {
        side,
        cell_size_m: cell,
        geotransform,
    };
    // The same ground read as a pyramid's 512-cell tiles would give it.
    let layout = TileLayout::new(side, DEFAULT_TILE_CELLS)?;
    for count in [10_000usize, 100_000, 1_000_000]
        .into_iter()
        .filter(|&n| n <= max_objects)
    {
        let objects = tiled_detections(database, source, &frame, [[0.0; 2], [extent; 2]], count);
        let options = BakeOptions {
            budget_bytes: budget_mib << 20,
            ..BakeOptions::default()
        };
        let start = Instant::now();
        let ground = Terrain::new(side, cell, &heights[..], &mask[..], None);
        let (clusters, _) = bake_database(
            &objects,
            &frame,
            &ground,
            &BTreeMap::new(),
            &options,
            &|_, _| {},
        )?;
        let bake_ms = start.elapsed().as_secs_f64() * 1e3;
        let baked = clusters.frames.len() / 5;
        emit(
            json_lines,
            json!({"bench": "clusters-bake", "objects": count, "budget_mib": budget_mib, "ms": bake_ms, "nodes": clusters.tree.nodes.len(),
                   "baked_nodes": baked, "atlas_bytes": clusters.report.atlas_bytes,
                   "density_cap": clusters.report.density_cap, "sharp_from_m": clusters.report.sharp_from_m,
                   "levels": clusters.report.levels}),
            format!(
                "bake {count} objects: {bake_ms:.0} ms, {} nodes, {baked} baked, atlas {:.1} MiB, sharp from {:?} m",
                clusters.tree.nodes.len(),
                clusters.report.atlas_bytes as f64 / (1 << 20) as f64,
                clusters.report.sharp_from_m.map(|d| d.round())
            ),
        );
        // The bake of a pyramid: the same objects standing on the same
        // ground read tile by tile (the same clusters, checked).
        let start = Instant::now();
        let tiled = TiledGround::new(&grid, layout, cell);
        let (on_tiles, _) = bake_database(
            &objects,
            &frame,
            &tiled,
            &BTreeMap::new(),
            &options,
            &|_, _| {},
        )?;
        let tiled_ms = start.elapsed().as_secs_f64() * 1e3;
        if on_tiles.tree.objects != clusters.tree.objects {
            anyhow::bail!("{count} objects stand elsewhere on the tiles' ground");
        }
        emit(
            json_lines,
            json!({"bench": "clusters-bake-tiled", "objects": count, "budget_mib": budget_mib,
                   "tile_cells": DEFAULT_TILE_CELLS, "ms": tiled_ms, "grid_ms": bake_ms}),
            format!(
                "bake {count} objects on {}-cell tiles' ground: {tiled_ms:.0} ms (on the whole grid {bake_ms:.0} ms)",
                DEFAULT_TILE_CELLS
            ),
        );
        select_all(
            &clusters,
            &frame,
            heights,
            &options.cut,
            (count, budget_mib),
            runs,
            json_lines,
        );
    }
    Ok(())
}

/// Selection time and draws of each selection, 8 headings from the centre.
fn select_all(
    clusters: &Clusters,
    frame: &TerrainFrame,
    heights: &[f32],
    cut: &CutOptions,
    (count, budget_mib): (usize, u64),
    runs: usize,
    json_lines: bool,
) {
    let centre = (frame.side - 1) as f64 * frame.cell_size_m / 2.0;
    let ground = heights[(frame.side / 2) * frame.side + frame.side / 2] as f64;
    let blobs = Blobs::new(clusters, 3_000.0);
    let quadtree = QuadtreeCut(clusters);
    let list = ObjectList(clusters);
    let selections: [&dyn Selection; 3] = [&list, &blobs, &quadtree];
    let mut out = DrawList::default();
    let one_thread = rayon::ThreadPoolBuilder::new().num_threads(1).build().ok();
    // The quadtree walk is parallel; measure it on one thread too, and with
    // narrower level fades (a fading cluster is drawn with its children).
    let faded = |level_fade: f64| CutOptions {
        level_fade,
        ..cut.clone()
    };
    let mut runs_of: Vec<(
        &dyn Selection,
        String,
        Option<&rayon::ThreadPool>,
        CutOptions,
    )> = selections
        .into_iter()
        .map(|s| (s, s.name().to_string(), None, cut.clone()))
        .collect();
    runs_of.extend(one_thread.as_ref().map(|pool| {
        (
            &quadtree as &dyn Selection,
            "quadtree, 1 thread".to_string(),
            Some(pool),
            cut.clone(),
        )
    }));
    for level_fade in [0.0, 0.1, 0.25]
        .into_iter()
        .filter(|&f| f != cut.level_fade)
    {
        runs_of.push((
            &quadtree,
            format!("quadtree, fade {level_fade}"),
            None,
            faded(level_fade),
        ));
    }
    for (selection, name, pool, cut) in runs_of {
        let cut = &cut;
        let (mut times, mut draws, mut represented) = (Vec::new(), Vec::new(), Vec::new());
        for heading in (0..8).map(|h| h as f64 * 45.0) {
            let camera = Camera {
                position: DVec3::new(centre, centre, ground + 300.0),
                heading_deg: heading,
                pitch_deg: -10.0,
                incl_px: 540.0,
                fov_x_deg: 60.0,
                width: 1920,
                height: 1080,
                near_m: 1.0,
                far_m: 50_000.0,
            };
            for _ in 0..runs {
                let start = Instant::now();
                match pool {
                    Some(pool) => pool.install(|| selection.select(&camera, cut, &mut out)),
                    None => selection.select(&camera, cut, &mut out),
                }
                times.push(start.elapsed().as_secs_f64() * 1e3);
            }
            draws.push(out.len() as f64);
            represented.push(out.represented as f64);
        }
        let (ms, draws, represented) = (median(&times), median(&draws), median(&represented));
        emit(
            json_lines,
            json!({"bench": "clusters-select", "objects": count, "selection": name, "budget_mib": budget_mib, "level_fade": cut.level_fade,
                   "ms": ms, "draws": draws, "represented": represented}),
            format!(
                "select {count} objects, {name:<18}: {ms:.3} ms, {draws:.0} draws for {represented:.0} objects (medians over 8 headings)"
            ),
        );
    }
}

/// The pictures of docs/algorithms.md#clusters: the five views of every
/// built-in model, and cluster views baked on the sample region, each over
/// a light background.
pub fn pictures(repo: &Path, out: &Path) -> Result<()> {
    use relevo_core::cluster::bake::{bake, ClassSource};
    use relevo_core::cluster::checks::frame_image;
    use relevo_core::cluster::image::PremulImage;
    use relevo_core::cluster::model::TreeKind;

    /// Paste `images` left to right (bottoms aligned) over a light
    /// background, `gap` texels apart.
    fn strip(rows: &[Vec<PremulImage>], gap: usize) -> (Vec<u8>, usize, usize) {
        let width = rows
            .iter()
            .map(|r| r.iter().map(|i| i.width + gap).sum::<usize>() + gap)
            .max()
            .unwrap_or(0);
        let heights: Vec<usize> = rows
            .iter()
            .map(|r| r.iter().map(|i| i.height).max().unwrap_or(0))
            .collect();
        let height = heights.iter().map(|h| h + gap).sum::<usize>() + gap;
        let mut rgba: Vec<u8> = [232u8, 238, 240, 255].repeat(width * height);
        let mut y0 = gap;
        for (row, row_height) in rows.iter().zip(&heights) {
            let mut x0 = gap;
            for image in row {
                let top = y0 + row_height - image.height;
                for y in 0..image.height {
                    for x in 0..image.width {
                        let t = image.texel(x, y);
                        let i = ((top + y) * width + x0 + x) * 4;
                        for k in 0..3 {
                            let background = rgba[i + k] as u32 * (255 - t[3] as u32) / 255;
                            rgba[i + k] = (background + t[k] as u32).min(255) as u8;
                        }
                    }
                }
                x0 += image.width + gap;
            }
            y0 += row_height + gap;
        }
        (rgba, width, height)
    }
    let write = |name: &str, (rgba, w, h): (Vec<u8>, usize, usize)| -> Result<()> {
        let bytes = relevo_core::raster::png::encode_rgba(&rgba, w, h)?;
        relevo_core::atomic::write_file(&out.join(name), &bytes)?;
        println!("{}", out.join(name).display());
        Ok(())
    };

    // Every built-in model's views: one class each, baked alone.
    let sources: Vec<ClassSource> = TreeKind::ALL
        .iter()
        .map(|k| ClassSource {
            name: k.name().into(),
            source: relevo_core::cluster::model::ModelSource::Procedural(*k),
            model: k.model(1),
        })
        .collect();
    let objects = (0..4u32)
        .map(|class| relevo_core::cluster::quadtree::ClusterObject {
            foot: [10.0 + 20.0 * class as f32, 10.0, 0.0],
            diameter: 8.0,
            height: 8.0,
            class,
            row: class,
        })
        .collect();
    let options = BakeOptions {
        class_frame_px: 128,
        ..BakeOptions::default()
    };
    let kinds = bake(sources, objects, [0.0; 2], 128.0, &options, &|_, _| {})?;
    let rows: Vec<Vec<PremulImage>> = kinds
        .classes
        .iter()
        .map(|c| c.frames.iter().map(|f| frame_image(&kinds, f)).collect())
        .collect();
    write("impostor_views.png", strip(&rows, 8))?;

    // Cluster views of the sample region: front and top of a few clusters
    // of growing size.
    relevo::ingest::gdalio::init();
    let dir = tempfile_dir()?;
    let region = RegionSpec::load(&repo.join("data/olinda/REGION.toml"))?;
    let bundle = relevo::prep::prep(&region, &dir.join("olinda.relevo"), true)?.bundle;
    let (_, clusters) =
        relevo_core::cluster::store::read(&Bundle::open(&bundle)?)?.context("no clusters")?;
    let mut rows = Vec::new();
    for wanted in [4u32, 16, 64] {
        let node = clusters
            .tree
            .nodes
            .iter()
            .filter(|n| n.frames != relevo_core::cluster::quadtree::NONE && n.count >= wanted)
            .min_by_key(|n| n.count)
            .context("no baked cluster of that size")?;
        rows.push(
            [0usize, 1, 3]
                .iter()
                .map(|&v| frame_image(&clusters, &clusters.frames[node.frames as usize + v]))
                .collect(),
        );
    }
    write("cluster_views.png", strip(&rows, 8))?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// `count` objects: the real detections of `database` (on `source`) tiled
/// k × k over `area` of the terrain of `target` (its lowest and highest
/// terrain coordinates, metres), k the smallest that holds them, in
/// database order tile after tile — density grows with the count.
pub fn tiled_detections(
    database: &[VegObject],
    source: &TerrainFrame,
    target: &TerrainFrame,
    area: [[f64; 2]; 2],
    count: usize,
) -> Vec<VegObject> {
    let source_side = (source.side - 1) as f64 * source.cell_size_m;
    let relative: Vec<(f64, f64, &VegObject)> = database
        .iter()
        .filter_map(|o| {
            let (x, y) = source.terrain_from_world(o.x, o.y)?;
            // Vertices stand half a cell inside the grid's edge: an object
            // on that rim is kept on the tile.
            let relative = |t: f64| (t / source_side).clamp(0.0, 1.0);
            Some((relative(x), relative(y), o))
        })
        .collect();
    if relative.is_empty() {
        return Vec::new();
    }
    let tiles = count.div_ceil(relative.len());
    let k = (tiles as f64).sqrt().ceil() as usize;
    let [low, high] = area;
    let tile_m = [0, 1].map(|a| (high[a] - low[a]) / k as f64);
    (0..count)
        .map(|i| {
            // Fewer than the detections: spread over them, not the first ones.
            let source = if count <= relative.len() {
                i * relative.len() / count
            } else {
                i % relative.len()
            };
            let (tile, (rx, ry, o)) = (i / relative.len(), relative[source]);
            let (x, y) = (
                low[0] + ((tile % k) as f64 + rx) * tile_m[0],
                low[1] + ((tile / k) as f64 + ry) * tile_m[1],
            );
            let (east, north) = target.world_from_terrain(x, y);
            VegObject {
                id: i as u64 + 1,
                x: east,
                y: north,
                class: o.class.clone(),
                size: o.size,
                score: o.score,
            }
        })
        .collect()
}
