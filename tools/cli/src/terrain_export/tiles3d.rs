//! `relevo export 3dtiles`: the terrain as glb tiles in Cesium's geodetic
//! tiling (the quantized-mesh export's meshes, each tile's covered part),
//! textured with the drape; the vegetation database as instanced glb tiles
//! split by a quadtree; a `tileset.json` for each and one over both.
//!
//! ```text
//! OUT/tileset.json               both, refined by adding
//! OUT/terrain/tileset.json       {z}/{x}/{y}.glb, refined by replacing
//! OUT/vegetation/tileset.json    {depth}/{x}/{y}.glb, refined by adding
//! ```

use super::{
    check_out, for_each_tile, with_source, write_file, write_folder, Grid, ManifestParts,
    Placement, Request, ToEllipsoid, TILES_A_BATCH,
};
use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use relevo_core::bundle::Bundle;
use relevo_core::bundle::BundleFiles;
use relevo_core::cluster::store;
use relevo_core::lp::export::MeshSource;
use relevo_core::lp::extract::mask_boundaries;
use relevo_core::terrain_tiles::tiling::{level_geometric_error_m, TileId, TileRange};
use relevo_core::terrain_tiles::{bounds_of, patch};
use relevo_core::tiles3d::terrain::{self, Skirt, TileTexture};
use relevo_core::tiles3d::tileset::{self, Refine, Tile};
use relevo_core::tiles3d::vegetation::{self, ClassMesh, Instance, VegTile, TILE_CAPACITY};
use relevo_core::tiles3d::{LocalFrame, Region};
use serde::Serialize;
use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

/// What an export wrote.
#[derive(Debug, Serialize)]
pub struct Summary {
    pub out: String,
    /// The terrain's coarsest and finest levels.
    pub levels: [u32; 2],
    pub terrain_tiles: usize,
    /// Whether the terrain tiles carry the drape.
    pub textured: bool,
    pub vegetation_tiles: usize,
    pub vegetation_objects: usize,
    pub bytes: u64,
    /// What the heights are measured from, as written.
    pub heights: String,
    pub seconds: f64,
}

impl Summary {
    pub fn line(&self) -> String {
        format!(
            "{}: terrain levels {}–{}, {} tiles{}; {} vegetation objects in {} tiles; {:.1} MB; {}; {:.1} s",
            self.out,
            self.levels[0],
            self.levels[1],
            self.terrain_tiles,
            if self.textured { " with the drape" } else { "" },
            self.vegetation_objects,
            self.vegetation_tiles,
            self.bytes as f64 / 1e6,
            self.heights,
            self.seconds
        )
    }
}

/// Export `a.bundle` as 3D Tiles into `a.out`.
pub fn export(a: &Request) -> Result<Summary> {
    check_out(a, "tileset.json")?;
    let start = Instant::now();
    with_source(a.bundle, |source, manifest, bundle| {
        export_source(a, source, manifest, bundle, start)
    })
}

/// Most tiles at the terrain's coarsest level: the first level is the
/// finest whose tiles over the region are no more than this.
const MAX_FIRST_LEVEL_TILES: usize = 4;

fn export_source(
    a: &Request,
    source: &dyn MeshSource,
    manifest: &ManifestParts,
    bundle: Option<&Bundle>,
    start: Instant,
) -> Result<Summary> {
    let frame = source.frame();
    let place = Placement::of(a, &frame, manifest)?;
    let first = (0..=place.max_zoom)
        .rev()
        .find(|&z| TileRange::covering(z, place.bounds).tile_count() <= MAX_FIRST_LEVEL_TILES)
        .unwrap_or(0);
    let ranges: Vec<TileRange> = (first..=place.max_zoom)
        .map(|z| TileRange::covering(z, place.bounds))
        .collect();
    let [w, s, e, n] = place.bounds;
    let [lo, hi] = manifest.height_range_m;
    let local = LocalFrame::at(
        (w + e) / 2.0,
        (s + n) / 2.0,
        (lo + hi) / 2.0 + (place.geoid_m[0] + place.geoid_m[1]) / 2.0,
    );
    // The error of drawing none of a tileset: the region's size (its
    // diagonal), so that a client draws it wherever the region is in view.
    let region_m = {
        let metres_per_deg = 111_320.0;
        let dx = (e - w) * metres_per_deg * ((s + n) / 2.0).to_radians().cos();
        let dy = (n - s) * metres_per_deg;
        (dx * dx + dy * dy).sqrt()
    };
    let vegetation = match bundle {
        Some(b) => vegetation_of(b, &place.to_earth)?,
        None => None,
    };
    let boundaries = mask_boundaries(frame.side, &|i| source.has_data(i));
    let grid = place.grid(a, source, manifest, &boundaries);
    let drape_pixel_deg = drape_pixel_deg(source, &place.to_earth)?;
    let (terrain_tiles, vegetation_tiles, bytes) = write_folder(a.out, |folder| {
        let (terrain, count, mut bytes) =
            write_terrain(folder, &grid, &ranges, &local, region_m, drape_pixel_deg)?;
        let mut children = vec![("terrain/tileset.json", terrain)];
        let mut vegetation_tiles = 0;
        if let Some((classes, objects)) = &vegetation {
            let (tree, n, b) =
                write_vegetation(folder, classes, objects.clone(), &local, region_m)?;
            children.push(("vegetation/tileset.json", tree));
            vegetation_tiles = n;
            bytes += b;
        }
        // The tileset over both: each child an external tileset.
        let root = Tile::over(
            "root".into(),
            None,
            region_m,
            children
                .iter()
                .map(|(uri, t)| Tile {
                    name: t.name.clone(),
                    region: t.region,
                    geometric_error_m: region_m.max(t.geometric_error_m),
                    content: Some(uri.to_string()),
                    children: vec![],
                })
                .collect(),
        );
        bytes += write_tileset(folder, &root, "tileset.json", Refine::Add, None, region_m)?;
        Ok((count, vegetation_tiles, bytes))
    })?;
    Ok(Summary {
        out: a.out.display().to_string(),
        levels: [first, place.max_zoom],
        terrain_tiles,
        textured: drape_pixel_deg.is_some(),
        vegetation_tiles,
        vegetation_objects: vegetation.as_ref().map_or(0, |v| v.1.len()),
        bytes,
        heights: place.heights_note,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Write the tileset files of `root` into `folder` (`path` the root's; see
/// [`tileset::files`]): their bytes.
fn write_tileset(
    folder: &Path,
    root: &Tile,
    path: &str,
    refine: Refine,
    transform: Option<[f64; 16]>,
    unrendered_error_m: f64,
) -> Result<u64> {
    let mut bytes = 0;
    let dir = Path::new(path).parent().unwrap_or(Path::new(""));
    let name = Path::new(path)
        .file_name()
        .map_or(path.into(), |n| n.to_string_lossy());
    for (file, json) in tileset::files(root, &name, refine, transform, unrendered_error_m) {
        let text = serde_json::to_string(&json)?;
        write_file(folder, &dir.join(&file).to_string_lossy(), text.as_bytes())?;
        bytes += text.len() as u64;
    }
    Ok(bytes)
}

/// Degrees a drape pixel spans at the grid's centre; `None` without a
/// drape.
fn drape_pixel_deg(source: &dyn MeshSource, to_earth: &ToEllipsoid) -> Result<Option<f64>> {
    let frame = source.frame();
    let c = (frame.side / 2) as f64;
    let Some(drape) = source.drape(relevo_core::lp::window::Rect {
        c0: frame.side / 2,
        r0: frame.side / 2,
        width: 2,
        height: 2,
    })?
    else {
        return Ok(None);
    };
    let (pixel_w, _) = drape.geotransform.cell_size();
    let (x0, y0) = frame.world_from_vertex(c, c);
    let (x1, y1) = frame.world_from_vertex(c + 1.0, c);
    let cell_world = ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt();
    Ok(Some(
        to_earth.cell_deg(&frame)? * pixel_w.abs() / cell_world,
    ))
}

/// Each terrain tile's region and geometric error, when it has content.
type TerrainRecords = HashMap<TileId, (Region, f64)>;

/// Write the terrain tiles of `ranges` and their tileset under
/// `folder/terrain`: the tree (for the tileset over both), the tiles and
/// the bytes written.
fn write_terrain(
    folder: &Path,
    grid: &Grid,
    ranges: &[TileRange],
    local: &LocalFrame,
    region_m: f64,
    drape_pixel_deg: Option<f64>,
) -> Result<(Tile, usize, u64)> {
    let mut records = TerrainRecords::new();
    let mut bytes = 0u64;
    for_each_tile(
        ranges,
        grid,
        |to_earth, tile| terrain_tile(grid, to_earth, tile, local, drape_pixel_deg),
        |tile, made| {
            if let Some((glb, region, error_m)) = made {
                write_file(
                    folder,
                    &format!("terrain/{}/{}/{}.glb", tile.z, tile.x, tile.y),
                    &glb,
                )?;
                bytes += glb.len() as u64;
                records.insert(tile, (region, error_m));
            }
            Ok(())
        },
    )?;
    let count = records.len();
    let first = &ranges[0];
    let children: Vec<Tile> = first
        .tiles()
        .filter_map(|t| terrain_tree(t, &records, ranges))
        .collect();
    if children.is_empty() {
        bail!("no terrain tile holds data: the mask covers nothing");
    }
    // The root has no content: its error, the region's size, makes
    // clients refine it wherever they see it.
    let root = Tile::over("root".into(), None, region_m, children);
    bytes += write_tileset(
        folder,
        &root,
        "terrain/tileset.json",
        Refine::Replace,
        Some(local.transform()),
        region_m,
    )?;
    Ok((root, count, bytes))
}

/// The tree under `tile`: the tile with its content if it has any, over
/// its children's trees; `None` when neither it nor a descendant has data.
fn terrain_tree(tile: TileId, records: &TerrainRecords, ranges: &[TileRange]) -> Option<Tile> {
    let last = ranges.last()?.z;
    let children: Vec<Tile> = if tile.z < last {
        tile.children()
            .into_iter()
            .filter_map(|c| terrain_tree(c, records, ranges))
            .collect()
    } else {
        Vec::new()
    };
    let own = records.get(&tile);
    if own.is_none() && children.is_empty() {
        return None;
    }
    Some(Tile::over(
        format!("{}/{}/{}", tile.z, tile.x, tile.y),
        own.map(|(region, _)| (format!("{}/{}/{}.glb", tile.z, tile.x, tile.y), *region)),
        own.map_or(0.0, |r| r.1),
        children,
    ))
}

/// Tile `tile`'s glb, region and geometric error — the largest LP error of
/// the vertices its level's mesh leaves out around it (its vertical error
/// bound), 0 on the last level — or `None` where it covers no data.
fn terrain_tile(
    grid: &Grid,
    to_earth: &ToEllipsoid,
    tile: TileId,
    local: &LocalFrame,
    drape_pixel_deg: Option<f64>,
) -> Result<Option<(Vec<u8>, Region, f64)>> {
    let p = patch(&grid.tile_mesh(to_earth, tile)?, tile);
    if p.covered == 0 {
        return Ok(None);
    }
    let Some(window) = grid.window(to_earth, tile)? else {
        return Ok(None);
    };
    let max_error = grid.max_error(tile);
    let mut error_m = 0f32;
    for r in window.r0..window.r0 + window.height {
        for c in window.c0..window.c0 + window.width {
            let i = r * grid.frame.side + c;
            let e = grid.source.error(i);
            if e <= max_error && grid.source.has_data(i) {
                error_m = error_m.max(e);
            }
        }
    }
    grid.source.release();
    let texture = match drape_pixel_deg {
        Some(pixel_deg) => {
            let covered = &p.mesh.triangles[..p.covered];
            let corners: Vec<[f64; 2]> = covered
                .iter()
                .flat_map(|t| t.map(|v| p.mesh.lon_lat_deg[v as usize]))
                .collect();
            let bounds = bounds_of(&corners);
            let (width, height) = terrain::texture_size(bounds, pixel_deg);
            let lattice = to_earth.to_world(&terrain::lattice(bounds))?;
            let world = terrain::texel_world(width, height, &lattice);
            let rgb = match grid.source.drape(window)? {
                Some(drape) => terrain::drape_rgb(&drape, &world),
                None => vec![128; width * height * 3],
            };
            Some(TileTexture {
                jpeg: terrain::encode_jpeg(&rgb, width, height)?,
                bounds_deg: bounds,
            })
        }
        None => None,
    };
    let skirt = Skirt {
        bounds_deg: tile.bounds_deg(),
        depth_m: terrain::skirt_depth_m(level_geometric_error_m(tile.z)),
    };
    Ok(
        terrain::glb(&p.mesh, p.covered, local, texture.as_ref(), skirt)?
            .map(|(glb, region)| (glb, region, error_m as f64)),
    )
}

/// The vegetation of a single-grid bundle on the ellipsoid, with its
/// classes' meshes: the objects the cluster bake placed on the terrain
/// (their ids and scores from the database); `None` without a bake.
fn vegetation_of(
    bundle: &Bundle,
    to_earth: &ToEllipsoid,
) -> Result<Option<(Vec<ClassMesh>, Vec<Instance>)>> {
    let Some((index, tree, _)) = store::read_tree(bundle)? else {
        if bundle.vegetation()?.is_some() {
            tracing::warn!(
                "the bundle's vegetation has not been baked (relevo bake): only the terrain is exported"
            );
        }
        return Ok(None);
    };
    let database = bundle
        .vegetation()?
        .context("the bundle has clusters but no vegetation database")?;
    let classes = index
        .classes
        .iter()
        .map(|c| {
            let model = c
                .model
                .load()
                .with_context(|| format!("the model of vegetation class {}", c.name))?;
            Ok(ClassMesh::of(&c.name, &model))
        })
        .collect::<Result<Vec<_>>>()?;
    if classes.len() > u8::MAX as usize {
        bail!("{} vegetation classes: at most 255", classes.len());
    }
    let objects = &tree.objects;
    // The database, the objects on the Earth, their quadtree and a batch
    // of tiles, measured at 1M objects: 440 MB.
    relevo_core::memory::check(
        &format!("the 3D Tiles of {} vegetation objects", objects.len()),
        objects.len() as u64,
        450,
        "export a bundle with fewer objects",
    )?;
    let frame = bundle.frame();
    let mut world = Vec::with_capacity(objects.len());
    let mut rows = Vec::with_capacity(objects.len());
    for o in objects {
        let Some(row) = database.get(o.row as usize) else {
            bail!(
                "a baked object names database row {}, past its {} objects",
                o.row,
                database.len()
            );
        };
        let (x, y) = frame.world_from_terrain(o.foot[0] as f64, o.foot[1] as f64);
        world.push([x, y, o.foot[2] as f64]);
        rows.push(row);
    }
    let on_earth = to_earth.to_ellipsoid(&world)?;
    let instances = objects
        .iter()
        .zip(rows)
        .zip(on_earth)
        .map(|((o, row), [lon, lat, h])| Instance {
            id: row.id,
            class: o.class as u8,
            lon_deg: lon,
            lat_deg: lat,
            foot_height_m: h,
            diameter_m: o.diameter,
            height_m: o.height,
            score: row.score,
        })
        .collect();
    Ok(Some((classes, instances)))
}

/// Write the vegetation's quadtree tiles and tileset under
/// `folder/vegetation`: the tree, the tiles and the bytes written.
fn write_vegetation(
    folder: &Path,
    classes: &[ClassMesh],
    objects: Vec<Instance>,
    local: &LocalFrame,
    region_m: f64,
) -> Result<(Tile, usize, u64)> {
    let points: Vec<[f64; 2]> = objects.iter().map(|o| [o.lon_deg, o.lat_deg]).collect();
    let root = vegetation::quadtree(objects, bounds_of(&points), TILE_CAPACITY);
    let mut flat: Vec<&VegTile> = Vec::new();
    let mut stack = vec![&root];
    while let Some(t) = stack.pop() {
        flat.push(t);
        stack.extend(t.children.iter());
    }
    flat.retain(|t| !t.objects.is_empty());
    let (mut bytes, mut count) = (0, 0);
    // A batch of tiles at a time, in parallel, then written.
    for batch in flat.chunks(TILES_A_BATCH) {
        let made: Vec<Result<Vec<u8>>> = batch
            .par_iter()
            .map(|t| Ok(vegetation::glb(&t.objects, classes, local)?))
            .collect();
        for (t, glb) in batch.iter().zip(made) {
            let glb = glb?;
            write_file(folder, &format!("vegetation/{}", t.path()), &glb)?;
            bytes += glb.len() as u64;
            count += 1;
        }
    }
    let tree = vegetation::tiles(&root);
    bytes += write_tileset(
        folder,
        &tree,
        "vegetation/tileset.json",
        Refine::Add,
        Some(local.transform()),
        region_m,
    )?;
    Ok((tree, count, bytes))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain_export::VerticalDatum;

    #[test]
    fn texels_placed_by_the_lattice_are_where_proj_puts_them() {
        // A level-7 tile (1.4°) in UTM zone 31 north, the largest tiles a
        // region's drape is sampled for, and a level-12 one.
        let to_earth = ToEllipsoid::new(
            &crate::ingest::crs::parse("EPSG:32631")
                .unwrap()
                .to_wkt()
                .unwrap(),
            VerticalDatum::Ellipsoid,
        )
        .unwrap();
        for bounds in [
            [4.21875, 44.296875, 5.625, 45.703125],
            [5.0, 45.0, 5.0439453125, 45.0439453125],
        ] {
            let lattice = to_earth.to_world(&terrain::lattice(bounds)).unwrap();
            let (width, height) = (256, 256);
            let placed = terrain::texel_world(width, height, &lattice);
            let [w, s, e, n] = bounds;
            let centres: Vec<[f64; 2]> = (0..width * height)
                .map(|i| {
                    [
                        w + ((i % width) as f64 + 0.5) / width as f64 * (e - w),
                        n - ((i / width) as f64 + 0.5) / height as f64 * (n - s),
                    ]
                })
                .collect();
            let exact = to_earth.to_world(&centres).unwrap();
            let worst = placed
                .iter()
                .zip(&exact)
                .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt())
                .fold(0.0, f64::max);
            // Within a tenth of a texel (over 600 m at level 7, 19 cm at 12).
            let texel_m = (n - s) * 111_320.0 / height as f64;
            assert!(worst < 0.1 * texel_m, "{worst} m off, texels {texel_m} m");
        }
    }
}
