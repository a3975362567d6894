//! `relevo export quantized-mesh` and `relevo export 3dtiles`, tile by
//! tile: the window of the tile's level's LP mesh that meets it, its
//! vertices taken to the ellipsoid through PROJ (the bundle's CRS to
//! longitude and latitude, the geoid's heights to ellipsoidal ones), cut by
//! `relevo_core::terrain_tiles`; the tiles written into a staging folder
//! that replaces the output only when complete.
//!
//! - [`quantized_mesh`]: Cesium's terrain format.
//! - [`tiles3d`]: 3D Tiles 1.1 with the drape and the vegetation.

pub mod quantized_mesh;
pub mod tiles3d;

use crate::ingest::crs;
use crate::progress;
use anyhow::{bail, Context, Result};
use gdal::spatial_ref::{AxisMappingStrategy, CoordTransform, SpatialRef};
use rayon::prelude::*;
use relevo_core::bundle::{Bundle, Crs, GridInfo, PYRAMID_FORMAT};
use relevo_core::geo::TerrainFrame;
use relevo_core::grid::vertex_normal_of;
use relevo_core::lp::export::{DrapeImage, MeshSource, Surface};
use relevo_core::lp::extract::{walk, GridMesh, MeshWalk, VertexBits};
use relevo_core::lp::window::Rect;
use relevo_core::pyramid::mesh::PyramidMesh;
use relevo_core::pyramid::Pyramid;
use relevo_core::terrain_tiles::bounds_of;
use relevo_core::terrain_tiles::clip::SurfaceMesh;
use relevo_core::terrain_tiles::ellipsoid::east_north_up;
use relevo_core::terrain_tiles::tiling::{
    level_for_resolution, level_geometric_error_m, TileId, TileRange,
};
use std::borrow::Cow;
use std::path::Path;

/// The surface the bundle's heights are measured from.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum VerticalDatum {
    /// EGM96 geoid heights (EPSG:5773).
    Egm96,
    /// EGM2008 geoid heights (EPSG:3855).
    Egm2008,
    /// Already above the WGS84 ellipsoid.
    Ellipsoid,
}

impl VerticalDatum {
    fn epsg(self) -> Option<u32> {
        match self {
            VerticalDatum::Egm96 => Some(5773),
            VerticalDatum::Egm2008 => Some(3855),
            VerticalDatum::Ellipsoid => None,
        }
    }
}

/// What to export, and how.
pub struct Request<'a> {
    /// The bundle (single grid or pyramid).
    pub bundle: &'a Path,
    /// The folder to write.
    pub out: &'a Path,
    /// The finest level; `None`: the level matching the grid's cells.
    pub max_zoom: Option<u32>,
    /// What the bundle's heights are measured from.
    pub vertical: VerticalDatum,
    /// Replace an earlier export.
    pub force: bool,
}

/// What an export reads of a bundle's or a pyramid's manifest.
struct ManifestParts {
    crs_wkt: String,
    region: String,
    /// The DEM's extent in the bundle's CRS, `[x0, y0, x1, y1]`.
    valid_extent: [f64; 4],
    /// Lowest and highest height, metres (above the geoid, or as held).
    height_range_m: [f64; 2],
}

impl ManifestParts {
    /// The parts of a manifest's CRS, region name and grid (a single
    /// grid's or a pyramid's level 0).
    fn of(crs: &Crs, region: &str, grid: &GridInfo) -> ManifestParts {
        ManifestParts {
            crs_wkt: crs.wkt.clone(),
            region: region.to_string(),
            valid_extent: grid.valid_extent,
            height_range_m: grid.height_range_m.map(f64::from),
        }
    }
}

/// Run `export` on the bundle at `path` — a single grid, with its drape
/// (and the bundle itself, for what only single grids hold), or a pyramid
/// read tile by tile — its errors named with the path.
fn with_source<T>(
    path: &Path,
    export: impl FnOnce(&dyn MeshSource, &ManifestParts, Option<&Bundle>) -> Result<T>,
) -> Result<T> {
    let name = path.display().to_string();
    if relevo_core::bundle::format_of(path).as_deref() == Some(PYRAMID_FORMAT) {
        let pyramid = Pyramid::open(path)?;
        let source = PyramidMesh::new(&pyramid)?;
        let m = &pyramid.manifest;
        let parts = ManifestParts::of(&m.crs, &m.region, &m.grid);
        return export(&source, &parts, None).with_context(|| name.clone());
    }
    let bundle = Bundle::open(path)?;
    let (heights, mask, lp) = (bundle.heights()?, bundle.mask()?, bundle.lp()?);
    let drape = bundle.drape()?;
    let surface = Surface {
        frame: bundle.frame(),
        heights: &heights,
        mask: &mask,
        hierarchy: lp.hierarchy(),
        drape: drape.as_ref().map(|d| DrapeImage {
            rgba: Cow::Borrowed(&d.rgba),
            width: d.info.width,
            height: d.info.height,
            geotransform: d.info.geotransform,
        }),
    };
    let m = &bundle.manifest;
    let parts = ManifestParts::of(&m.crs, &m.region, &m.grid);
    export(&surface, &parts, Some(&bundle)).with_context(|| name.clone())
}

/// Where a region lies on the Earth, as both exports need it.
struct Placement {
    to_earth: ToEllipsoid,
    /// The finest level written.
    max_zoom: u32,
    /// The grid's square, and its data's extent, degrees.
    grid_box: [f64; 4],
    outline: Vec<[f64; 2]>,
    /// `[west, south, east, north]` of the outline.
    bounds: [f64; 4],
    /// The geoid's lowest and highest height above the ellipsoid over the
    /// region, metres, and what the heights written are measured from.
    geoid_m: [f64; 2],
    heights_note: String,
}

impl Placement {
    fn of(a: &Request, frame: &TerrainFrame, manifest: &ManifestParts) -> Result<Placement> {
        if manifest.crs_wkt.trim().is_empty() {
            bail!("the bundle has no coordinate reference system, so its tiles cannot be placed on the Earth");
        }
        let to_earth = ToEllipsoid::new(&manifest.crs_wkt, a.vertical)?;
        let max_zoom = match a.max_zoom {
            Some(z) if z > 24 => bail!("--max-zoom {z}: at most 24"),
            Some(z) => z,
            None => level_for_resolution(to_earth.cell_deg(frame)?),
        };
        let last = (frame.side - 1) as f64;
        let grid_box = bounds_of(&to_earth.outline(frame, [[0.0, 0.0], [last, last]])?);
        let outline = to_earth.outline_of_extent(manifest.valid_extent)?;
        let bounds = bounds_of(&outline);
        let (geoid_m, heights_note) = to_earth.geoid_range(bounds)?;
        Ok(Placement {
            to_earth,
            max_zoom,
            grid_box,
            outline,
            bounds,
            geoid_m,
            heights_note,
        })
    }

    /// The grid tiles are walked from.
    fn grid<'a>(
        &self,
        a: &Request,
        source: &'a dyn MeshSource,
        manifest: &'a ManifestParts,
        boundaries: &'a VertexBits,
    ) -> Grid<'a> {
        Grid {
            source,
            frame: source.frame(),
            boundaries,
            grid_box: self.grid_box,
            crs_wkt: &manifest.crs_wkt,
            vertical: a.vertical,
            max_zoom: self.max_zoom,
        }
    }
}

/// Refuse to replace `out` unless it is an earlier export (holding
/// `marker`) and `--force` is given.
fn check_out(a: &Request, marker: &str) -> Result<()> {
    crate::output::check(&[a.out], a.force)?;
    if a.out.exists() && !a.out.join(marker).is_file() {
        bail!(
            "{}: exists and holds no {marker}; refusing to replace it, even with --force",
            a.out.display()
        );
    }
    Ok(())
}

/// Tiles made before they are written.
const TILES_A_BATCH: usize = 256;

/// Make every tile of `ranges` with `make` — in parallel, a batch at a
/// time so that a level of any size holds only that many made tiles, each
/// worker with its own PROJ transforms — and hand each to `take`, level by
/// level, in the ranges' order.
fn for_each_tile<T: Send>(
    ranges: &[TileRange],
    grid: &Grid,
    make: impl Fn(&ToEllipsoid, TileId) -> Result<T> + Sync,
    mut take: impl FnMut(TileId, T) -> Result<()>,
) -> Result<()> {
    let total: usize = ranges.iter().map(TileRange::tile_count).sum();
    let bar = progress::bar(total as u64, "tiles");
    for range in ranges {
        let ids: Vec<TileId> = range.tiles().collect();
        for batch in ids.chunks(TILES_A_BATCH) {
            let made: Vec<Result<T>> = batch
                .par_iter()
                .map(|&tile| {
                    let result = with_transforms(grid.crs_wkt, grid.vertical, |to_earth| {
                        make(to_earth, tile)
                    });
                    bar.inc(1);
                    result
                })
                .collect();
            for (&tile, result) in batch.iter().zip(made) {
                take(tile, result?)?;
            }
        }
    }
    bar.finish_and_clear();
    Ok(())
}

/// Write `bytes` to `folder/relative`, making its folders.
fn write_file(folder: &Path, relative: &str, bytes: &[u8]) -> Result<()> {
    let path = folder.join(relative);
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot write", dir.display()))?;
    }
    std::fs::write(&path, bytes).with_context(|| format!("{}: cannot write", path.display()))
}

/// The grid a tile's mesh is walked from.
struct Grid<'a> {
    source: &'a dyn MeshSource,
    frame: TerrainFrame,
    boundaries: &'a VertexBits,
    /// The grid's square on the Earth, degrees.
    grid_box: [f64; 4],
    crs_wkt: &'a str,
    vertical: VerticalDatum,
    max_zoom: u32,
}

impl Grid<'_> {
    /// Tile `tile`'s mesh, on the ellipsoid: the triangles of its level's
    /// LP mesh (at the level's geometric error; every vertex on the last
    /// level) that meet the tile, read by a window walk — exactly the
    /// whole level's triangles there, so neighbours cut the same mesh.
    fn tile_mesh(&self, to_earth: &ToEllipsoid, tile: TileId) -> Result<SurfaceMesh> {
        let Some(window) = self.window(to_earth, tile)? else {
            return Ok(SurfaceMesh::default());
        };
        let mesh = walk(&MeshWalk {
            side: self.frame.side,
            max_error: self.max_error(tile),
            error: &|i| self.source.error(i),
            has_data: Some(&|i| self.source.has_data(i)),
            boundaries: Some(self.boundaries),
            window: Some(window),
            max_vertices: usize::MAX,
        })
        .unwrap_or_default();
        to_earth.surface(self.source, &self.frame, &mesh)
    }

    /// The vertices a walk for `tile` reads; `None` off the grid.
    fn window(&self, to_earth: &ToEllipsoid, tile: TileId) -> Result<Option<Rect>> {
        to_earth.window(tile.bounds_deg(), self.grid_box, &self.frame)
    }

    /// The LP tolerance of `tile`'s level, metres: the level's geometric
    /// error, 0 (every vertex) on the last level.
    fn max_error(&self, tile: TileId) -> f32 {
        if tile.z == self.max_zoom {
            0.0
        } else {
            level_geometric_error_m(tile.z) as f32
        }
    }
}

/// Fill a staging folder beside `out` with `write`, then move it onto
/// `out` (replacing an earlier export); on any failure the staging folder
/// is removed and `out` is left as it was.
fn write_folder<T>(out: &Path, write: impl FnOnce(&Path) -> Result<T>) -> Result<T> {
    let staging = relevo_core::atomic::partial_path(out);
    let _ = std::fs::remove_dir_all(&staging);
    std::fs::create_dir_all(&staging)
        .with_context(|| format!("{}: cannot write", staging.display()))?;
    let result = write(&staging).and_then(|value| {
        if out.exists() {
            std::fs::remove_dir_all(out)
                .with_context(|| format!("{}: cannot replace", out.display()))?;
        }
        std::fs::rename(&staging, out)
            .with_context(|| format!("{}: cannot move into place", out.display()))?;
        Ok(value)
    });
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&staging);
    }
    result
}

/// The bundle's CRS to the ellipsoid: longitude and latitude on WGS84 (PROJ),
/// and the geoid's heights to ellipsoidal ones (PROJ, with the geoid's grid).
struct ToEllipsoid {
    horizontal: CoordTransform,
    /// WGS84 back to the bundle's CRS.
    inverse: CoordTransform,
    vertical: Option<(CoordTransform, VerticalDatum)>,
}

thread_local! {
    /// Each worker thread's transforms, made once (PROJ looks the CRSs up
    /// in its database): the CRS and datum they are for, and them.
    static TRANSFORMS: std::cell::RefCell<Option<(String, VerticalDatum, ToEllipsoid)>> =
        const { std::cell::RefCell::new(None) };
}

/// Run `f` with this thread's transforms from `crs_wkt` and `datum`. They
/// are taken out of the thread's slot while `f` runs: a tile's own
/// parallel work may run another tile on this thread meanwhile, which then
/// makes its own.
fn with_transforms<T>(
    crs_wkt: &str,
    datum: VerticalDatum,
    f: impl FnOnce(&ToEllipsoid) -> Result<T>,
) -> Result<T> {
    let kept = TRANSFORMS.with(|cell| cell.borrow_mut().take());
    let to_earth = match kept {
        Some((wkt, d, t)) if wkt == crs_wkt && d == datum => t,
        _ => ToEllipsoid::new(crs_wkt, datum)?,
    };
    let result = f(&to_earth);
    TRANSFORMS.with(|cell| *cell.borrow_mut() = Some((crs_wkt.to_string(), datum, to_earth)));
    result
}

/// Points a side of a tile or an extent is sampled at when it goes from one
/// CRS to the other (its sides curve there).
const SIDE_SAMPLES: usize = 9;

impl ToEllipsoid {
    fn new(crs_wkt: &str, datum: VerticalDatum) -> Result<ToEllipsoid> {
        let from = crs::parse(crs_wkt)?;
        let wgs84 = crs::wgs84()?;
        let horizontal = CoordTransform::new(&from, &wgs84)?;
        let inverse = CoordTransform::new(&wgs84, &from)?;
        let vertical = match datum.epsg() {
            None => None,
            Some(code) => {
                let mut geoid = SpatialRef::from_definition(&format!("EPSG:4326+{code}"))?;
                geoid.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
                let mut ellipsoid = SpatialRef::from_epsg(4979)?;
                ellipsoid.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
                Some((CoordTransform::new(&geoid, &ellipsoid)?, datum))
            }
        };
        Ok(ToEllipsoid {
            horizontal,
            inverse,
            vertical,
        })
    }

    /// Degrees a cell spans at the grid's centre (the smaller of longitude
    /// and latitude).
    fn cell_deg(&self, frame: &TerrainFrame) -> Result<f64> {
        let c = (frame.side / 2) as f64;
        let p = self.to_degrees(&[
            frame.world_from_vertex(c, c),
            frame.world_from_vertex(c + 1.0, c + 1.0),
        ])?;
        Ok((p[1][0] - p[0][0]).abs().min((p[1][1] - p[0][1]).abs()))
    }

    /// The rectangle of vertices `[[c0, r0], [c1, r1]]` of `frame` on the
    /// Earth: its sides sampled, degrees.
    fn outline(
        &self,
        frame: &TerrainFrame,
        [[c0, r0], [c1, r1]]: [[f64; 2]; 2],
    ) -> Result<Vec<[f64; 2]>> {
        let world: Vec<(f64, f64)> = rectangle_sides([c0, r0, c1, r1])
            .into_iter()
            .map(|[c, r]| frame.world_from_vertex(c, r))
            .collect();
        self.to_degrees(&world)
    }

    /// `extent` (`[x0, y0, x1, y1]` in the bundle's CRS) on the Earth: its
    /// sides sampled, degrees, in order.
    fn outline_of_extent(&self, extent: [f64; 4]) -> Result<Vec<[f64; 2]>> {
        let world: Vec<(f64, f64)> = rectangle_sides(extent)
            .into_iter()
            .map(|[x, y]| (x, y))
            .collect();
        self.to_degrees(&world)
    }

    fn to_degrees(&self, world: &[(f64, f64)]) -> Result<Vec<[f64; 2]>> {
        let mut xs: Vec<f64> = world.iter().map(|p| p.0).collect();
        let mut ys: Vec<f64> = world.iter().map(|p| p.1).collect();
        let mut zs = vec![0.0; xs.len()];
        self.horizontal
            .transform_coords(&mut xs, &mut ys, &mut zs)?;
        Ok(xs.iter().zip(&ys).map(|(&x, &y)| [x, y]).collect())
    }

    /// The geoid's height above the ellipsoid over `bounds` (lowest and
    /// highest on a 9 × 9 lattice), and what the heights written are
    /// measured from; a warning when PROJ lacks the geoid's grid.
    fn geoid_range(&self, [w, s, e, n]: [f64; 4]) -> Result<([f64; 2], String)> {
        let Some((t, datum)) = &self.vertical else {
            return Ok((
                [0.0; 2],
                "heights above the WGS84 ellipsoid, as the bundle holds them".into(),
            ));
        };
        let at = |lo: f64, hi: f64, i: usize| lo + (hi - lo) * i as f64 / 8.0;
        let (mut xs, mut ys): (Vec<f64>, Vec<f64>) =
            (0..81).map(|k| (at(w, e, k % 9), at(s, n, k / 9))).unzip();
        let mut zs = vec![0.0; xs.len()];
        t.transform_coords(&mut xs, &mut ys, &mut zs)?;
        let name = format!("{datum:?}").to_uppercase();
        if zs.iter().all(|&z| z == 0.0) {
            tracing::warn!(
                "PROJ has no grid for the {name} geoid (Debian: proj-data; or projsync); the heights are written as the bundle holds them, above the geoid, not the ellipsoid"
            );
            return Ok((
                [0.0; 2],
                format!("heights above the {name} geoid (PROJ lacked its grid), not the ellipsoid"),
            ));
        }
        let lo = zs.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = zs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Ok((
            [lo, hi],
            format!("heights above the WGS84 ellipsoid, from {name} geoid heights through PROJ"),
        ))
    }

    /// The vertices of `frame` a walk for tile `tile` (degrees) needs: the
    /// part of the tile over the grid's box, taken to the bundle's CRS,
    /// with a margin of two vertices; `None` when the tile misses the grid.
    fn window(
        &self,
        tile: [f64; 4],
        grid_box: [f64; 4],
        frame: &TerrainFrame,
    ) -> Result<Option<Rect>> {
        let part = [
            tile[0].max(grid_box[0]),
            tile[1].max(grid_box[1]),
            tile[2].min(grid_box[2]),
            tile[3].min(grid_box[3]),
        ];
        if part[0] >= part[2] || part[1] >= part[3] {
            return Ok(None);
        }
        let corners = rectangle_sides(part);
        let (mut xs, mut ys): (Vec<f64>, Vec<f64>) = corners.iter().map(|p| (p[0], p[1])).unzip();
        let mut zs = vec![0.0; xs.len()];
        self.inverse.transform_coords(&mut xs, &mut ys, &mut zs)?;
        let mut box_ = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for (&x, &y) in xs.iter().zip(&ys) {
            let Some((c, r)) = frame.vertex_from_world(x, y) else {
                continue;
            };
            box_ = [
                box_[0].min(c),
                box_[1].min(r),
                box_[2].max(c),
                box_[3].max(r),
            ];
        }
        let last = (frame.side - 1) as f64;
        let [c0, r0] = [box_[0], box_[1]].map(|v| (v.floor() - 2.0).clamp(0.0, last) as usize);
        let [c1, r1] = [box_[2], box_[3]].map(|v| (v.ceil() + 2.0).clamp(0.0, last) as usize);
        if !(c0 < c1 && r0 < r1) {
            return Ok(None);
        }
        Ok(Some(Rect {
            c0,
            r0,
            width: c1 - c0 + 1,
            height: r1 - r0 + 1,
        }))
    }

    /// Points of the bundle's CRS with heights as the bundle holds them on
    /// the ellipsoid: longitude, latitude (degrees), height above it
    /// (metres).
    fn to_ellipsoid(&self, world: &[[f64; 3]]) -> Result<Vec<[f64; 3]>> {
        let mut xs: Vec<f64> = world.iter().map(|p| p[0]).collect();
        let mut ys: Vec<f64> = world.iter().map(|p| p[1]).collect();
        let mut zs: Vec<f64> = world.iter().map(|p| p[2]).collect();
        let mut flat = vec![0.0; world.len()];
        self.horizontal
            .transform_coords(&mut xs, &mut ys, &mut flat)?;
        if let Some((t, _)) = &self.vertical {
            let (mut lon, mut lat) = (xs.clone(), ys.clone());
            t.transform_coords(&mut lon, &mut lat, &mut zs)?;
        }
        Ok((0..world.len()).map(|i| [xs[i], ys[i], zs[i]]).collect())
    }

    /// Longitudes and latitudes (degrees) in the bundle's CRS.
    fn to_world(&self, lon_lat_deg: &[[f64; 2]]) -> Result<Vec<[f64; 2]>> {
        let (mut xs, mut ys): (Vec<f64>, Vec<f64>) =
            lon_lat_deg.iter().map(|p| (p[0], p[1])).unzip();
        let mut zs = vec![0.0; xs.len()];
        self.inverse.transform_coords(&mut xs, &mut ys, &mut zs)?;
        Ok(xs.into_iter().zip(ys).map(|(x, y)| [x, y]).collect())
    }

    /// `mesh` on the ellipsoid: its vertices through PROJ, normals from the
    /// grid in each vertex's east/north/up frame, triangles turned
    /// counter-clockwise in longitude and latitude.
    fn surface(
        &self,
        source: &dyn MeshSource,
        frame: &TerrainFrame,
        mesh: &GridMesh,
    ) -> Result<SurfaceMesh> {
        let world: Vec<[f64; 3]> = mesh
            .vertices
            .iter()
            .map(|&[c, r]| {
                let (x, y) = frame.world_from_vertex(c as f64, r as f64);
                [x, y, source.height(c as usize, r as usize) as f64]
            })
            .collect();
        let on_earth = self.to_ellipsoid(&world)?;
        let cell = frame.cell_size_m;
        let normal = mesh
            .vertices
            .iter()
            .zip(&on_earth)
            .map(|(&[c, r], &[lon, lat, _])| {
                let local = vertex_normal_of(
                    &|c, r| source.height(c, r),
                    frame.side,
                    cell,
                    c as usize,
                    r as usize,
                );
                let [e, n, u] = east_north_up(lon, lat);
                [0, 1, 2].map(|k| local[0] * e[k] + local[1] * n[k] + local[2] * u[k])
            })
            .collect();
        let mut out = SurfaceMesh {
            lon_lat_deg: on_earth.iter().map(|p| [p[0], p[1]]).collect(),
            height_m: on_earth.iter().map(|p| p[2]).collect(),
            normal,
            triangles: Vec::with_capacity(mesh.triangles.len()),
        };
        for &t in &mesh.triangles {
            let [p, q, r] = t.map(|v| out.lon_lat_deg[v as usize]);
            let area = (q[0] - p[0]) * (r[1] - p[1]) - (r[0] - p[0]) * (q[1] - p[1]);
            out.triangles
                .push(if area < 0.0 { [t[0], t[2], t[1]] } else { t });
        }
        Ok(out)
    }
}

/// Points along the sides of rectangle `[x0, y0, x1, y1]`, in order round
/// it, [`SIDE_SAMPLES`] a side.
fn rectangle_sides([x0, y0, x1, y1]: [f64; 4]) -> Vec<[f64; 2]> {
    let at = |a: f64, b: f64, i: usize| a + (b - a) * i as f64 / (SIDE_SAMPLES - 1) as f64;
    let mut points = Vec::with_capacity(4 * (SIDE_SAMPLES - 1));
    for i in 0..SIDE_SAMPLES - 1 {
        points.push([at(x0, x1, i), y0]);
    }
    for i in 0..SIDE_SAMPLES - 1 {
        points.push([x1, at(y0, y1, i)]);
    }
    for i in 0..SIDE_SAMPLES - 1 {
        points.push([at(x1, x0, i), y1]);
    }
    for i in 0..SIDE_SAMPLES - 1 {
        points.push([x0, at(y1, y0, i)]);
    }
    points
}
