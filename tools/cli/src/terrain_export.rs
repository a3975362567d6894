//! `relevo export quantized-mesh`: the bundle's vertices taken to the
//! ellipsoid through PROJ (the bundle's CRS to longitude and latitude, then
//! the geoid's heights to ellipsoidal ones), each level's LP mesh cut into
//! tiles by `relevo_core::terrain_tiles`, the tiles written into a staging
//! folder that replaces the output only when complete.

use crate::ingest::crs;
use crate::progress;
use anyhow::{bail, Context, Result};
use gdal::spatial_ref::{AxisMappingStrategy, CoordTransform, SpatialRef};
use relevo_core::bundle::{Bundle, PYRAMID_FORMAT};
use relevo_core::geo::TerrainFrame;
use relevo_core::grid::vertex_normal_of;
use relevo_core::lp::export::{MeshSource, Surface};
use relevo_core::lp::extract::{walk, GridMesh, MeshWalk};
use relevo_core::pyramid::mesh::PyramidMesh;
use relevo_core::pyramid::Pyramid;
use relevo_core::terrain_tiles::clip::SurfaceMesh;
use relevo_core::terrain_tiles::ellipsoid::east_north_up;
use relevo_core::terrain_tiles::quantized_mesh::{encode, TileExtras};
use relevo_core::terrain_tiles::tiling::{
    level_for_resolution, level_geometric_error_m, TileRange,
};
use relevo_core::terrain_tiles::{available_json, children_available, level_patches, water_mask};
use serde::Serialize;
use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

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

/// What an export wrote.
#[derive(Debug, Serialize)]
pub struct Summary {
    pub out: String,
    pub max_zoom: u32,
    pub tiles: usize,
    pub bytes: u64,
    /// Triangles of each level's mesh, level 0 first.
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

/// Export `a.bundle` as quantized-mesh tiles into `a.out`.
pub fn quantized_mesh(a: &Request) -> Result<Summary> {
    crate::output::check(&[a.out], a.force)?;
    if a.out.exists() && !a.out.join("layer.json").is_file() {
        bail!(
            "{}: exists and holds no layer.json; refusing to replace it, even with --force",
            a.out.display()
        );
    }
    let start = Instant::now();
    let name = a.bundle.display().to_string();
    if relevo_core::bundle::format_of(a.bundle).as_deref() == Some(PYRAMID_FORMAT) {
        let pyramid = Pyramid::open(a.bundle)?;
        let source = PyramidMesh::new(&pyramid)?;
        let m = &pyramid.manifest;
        return export(
            a,
            &source,
            &m.crs.wkt,
            &m.region,
            m.grid.valid_extent,
            start,
        );
    }
    let bundle = Bundle::open(a.bundle)?;
    let (heights, mask, lp) = (bundle.heights()?, bundle.mask()?, bundle.lp()?);
    let surface = Surface {
        frame: bundle.frame(),
        heights: &heights,
        mask: &mask,
        hierarchy: lp.hierarchy(),
        drape: None,
    };
    let m = &bundle.manifest;
    export(
        a,
        &surface,
        &m.crs.wkt,
        &m.region,
        m.grid.valid_extent,
        start,
    )
    .with_context(|| name.clone())
}

/// Bytes a vertex of the finest level holds while it is cut (its grid
/// place, position, height and normal, twice over as the tiles copy them).
const BYTES_PER_FINEST_VERTEX: u64 = 160;

fn export(
    a: &Request,
    source: &dyn MeshSource,
    crs_wkt: &str,
    region: &str,
    valid_extent: [f64; 4],
    start: Instant,
) -> Result<Summary> {
    if crs_wkt.trim().is_empty() {
        bail!("the bundle has no coordinate reference system, so its tiles cannot be placed on the Earth");
    }
    let frame = source.frame();
    let side = frame.side;
    relevo_core::memory::check(
        &format!("the {side}×{side} grid's finest mesh"),
        (side * side) as u64,
        BYTES_PER_FINEST_VERTEX,
        "pass a smaller --max-zoom",
    )?;
    let to_earth = ToEllipsoid::new(crs_wkt, a.vertical)?;
    let max_zoom = match a.max_zoom {
        Some(z) if z > 24 => bail!("--max-zoom {z}: at most 24"),
        Some(z) => z,
        None => level_for_resolution(to_earth.cell_deg(&frame)?),
    };
    // The finest mesh keeps every vertex that matters (tolerance 0): its
    // vertices hold every coarser level's.
    let tolerance = |z: u32| {
        if z == max_zoom {
            0.0
        } else {
            level_geometric_error_m(z) as f32
        }
    };
    let meshes: Vec<GridMesh> = (0..=max_zoom)
        .map(|z| {
            walk(&MeshWalk {
                side,
                max_error: tolerance(z),
                error: &|i| source.error(i),
                has_data: Some(&|i| source.has_data(i)),
                window: None,
                max_vertices: usize::MAX,
            })
            .unwrap_or_default()
        })
        .collect();
    let finest = meshes.last().context("no level")?;
    if finest.triangles.is_empty() {
        bail!("the bundle holds no triangle with data");
    }
    let (earth, heights_note) = to_earth.vertices(source, &frame, &finest.vertices)?;
    let place: HashMap<[u16; 2], u32> = finest
        .vertices
        .iter()
        .enumerate()
        .map(|(i, &v)| (v, i as u32))
        .collect();
    let bounds = earth.bounds_deg();
    let tiles = TileSet {
        ranges: (0..=max_zoom)
            .map(|z| TileRange::covering(z, bounds))
            .collect(),
        // One quantization of heights for every tile: shared vertices
        // decode alike.
        height_range_m: [
            earth.height_m.iter().copied().fold(0.0, f64::min),
            earth.height_m.iter().copied().fold(0.0, f64::max),
        ],
        outline: to_earth.outline(valid_extent)?,
    };
    let layer = serde_json::json!({
        "tilejson": "2.1.0",
        "name": region,
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
    let levels = meshes.iter().map(|m| level_mesh(m, &place, &earth));
    let (count, bytes) = write_folder(a.out, |staging| tiles.write(staging, levels, &layer))?;
    Ok(Summary {
        out: a.out.display().to_string(),
        max_zoom,
        tiles: count,
        bytes,
        level_triangles: meshes.iter().map(|m| m.triangles.len()).collect(),
        heights: heights_note,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// A level's mesh on the ellipsoid: `mesh`'s vertices looked up (by grid
/// place, `place`) in the finest level's, `earth`; triangles turned
/// counter-clockwise in longitude and latitude.
fn level_mesh(mesh: &GridMesh, place: &HashMap<[u16; 2], u32>, earth: &SurfaceMesh) -> SurfaceMesh {
    let ids: Vec<usize> = mesh.vertices.iter().map(|v| place[v] as usize).collect();
    let mut out = SurfaceMesh {
        lon_lat_deg: ids.iter().map(|&i| earth.lon_lat_deg[i]).collect(),
        height_m: ids.iter().map(|&i| earth.height_m[i]).collect(),
        normal: ids.iter().map(|&i| earth.normal[i]).collect(),
        triangles: Vec::with_capacity(mesh.triangles.len()),
    };
    for &t in &mesh.triangles {
        let [p, q, r] = t.map(|v| out.lon_lat_deg[v as usize]);
        let area = (q[0] - p[0]) * (r[1] - p[1]) - (r[0] - p[0]) * (q[1] - p[1]);
        out.triangles
            .push(if area < 0.0 { [t[0], t[2], t[1]] } else { t });
    }
    out
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
    /// Write each level's tiles (from `levels`, level 0 first) and
    /// `layer.json` into `folder`: the tiles and bytes written.
    fn write(
        &self,
        folder: &Path,
        levels: impl Iterator<Item = SurfaceMesh>,
        layer: &serde_json::Value,
    ) -> Result<(usize, u64)> {
        let total: usize = self.ranges.iter().map(TileRange::len).sum();
        let bar = progress::bar(total as u64, "tiles");
        let (mut tiles, mut bytes) = (0, 0u64);
        for (z, surface) in levels.enumerate() {
            for patch in level_patches(&surface, self.ranges[z]) {
                let children = children_available(patch.tile, self.ranges.get(z + 1));
                let extras = TileExtras {
                    height_range_m: self.height_range_m,
                    water: water_mask(&patch, &self.outline),
                    children_available: &children,
                };
                let data = encode(patch.tile, &patch.mesh, &extras);
                let dir = folder.join(format!("{z}/{}", patch.tile.x));
                std::fs::create_dir_all(&dir)
                    .with_context(|| format!("{}: cannot write", dir.display()))?;
                let path = dir.join(format!("{}.terrain", patch.tile.y));
                std::fs::write(&path, &data)
                    .with_context(|| format!("{}: cannot write", path.display()))?;
                tiles += 1;
                bytes += data.len() as u64;
                bar.inc(1);
            }
        }
        bar.finish_and_clear();
        let text = serde_json::to_string_pretty(layer)?;
        std::fs::write(folder.join("layer.json"), &text)?;
        Ok((tiles, bytes + text.len() as u64))
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
    vertical: Option<(CoordTransform, VerticalDatum)>,
}

impl ToEllipsoid {
    fn new(crs_wkt: &str, datum: VerticalDatum) -> Result<ToEllipsoid> {
        let from = crs::parse(crs_wkt)?;
        let horizontal = CoordTransform::new(&from, &crs::wgs84()?)?;
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
            vertical,
        })
    }

    /// Degrees a cell spans at the grid's centre (the smaller of longitude
    /// and latitude).
    fn cell_deg(&self, frame: &TerrainFrame) -> Result<f64> {
        let c = (frame.side / 2) as f64;
        let (x0, y0) = frame.world_from_vertex(c, c);
        let (x1, y1) = frame.world_from_vertex(c + 1.0, c + 1.0);
        let (mut xs, mut ys, mut zs) = (vec![x0, x1], vec![y0, y1], vec![0.0; 2]);
        self.horizontal
            .transform_coords(&mut xs, &mut ys, &mut zs)?;
        Ok((xs[1] - xs[0]).abs().min((ys[1] - ys[0]).abs()))
    }

    /// The corners of `extent` (`[x0, y0, x1, y1]` in the bundle's CRS) in
    /// degrees, in order.
    fn outline(&self, [x0, y0, x1, y1]: [f64; 4]) -> Result<Vec<[f64; 2]>> {
        let (mut xs, mut ys, mut zs) = (vec![x0, x1, x1, x0], vec![y0, y0, y1, y1], vec![0.0; 4]);
        self.horizontal
            .transform_coords(&mut xs, &mut ys, &mut zs)?;
        Ok(xs.iter().zip(&ys).map(|(&x, &y)| [x, y]).collect())
    }

    /// `vertices` (grid places) on the ellipsoid, with normals, and what
    /// the heights are measured from.
    fn vertices(
        &self,
        source: &dyn MeshSource,
        frame: &TerrainFrame,
        vertices: &[[u16; 2]],
    ) -> Result<(SurfaceMesh, String)> {
        let n = vertices.len();
        let (mut xs, mut ys) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let mut zs: Vec<f64> = Vec::with_capacity(n);
        for &[c, r] in vertices {
            let (x, y) = frame.world_from_vertex(c as f64, r as f64);
            xs.push(x);
            ys.push(y);
            zs.push(source.height(c as usize, r as usize) as f64);
        }
        let mut flat = vec![0.0; n];
        self.horizontal
            .transform_coords(&mut xs, &mut ys, &mut flat)?;
        let note = match &self.vertical {
            None => "heights above the WGS84 ellipsoid, as the bundle holds them".to_string(),
            Some((t, datum)) => {
                let before = zs.clone();
                let (mut lon, mut lat) = (xs.clone(), ys.clone());
                t.transform_coords(&mut lon, &mut lat, &mut zs)?;
                let name = format!("{datum:?}").to_uppercase();
                if zs == before {
                    tracing::warn!(
                        "PROJ has no grid for the {name} geoid (Debian: proj-data; or projsync); the heights are written as the bundle holds them, above the geoid, not the ellipsoid"
                    );
                    format!(
                        "heights above the {name} geoid (PROJ lacked its grid), not the ellipsoid"
                    )
                } else {
                    format!(
                        "heights above the WGS84 ellipsoid, from {name} geoid heights through PROJ"
                    )
                }
            }
        };
        let cell = frame.cell_size_m;
        let normal = vertices
            .iter()
            .zip(xs.iter().zip(&ys))
            .map(|(&[c, r], (&lon, &lat))| {
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
        Ok((
            SurfaceMesh {
                lon_lat_deg: xs.iter().zip(&ys).map(|(&x, &y)| [x, y]).collect(),
                height_m: zs,
                normal,
                triangles: Vec::new(),
            },
            note,
        ))
    }
}
