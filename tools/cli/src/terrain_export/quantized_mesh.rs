//! `relevo export quantized-mesh`: `layer.json` and `{z}/{x}/{y}.terrain`,
//! each tile encoded by `relevo_core::terrain_tiles::quantized_mesh`.

use super::{
    check_out, for_each_tile, with_source, write_file, write_folder, Grid, ManifestParts,
    Placement, Request,
};
use anyhow::Result;
use relevo_core::lp::export::MeshSource;
use relevo_core::lp::extract::mask_boundaries;
use relevo_core::terrain_tiles::quantized_mesh::{encode, TileExtras};
use relevo_core::terrain_tiles::tiling::TileRange;
use relevo_core::terrain_tiles::{available_json, children_available, patch, water_mask};
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// What an export wrote.
#[derive(Debug, Serialize)]
pub struct Summary {
    pub out: String,
    pub max_zoom: u32,
    pub tiles: usize,
    pub bytes: u64,
    /// Each level's triangles with data, as its tiles hold them (cut
    /// where they cross tile lines), level 0 first.
    pub level_triangles: Vec<usize>,
    /// What the heights are measured from, as written.
    pub heights: String,
    pub seconds: f64,
}

impl Summary {
    pub fn line(&self) -> String {
        format!(
            "{}: levels 0–{}, {} tiles, {:.1} MB; {}; {:.1} s",
            self.out,
            self.max_zoom,
            self.tiles,
            self.bytes as f64 / 1e6,
            self.heights,
            self.seconds
        )
    }
}

/// Export `a.bundle` as quantized-mesh tiles into `a.out`.
pub fn export(a: &Request) -> Result<Summary> {
    check_out(a, "layer.json")?;
    let start = Instant::now();
    with_source(a.bundle, |source, manifest, _| {
        export_source(a, source, manifest, start)
    })
}

fn export_source(
    a: &Request,
    source: &dyn MeshSource,
    manifest: &ManifestParts,
    start: Instant,
) -> Result<Summary> {
    let frame = source.frame();
    let place = Placement::of(a, &frame, manifest)?;
    let (max_zoom, bounds, geoid_m) = (place.max_zoom, place.bounds, place.geoid_m);
    let heights_note = place.heights_note.clone();
    let tiles = TileSet {
        ranges: (0..=max_zoom)
            .map(|z| TileRange::covering(z, bounds))
            .collect(),
        // One quantization of heights for every tile, so that shared
        // vertices decode alike: the bundle's heights, moved by the
        // geoid's range over the region (with a margin for between its
        // samples), and 0, where the fill lies.
        height_range_m: {
            let [lo, hi] = manifest.height_range_m;
            let margin = 1.0 + 0.2 * (geoid_m[1] - geoid_m[0]);
            [
                (lo + geoid_m[0] - margin).min(0.0),
                (hi + geoid_m[1] + margin).max(0.0),
            ]
        },
        outline: place.outline.clone(),
    };
    let layer = serde_json::json!({
        "tilejson": "2.1.0",
        "name": manifest.region,
        "description": format!("Relevo {}: {heights_note}", env!("CARGO_PKG_VERSION")),
        "version": "1.0.0",
        "format": "quantized-mesh-1.0",
        "scheme": "tms",
        "tiles": ["{z}/{x}/{y}.terrain?v={version}"],
        "projection": "EPSG:4326",
        "bounds": bounds,
        "minzoom": 0,
        "maxzoom": max_zoom,
        "available": available_json(&tiles.ranges),
        // Clients that read availability from the tiles: each tile lists
        // its children (CesiumJS reads the metadata extension only so).
        "metadataAvailability": 1,
        "extensions": ["octvertexnormals", "watermask", "metadata"],
    });
    // The mask's boundaries, once for every tile's walk.
    let boundaries = mask_boundaries(frame.side, &|i| source.has_data(i));
    let grid = place.grid(a, source, manifest, &boundaries);
    let (count, bytes, level_triangles) =
        write_folder(a.out, |staging| tiles.write(staging, &grid, &layer))?;
    Ok(Summary {
        out: a.out.display().to_string(),
        max_zoom,
        tiles: count,
        bytes,
        level_triangles,
        heights: heights_note,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// What every tile of an export shares.
struct TileSet {
    /// Each level's available tiles, level 0 first.
    ranges: Vec<TileRange>,
    height_range_m: [f64; 2],
    /// The grid's data extent, degrees (water where it holds no data).
    outline: Vec<[f64; 2]>,
}

impl TileSet {
    /// Write each level's tiles, cut from `grid` (tiles in parallel, each
    /// worker with its own PROJ transforms), and `layer.json` into
    /// `folder`: the tiles and bytes written, and each level's triangles.
    fn write(
        &self,
        folder: &Path,
        grid: &Grid,
        layer: &serde_json::Value,
    ) -> Result<(usize, u64, Vec<usize>)> {
        let (mut tiles, mut bytes) = (0, 0u64);
        let mut level_triangles = vec![0; self.ranges.len()];
        for_each_tile(
            &self.ranges,
            grid,
            |to_earth, tile| {
                let patch = patch(&grid.tile_mesh(to_earth, tile)?, tile);
                let children = children_available(tile, self.ranges.get(tile.z as usize + 1));
                let extras = TileExtras {
                    height_range_m: self.height_range_m,
                    water: water_mask(&patch, &self.outline),
                    children_available: &children,
                };
                Ok((encode(tile, &patch.mesh, &extras), patch.covered))
            },
            |tile, (data, covered)| {
                write_file(
                    folder,
                    &format!("{}/{}/{}.terrain", tile.z, tile.x, tile.y),
                    &data,
                )?;
                tiles += 1;
                bytes += data.len() as u64;
                level_triangles[tile.z as usize] += covered;
                Ok(())
            },
        )?;
        let text = serde_json::to_string_pretty(layer)?;
        std::fs::write(folder.join("layer.json"), &text)?;
        Ok((tiles, bytes + text.len() as u64, level_triangles))
    }
}
