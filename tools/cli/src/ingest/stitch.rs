//! Stitching georeferenced tiles into one grid.
//!
//! Every tile is warped by GDAL onto its window of a common north-up target
//! grid, then relevo-core's mosaic combines the windows (first, last, or a
//! distance-weighted feather across overlaps).

use super::crs;
use super::gdalio::{self, GridSpec, Resampling, Source};
use crate::progress;
use anyhow::{bail, Context, Result};
use gdal::raster::GdalDataType;
use gdal::spatial_ref::SpatialRef;
use relevo_core::geo::GeoTransform;
use relevo_core::raster::encoding::Encoding;
use relevo_core::raster::mosaic::{mosaic, Overlap, PlacedTile};
use relevo_core::raster::Raster;
use std::path::{Path, PathBuf};

/// How to build the target grid and combine tiles (gdalwarp's options in spirit).
#[derive(Debug, Clone, Default)]
pub struct StitchOptions {
    /// Target CRS; default: the first tile's.
    pub target_crs: Option<String>,
    /// Cell size (x, y) in target CRS units; default: the finest tile's,
    /// or its detail-preserving size after reprojection.
    pub resolution: Option<(f64, f64)>,
    /// `[xmin, ymin, xmax, ymax]` in target CRS units; default: all tiles.
    pub extent: Option<[f64; 4]>,
    pub resampling: Resampling,
    /// Source no-data value, overriding what the files declare.
    pub src_nodata: Option<f64>,
    /// No-data value written to the output; default: the sources'.
    pub dst_nodata: Option<f64>,
    pub overlap: Overlap,
    pub encoding: Encoding,
    /// Bands to keep, 1-based, in output order; default: all.
    pub bands: Option<Vec<usize>>,
}

/// A stitched raster and the grid it lies on.
pub struct Mosaic {
    pub raster: Raster,
    pub grid: GridSpec,
    /// Band type to write: the sources' common type (Float32 for decoded tiles).
    pub band_type: GdalDataType,
    pub nodata: f64,
    pub srs: Option<SpatialRef>,
}

/// Tiles warped onto their windows of the target grid, not yet combined.
pub struct Placement {
    pub tiles: Vec<PlacedTile>,
    pub grid: GridSpec,
    /// Band type to write: the sources' common type (Float32 for decoded tiles).
    pub band_type: GdalDataType,
    pub nodata: f64,
    pub srs: Option<SpatialRef>,
}

/// Open, check, warp and combine `paths`.
pub fn stitch(paths: &[PathBuf], opts: &StitchOptions) -> Result<Mosaic> {
    let mut p = place(paths, opts)?;
    let bands = p.tiles.first().map_or(1, |t| t.raster.bands);
    let whole_grid = |t: &PlacedTile| {
        t.col == 0
            && t.row == 0
            && t.raster.width == p.grid.width
            && t.raster.height == p.grid.height
    };
    let raster = if p.tiles.len() == 1 && whole_grid(&p.tiles[0]) {
        // One tile covering the grid is its own mosaic.
        p.tiles.remove(0).raster
    } else {
        mosaic(p.grid.width, p.grid.height, bands, &p.tiles, opts.overlap)
    };
    if raster.valid_count() == 0 {
        let names: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
        bail!(
            "{}: no valid data (every cell is no-data)",
            names.join(", ")
        );
    }
    Ok(Mosaic {
        raster,
        grid: p.grid,
        band_type: p.band_type,
        nodata: p.nodata,
        srs: p.srs,
    })
}

/// Open and check `paths`, plan the target grid and warp every tile onto it.
pub fn place(paths: &[PathBuf], opts: &StitchOptions) -> Result<Placement> {
    if paths.is_empty() {
        bail!("no input tiles given");
    }
    let sources: Vec<Source> = paths
        .iter()
        .map(|p| gdalio::open(p))
        .collect::<Result<_>>()?;
    check_sources(&sources, opts)?;
    let first = &sources[0];

    let georeferenced = sources.iter().all(|s| s.geotransform.is_some());
    let (tiles, grid, srs) = if georeferenced {
        warp_all(&sources, opts)?
    } else {
        let lacking = sources
            .iter()
            .find(|s| s.geotransform.is_none())
            .map(|s| s.path.display());
        if sources.len() > 1
            || opts.target_crs.is_some()
            || opts.extent.is_some()
            || opts.resolution.is_some()
        {
            bail!(
                "{}: has no georeferencing (no geotransform and no world file); \
                 only a single such tile can be used, in pixel coordinates",
                lacking.unwrap_or_else(|| first.path.display())
            );
        }
        let raster = select_bands(decode(first, opts)?, opts);
        let grid = GridSpec {
            crs_wkt: String::new(),
            geotransform: GeoTransform::IDENTITY,
            width: first.width,
            height: first.height,
        };
        (
            vec![PlacedTile {
                col: 0,
                row: 0,
                raster,
            }],
            grid,
            None,
        )
    };

    let band_type = if opts.encoding != Encoding::Plain {
        GdalDataType::Float32
    } else if sources.iter().all(|s| s.band_type == first.band_type) {
        first.band_type
    } else {
        GdalDataType::Float64
    };
    let nodata = opts
        .dst_nodata
        .or(opts.src_nodata)
        .or(first.nodata)
        .unwrap_or_else(|| gdalio::default_nodata(band_type));
    Ok(Placement {
        tiles,
        grid,
        band_type,
        nodata,
        srs,
    })
}

/// Refuse inputs that cannot be combined, naming the file.
fn check_sources(sources: &[Source], opts: &StitchOptions) -> Result<()> {
    let first = &sources[0];
    for s in &sources[1..] {
        if s.bands != first.bands {
            bail!(
                "{}: has {} band(s) but {} has {}; tiles must have the same bands",
                s.path.display(),
                s.bands,
                first.path.display(),
                first.bands
            );
        }
        if s.srs.is_some() != first.srs.is_some() {
            bail!(
                "{}: {} a CRS but {} {}",
                s.path.display(),
                if s.srs.is_some() { "has" } else { "lacks" },
                first.path.display(),
                if first.srs.is_some() {
                    "has one"
                } else {
                    "does not"
                }
            );
        }
    }
    let needed = opts.encoding.bands_needed();
    if first.bands < needed {
        bail!(
            "{}: has {} band(s); the {:?} encoding needs {needed}",
            first.path.display(),
            first.bands,
            opts.encoding
        );
    }
    let available = if opts.encoding == Encoding::Plain {
        first.bands
    } else {
        1
    };
    if let Some(bands) = &opts.bands {
        if let Some(b) = bands.iter().find(|&&b| b == 0 || b > available) {
            bail!(
                "{}: has no band {b} (bands are 1..={available})",
                first.path.display()
            );
        }
    }
    Ok(())
}

/// The tile's values with its encoding decoded and no-data as NaN.
/// The tile's heights (or bands) as the options ask: decoded from an RGB
/// encoding, then the chosen bands.
fn decode(source: &Source, opts: &StitchOptions) -> Result<Raster> {
    let raw = source.read(opts.src_nodata.or(source.nodata))?;
    Ok(opts.encoding.decode_raster(raw))
}

fn select_bands(raster: Raster, opts: &StitchOptions) -> Raster {
    match &opts.bands {
        Some(bands) => raster.select_bands(bands),
        None => raster,
    }
}

/// Plan the target grid and warp every tile onto its window of it.
fn warp_all(
    sources: &[Source],
    opts: &StitchOptions,
) -> Result<(Vec<PlacedTile>, GridSpec, Option<SpatialRef>)> {
    let first = &sources[0];
    let target = match &opts.target_crs {
        Some(def) => Some(crs::parse(def)?),
        None => first.srs.clone(),
    };
    let same_crs = |s: &Source| match (&s.srs, &target) {
        (Some(a), Some(b)) => a == b,
        _ => true,
    };
    let (native, (rx, ry)) = resolution(sources, opts, target.as_ref(), &same_crs)?;
    let footprints: Vec<[f64; 4]> = sources
        .iter()
        .map(|s| {
            let geo = georeferenced(s)?;
            crs::footprint(&geo, s.width, s.height, s.srs.as_ref(), target.as_ref())
                .with_context(|| s.path.display().to_string())
        })
        .collect::<Result<_>>()?;
    let (origin_x, origin_y, width, height) =
        grid_extent(opts.extent, &footprints, native.as_ref(), (rx, ry))?;
    let crs_wkt = match &target {
        Some(t) => crs::to_wkt(t)?,
        None => String::new(),
    };
    let grid = GridSpec {
        crs_wkt,
        geotransform: GeoTransform::north_up(origin_x, origin_y, rx, ry),
        width,
        height,
    };
    tracing::info!(width, height, cell_x = rx, cell_y = ry, "target grid");
    // The mosaic, its tiles and their warped copies: about three f64 grids
    // per band.
    let bands = opts.bands.as_ref().map_or(first.bands, Vec::len) as u64;
    relevo_core::memory::check(
        &format!("the stitched grid of {width}×{height} cells"),
        (width as u64).saturating_mul(height as u64),
        24 * bands,
        "choose a coarser resolution or a smaller extent; a region of any size is \
         prepared by `prep --tiled` from one projected GeoTIFF (docs/guide.md, \"Large regions\")",
    )?;

    let bar = progress::bar(sources.len() as u64, "warping tiles");
    let mut tiles = Vec::new();
    for (s, f) in sources.iter().zip(&footprints) {
        bar.set_message(file_name(&s.path));
        let c0 = (((f[0] - origin_x) / rx + 1e-6).floor().max(0.0) as usize).min(width);
        let c1 = (((f[2] - origin_x) / rx - 1e-6).ceil().max(0.0) as usize).min(width);
        let r0 = (((origin_y - f[3]) / ry + 1e-6).floor().max(0.0) as usize).min(height);
        let r1 = (((origin_y - f[1]) / ry - 1e-6).ceil().max(0.0) as usize).min(height);
        if c1 <= c0 || r1 <= r0 {
            tracing::warn!("{}: outside the target extent, skipped", s.path.display());
            bar.inc(1);
            continue;
        }
        let window = GridSpec {
            crs_wkt: grid.crs_wkt.clone(),
            geotransform: GeoTransform::north_up(
                origin_x + c0 as f64 * rx,
                origin_y - r0 as f64 * ry,
                rx,
                ry,
            ),
            width: c1 - c0,
            height: r1 - r0,
        };
        let raster = warp_tile(s, &window, same_crs(s), opts)?;
        tiles.push(PlacedTile {
            col: c0,
            row: r0,
            raster: select_bands(raster, opts),
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    if tiles.is_empty() {
        bail!("no input tile reaches the target extent");
    }
    Ok((tiles, grid, target))
}

/// The target grid's cell size, and the native grid it follows when one
/// tile is already in the target CRS. The native grid: the finest tile
/// already in the target CRS sets the cell size and the cell lines; tiles
/// in other CRSs are resampled onto it. Only when no tile is native does
/// the finest detail-preserving cell of the reprojected tiles set the size
/// (lines at its multiples). `--tr` overrides the size.
fn resolution(
    sources: &[Source],
    opts: &StitchOptions,
    target: Option<&SpatialRef>,
    same_crs: &dyn Fn(&Source) -> bool,
) -> Result<(Option<GeoTransform>, (f64, f64))> {
    let mut native: Option<GeoTransform> = None;
    for s in sources.iter().filter(|s| same_crs(s)) {
        let geo = georeferenced(s)?;
        let area = |g: &GeoTransform| g.cell_size().0 * g.cell_size().1;
        if native.as_ref().is_none_or(|n| area(&geo) < area(n)) {
            native = Some(geo);
        }
    }
    let (rx, ry) = match (opts.resolution, &native) {
        (Some(r), _) => r,
        (None, Some(geo)) => geo.cell_size(),
        (None, None) => {
            let mut best = f64::INFINITY;
            for s in sources {
                let geo = georeferenced(s)?;
                let (Some(from), Some(to)) = (s.srs.as_ref(), target) else {
                    bail!("{}: no CRS to reproject from", s.path.display());
                };
                let cell = crs::detail_preserving_cell(&geo, s.width, s.height, from, to)
                    .with_context(|| s.path.display().to_string())?;
                best = best.min(cell);
            }
            (best, best)
        }
    };
    if !(rx > 0.0 && ry > 0.0) {
        bail!("target resolution must be positive, got {rx} × {ry}");
    }
    Ok((native, (rx, ry)))
}

/// The target grid's origin (top-left corner) and size in cells: the
/// extent asked for, or the union of the tiles' footprints aligned to the
/// native tile's cell lines when it lies on the target grid (so aligned
/// tiles are copied without resampling), otherwise to multiples of the
/// resolution.
fn grid_extent(
    extent: Option<[f64; 4]>,
    footprints: &[[f64; 4]],
    native: Option<&GeoTransform>,
    (rx, ry): (f64, f64),
) -> Result<(f64, f64, usize, usize)> {
    if let Some([xmin, ymin, xmax, ymax]) = extent {
        if !(xmax > xmin && ymax > ymin) {
            bail!("extent must have xmin < xmax and ymin < ymax");
        }
        let w = ((xmax - xmin) / rx).round().max(1.0) as usize;
        let h = ((ymax - ymin) / ry).round().max(1.0) as usize;
        return Ok((xmin, ymax, w, h));
    }
    let union = footprints.iter().fold(
        [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ],
        |b, f| {
            [
                b[0].min(f[0]),
                b[1].min(f[1]),
                b[2].max(f[2]),
                b[3].max(f[3]),
            ]
        },
    );
    let (anchor_x, anchor_y) = match native {
        Some(geo) if geo.is_north_up() && geo.cell_size() == (rx, ry) => (geo.0[0], geo.0[3]),
        _ => (0.0, 0.0),
    };
    let ox = anchor_x + ((union[0] - anchor_x) / rx + 1e-6).floor() * rx;
    let oy = anchor_y + ((union[3] - anchor_y) / ry - 1e-6).ceil() * ry;
    let w = ((union[2] - ox) / rx - 1e-6).ceil().max(1.0) as usize;
    let h = ((oy - union[1]) / ry - 1e-6).ceil().max(1.0) as usize;
    Ok((ox, oy, w, h))
}

/// One tile on its `window` of the target grid: copied cell for cell when
/// it lies on that grid, else warped by GDAL; encoded elevation tiles are
/// decoded first.
fn warp_tile(
    s: &Source,
    window: &GridSpec,
    same_crs: bool,
    opts: &StitchOptions,
) -> Result<Raster> {
    if opts.encoding != Encoding::Plain {
        let decoded = decode(s, opts)?;
        let geo = georeferenced(s)?;
        let mem = gdalio::mem_dataset(&decoded, &geo, s.srs.as_ref())?;
        return gdalio::warp(&mem, &s.path, window, opts.resampling, None);
    }
    let nodata = opts.src_nodata.or(s.nodata);
    match aligned_offset(s, window, same_crs) {
        Some(offset) => copy_aligned(s, window, offset, nodata),
        None => {
            // GDAL's warper would take NaN for no-data silently; reading
            // once refuses undeclared NaN with the file named.
            if gdalio::is_float(s.band_type) && !nodata.is_some_and(f64::is_nan) {
                s.read(nodata)?;
            }
            gdalio::warp(
                &s.dataset,
                &s.path,
                window,
                opts.resampling,
                opts.src_nodata,
            )
        }
    }
}

/// When `source` lies on the window's own grid (same CRS, north-up, same
/// cell size, whole-cell offset), the (column, row) of the window's origin in
/// source cells: every kernel then reduces to copying cells.
fn aligned_offset(source: &Source, window: &GridSpec, same_crs: bool) -> Option<(i64, i64)> {
    let geo = source.geotransform?;
    same_crs
        .then(|| geo.whole_cell_offset(&window.geotransform))
        .flatten()
}

/// Fill the window from the source cells it overlaps, no-data elsewhere.
fn copy_aligned(
    source: &Source,
    window: &GridSpec,
    (dc, dr): (i64, i64),
    nodata: Option<f64>,
) -> Result<Raster> {
    let mut out = Raster::empty(window.width, window.height, source.bands);
    // Overlap of the window with the source, in source cells.
    let c0 = dc.max(0);
    let r0 = dr.max(0);
    let c1 = (dc + window.width as i64).min(source.width as i64);
    let r1 = (dr + window.height as i64).min(source.height as i64);
    if c1 <= c0 || r1 <= r0 {
        return Ok(out);
    }
    let (w, h) = ((c1 - c0) as usize, (r1 - r0) as usize);
    let part = source.read_window(c0 as usize, r0 as usize, w, h, None, nodata)?;
    out.paste(&part, (c0 - dc) as usize, (r0 - dr) as usize);
    out.unify_validity();
    Ok(out)
}

/// The geotransform of a source that [`check_sources`] found georeferenced.
fn georeferenced(source: &Source) -> Result<GeoTransform> {
    source
        .geotransform
        .with_context(|| format!("{}: not georeferenced", source.path.display()))
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default()
}
