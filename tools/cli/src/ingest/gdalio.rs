//! Everything that talks to GDAL: opening rasters with clear errors, reading
//! them into [`Raster`]s, warping onto a target grid, and writing GeoTIFFs.

use crate::output;
use anyhow::{anyhow, bail, Context, Result};
use gdal::errors::CplErrType;
use gdal::raster::{Buffer, GdalDataType, GdalType, RasterCreationOptions};
use gdal::spatial_ref::SpatialRef;
use gdal::{Dataset, DriverManager};
use relevo_core::geo::GeoTransform;
use relevo_core::raster::Raster;
use std::ffi::{c_char, c_int, CString};
use std::path::{Path, PathBuf};
use std::ptr::null_mut;

/// A north-up target grid in a CRS (empty WKT: not georeferenced).
#[derive(Debug, Clone, PartialEq)]
pub struct GridSpec {
    pub crs_wkt: String,
    pub geotransform: GeoTransform,
    pub width: usize,
    pub height: usize,
}

/// Route GDAL's own messages into our log instead of stderr; failures are
/// reported through return values with the file named. GDAL's failures
/// are also kept (per thread, the first few since `clear_errors`), since
/// the message that names the cause — a VRT's missing source, say — often
/// comes before the one a failed call leaves last.
pub fn init() {
    gdal::config::set_error_handler(|class, number, message| {
        tracing::debug!(target: "gdal", "{class:?} {number}: {message}");
        if matches!(class, CplErrType::Failure | CplErrType::Fatal) {
            FAILURES.with_borrow_mut(|kept| {
                if kept.len() < KEPT_FAILURES && !kept.iter().any(|m| m == message) {
                    kept.push(message.trim().to_string());
                }
            });
        }
    });
}

/// GDAL failures kept per call (the cause and what it led to).
const KEPT_FAILURES: usize = 3;

thread_local! {
    /// GDAL's failure messages on this thread since [`clear_errors`].
    static FAILURES: std::cell::RefCell<Vec<String>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Forget GDAL's failures so far on this thread (before a call whose
/// failure [`last_error`] will explain).
pub(crate) fn clear_errors() {
    FAILURES.with_borrow_mut(Vec::clear);
}

/// GDAL's failure messages on this thread since [`clear_errors`], first
/// (the cause) to last; else GDAL's last message; else `fallback`.
pub(crate) fn last_error(fallback: &str) -> String {
    let kept = FAILURES.with_borrow_mut(std::mem::take);
    if !kept.is_empty() {
        return kept.join("; ");
    }
    // SAFETY: CPLGetLastErrorMsg returns a pointer to a thread-local string.
    let message = unsafe { std::ffi::CStr::from_ptr(gdal_sys::CPLGetLastErrorMsg()) }
        .to_string_lossy()
        .trim()
        .to_string();
    if message.is_empty() {
        fallback.to_string()
    } else {
        message
    }
}

/// What ingest needs to know of one input raster.
pub struct Source {
    pub path: PathBuf,
    pub dataset: Dataset,
    pub width: usize,
    pub height: usize,
    pub bands: usize,
    pub band_type: GdalDataType,
    pub nodata: Option<f64>,
    /// `None` when the file (and any world file beside it) gives no georeferencing.
    pub geotransform: Option<GeoTransform>,
    /// `None` when no CRS is known.
    pub srs: Option<SpatialRef>,
}

/// Open a raster and read its header, with errors that name the file.
pub fn open(path: &Path) -> Result<Source> {
    if !path.exists() {
        bail!("{}: no such file", path.display());
    }
    if path.is_dir() {
        // GDAL opens some directories; as an input here one is a user mistake.
        bail!("{}: is a directory, not a raster", path.display());
    }
    clear_errors();
    let dataset = Dataset::open(path).map_err(|_| {
        anyhow!(
            "{}: not a raster GDAL can read ({})",
            path.display(),
            last_error("unrecognised format")
        )
    })?;
    let (width, height) = dataset.raster_size();
    let bands = dataset.raster_count();
    if bands == 0 {
        bail!("{}: has no raster bands", path.display());
    }
    let band = dataset.rasterband(1)?;
    let band_type = band.band_type();
    let nodata = band.no_data_value();
    let geotransform = dataset
        .geo_transform()
        .ok()
        .map(GeoTransform)
        .filter(|g| *g != GeoTransform::IDENTITY);
    if geotransform.is_none() {
        if let Some(world) = world_files(path).into_iter().find(|w| w.is_file()) {
            bail!(
                "{}: the world file beside {} cannot be read (a world file holds six numbers, \
                 one a line: pixel width, two rotations, pixel height, then the easting and \
                 northing of the first pixel's centre)",
                world.display(),
                path.display()
            );
        }
    }
    let srs = dataset.spatial_ref().ok().map(|mut s| {
        s.set_axis_mapping_strategy(gdal::spatial_ref::AxisMappingStrategy::TraditionalGisOrder);
        s
    });
    Ok(Source {
        path: path.to_path_buf(),
        dataset,
        width,
        height,
        bands,
        band_type,
        nodata,
        geotransform,
        srs,
    })
}

/// The world files GDAL looks for beside `path`: the extension's first
/// and last letters and a `w` (`.pgw`), the extension and a `w` (`.pngw`),
/// and `.wld`, each in lower and upper case.
fn world_files(path: &Path) -> Vec<PathBuf> {
    let Some(ext) = path.extension().and_then(|e| e.to_str()) else {
        return Vec::new();
    };
    let mut names = vec![format!("{ext}w"), "wld".to_string()];
    if let (Some(first), Some(last)) = (ext.chars().next(), ext.chars().last()) {
        names.insert(0, format!("{first}{last}w"));
    }
    names
        .iter()
        .flat_map(|n| [n.to_lowercase(), n.to_uppercase()])
        .map(|n| path.with_extension(n))
        .collect()
}

impl Source {
    /// Read every band into memory as f64, turning `nodata` into NaN.
    /// Reads the whole file, so a truncated or corrupt file fails here.
    pub fn read(&self, nodata: Option<f64>) -> Result<Raster> {
        self.read_window(0, 0, self.width, self.height, None, nodata)
    }

    /// Read the `width`×`height` window at (`col`, `row`) as f64, turning
    /// `nodata` into NaN: the given bands (1-based, in that order), or all.
    pub fn read_window(
        &self,
        col: usize,
        row: usize,
        width: usize,
        height: usize,
        bands: Option<&[usize]>,
        nodata: Option<f64>,
    ) -> Result<Raster> {
        self.read_window_as(col, row, width, height, (width, height), bands, nodata)
    }

    /// [`Source::read_window`] resampled by GDAL (nearest) to `size` cells,
    /// e.g. a decimated view of a whole image.
    #[allow(clippy::too_many_arguments)]
    pub fn read_window_as(
        &self,
        col: usize,
        row: usize,
        width: usize,
        height: usize,
        size: (usize, usize),
        bands: Option<&[usize]>,
        nodata: Option<f64>,
    ) -> Result<Raster> {
        let (out_w, out_h) = size;
        let all: Vec<usize> = (1..=self.bands).collect();
        let bands = bands.unwrap_or(&all);
        // The f64 copy and GDAL's buffer of one band.
        relevo_core::memory::check(
            &format!(
                "{}: reading {out_w}×{out_h} cells, {} band(s),",
                self.path.display(),
                bands.len()
            ),
            (out_w as u64).saturating_mul(out_h as u64),
            8 * bands.len() as u64 + 8,
            "crop the raster first (gdal_translate -srcwin)",
        )?;
        let mut data = Vec::with_capacity(out_w * out_h * bands.len());
        clear_errors();
        for &b in bands {
            let band = self.dataset.rasterband(b)?;
            let buffer: Buffer<f64> = band
                .read_as(
                    (col as isize, row as isize),
                    (width, height),
                    (out_w, out_h),
                    None,
                )
                .map_err(|_| {
                    anyhow!(
                        "{}: cannot read band {b} ({})",
                        self.path.display(),
                        last_error("read failed")
                    )
                })?;
            let nan_is_nodata = nodata.is_some_and(f64::is_nan);
            let infinite = buffer
                .data()
                .iter()
                .filter(|&&v| v.is_infinite() && Some(v) != nodata)
                .count();
            if infinite > 0 {
                bail!(
                    "{}: band {b}: {infinite} value(s) are infinite and not the declared no-data; \
                     pass --src-nodata VALUE if they mark holes",
                    self.path.display()
                );
            }
            if !nan_is_nodata {
                let nans = buffer.data().iter().filter(|v| v.is_nan()).count();
                if nans > 0 {
                    bail!(
                        "{}: {nans} value(s) are NaN but the file does not declare NaN as no-data; \
                         pass --src-nodata nan to treat them as holes",
                        self.path.display()
                    );
                }
            }
            data.extend(buffer.data().iter().map(|&v| match nodata {
                Some(nd) if v == nd || nan_is_nodata && v.is_nan() => f64::NAN,
                _ => v,
            }));
        }
        Ok(Raster::from_data(out_w, out_h, bands.len(), data))
    }
}

/// Resampling kernels, by gdalwarp's names.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Resampling {
    #[default]
    Nearest,
    Bilinear,
    Cubic,
    Cubicspline,
    Lanczos,
    Average,
    Mode,
}

impl Resampling {
    fn gdal_name(self) -> &'static str {
        match self {
            Resampling::Nearest => "near",
            Resampling::Bilinear => "bilinear",
            Resampling::Cubic => "cubic",
            Resampling::Cubicspline => "cubicspline",
            Resampling::Lanczos => "lanczos",
            Resampling::Average => "average",
            Resampling::Mode => "mode",
        }
    }
}

/// An in-memory GDAL dataset (Float64) holding `raster`, for warping data
/// that was decoded or computed rather than read.
pub fn mem_dataset(
    raster: &Raster,
    geotransform: &GeoTransform,
    srs: Option<&SpatialRef>,
) -> Result<Dataset> {
    let driver = DriverManager::get_driver_by_name("MEM")?;
    let mut ds =
        driver.create_with_band_type::<f64, _>("", raster.width, raster.height, raster.bands)?;
    ds.set_geo_transform(&geotransform.0)?;
    if let Some(srs) = srs {
        ds.set_spatial_ref(srs)?;
    }
    for b in 0..raster.bands {
        let mut band = ds.rasterband(b + 1)?;
        band.set_no_data_value(Some(f64::NAN))?;
        let mut buffer = Buffer::new((raster.width, raster.height), raster.band(b).to_vec());
        band.write((0, 0), (raster.width, raster.height), &mut buffer)?;
    }
    Ok(ds)
}

/// Warp `source` onto `grid` with GDAL's warper (gdalwarp's engine), returning
/// every band as f64 with NaN where the source has no data or does not reach.
/// `src_nodata` overrides the file's own no-data value.
pub fn warp(
    source: &Dataset,
    name: &Path,
    grid: &GridSpec,
    resampling: Resampling,
    src_nodata: Option<f64>,
) -> Result<Raster> {
    let [xmin, ymin, xmax, ymax] = grid.geotransform.bounds(grid.width, grid.height);
    let mut args: Vec<String> = vec![
        "-of".into(),
        "MEM".into(),
        "-ot".into(),
        "Float64".into(),
        "-te".into(),
        format!("{xmin:.17}"),
        format!("{ymin:.17}"),
        format!("{xmax:.17}"),
        format!("{ymax:.17}"),
        "-ts".into(),
        grid.width.to_string(),
        grid.height.to_string(),
        "-r".into(),
        resampling.gdal_name().into(),
        "-dstnodata".into(),
        "nan".into(),
        "-wo".into(),
        "NUM_THREADS=ALL_CPUS".into(),
    ];
    if !grid.crs_wkt.is_empty() {
        args.extend(["-t_srs".into(), grid.crs_wkt.clone()]);
    }
    if let Some(nd) = src_nodata {
        args.extend(["-srcnodata".into(), format_nodata(nd)]);
    }
    let out = gdal_warp(source, &args)
        .with_context(|| format!("{}: cannot warp onto the target grid", name.display()))?;
    let mut data = Vec::with_capacity(grid.width * grid.height * out.raster_count());
    for b in 1..=out.raster_count() {
        let buffer: Buffer<f64> = out.rasterband(b)?.read_as(
            (0, 0),
            (grid.width, grid.height),
            (grid.width, grid.height),
            None,
        )?;
        data.extend_from_slice(buffer.data());
    }
    let mut raster = Raster::from_data(grid.width, grid.height, out.raster_count(), data);
    raster.unify_validity();
    Ok(raster)
}

fn format_nodata(v: f64) -> String {
    if v.is_nan() {
        "nan".into()
    } else {
        format!("{v}")
    }
}

/// `GDALWarp` (the library form of gdalwarp) on one source, returning the
/// output dataset. The gdal crate does not wrap it.
fn gdal_warp(source: &Dataset, args: &[String]) -> Result<Dataset> {
    let c_args: Vec<CString> = args
        .iter()
        .map(|a| CString::new(a.as_str()))
        .collect::<Result<_, _>>()?;
    let mut c_ptrs: Vec<*mut c_char> = c_args
        .iter()
        .map(|a| a.as_ptr() as *mut c_char)
        .chain(std::iter::once(null_mut()))
        .collect();
    let empty = CString::default();
    clear_errors();
    // SAFETY: the argument strings outlive the options object, which is freed
    // before returning; the source handle stays valid for the call.
    unsafe {
        let options = gdal_sys::GDALWarpAppOptionsNew(c_ptrs.as_mut_ptr(), null_mut());
        if options.is_null() {
            bail!("invalid warp options: {}", last_error("unknown"));
        }
        let mut sources = [source.c_dataset()];
        let mut usage_error: c_int = 0;
        let out = gdal_sys::GDALWarp(
            empty.as_ptr(),
            null_mut(),
            1,
            sources.as_mut_ptr(),
            options,
            &mut usage_error,
        );
        gdal_sys::GDALWarpAppOptionsFree(options);
        if out.is_null() {
            bail!("{}", last_error("GDALWarp failed"));
        }
        Ok(Dataset::from_c_dataset(out))
    }
}

/// Read band 1 of a raster (warning when it has more) with its grid, band
/// type and no-data value (`src_nodata` overriding the file's); a raster
/// with no valid cell is refused.
pub fn read_single_band(
    path: &Path,
    src_nodata: Option<f64>,
) -> Result<(Raster, GridSpec, GdalDataType, Option<f64>)> {
    let source = open(path)?;
    let nodata = src_nodata.or(source.nodata);
    let mut raster = source.read(nodata)?;
    if raster.bands > 1 {
        tracing::warn!("{}: using band 1 of {}", path.display(), raster.bands);
        raster = Raster::from_data(raster.width, raster.height, 1, raster.band(0).to_vec());
    }
    let grid = GridSpec {
        crs_wkt: source
            .srs
            .as_ref()
            .map(super::crs::to_wkt)
            .transpose()?
            .unwrap_or_default(),
        geotransform: source.geotransform.unwrap_or(GeoTransform::IDENTITY),
        width: source.width,
        height: source.height,
    };
    if raster.valid_count() == 0 {
        bail!("{}: no valid data (every cell is no-data)", path.display());
    }
    check_heights(&raster, &path.display().to_string())?;
    Ok((raster, grid, source.band_type, nodata))
}

/// Largest height magnitude taken as a height, metres: beyond it a value
/// is an undeclared no-data marker (such as ±3.4e38) or a unit error.
pub const MAX_ABS_HEIGHT_M: f64 = 100_000.0;

/// Refuse heights beyond ±[`MAX_ABS_HEIGHT_M`] in band 1 of `raster`
/// (NaN is no-data), naming `source`, how many, and the first one's cell.
pub fn check_heights(raster: &Raster, source: &str) -> Result<()> {
    let band = raster.band(0);
    let beyond = band.iter().filter(|v| v.abs() > MAX_ABS_HEIGHT_M).count();
    if let Some(first) = band.iter().position(|v| v.abs() > MAX_ABS_HEIGHT_M) {
        bail!(
            "{source}: {beyond} height(s) beyond ±{MAX_ABS_HEIGHT_M} m (the first, {:e}, at column {}, \
             row {}): an undeclared no-data value? pass --src-nodata VALUE",
            band[first],
            first % raster.width,
            first / raster.width
        );
    }
    Ok(())
}

/// Write `raster` as a tiled, deflate-compressed GeoTIFF of `band_type`,
/// NaN cells becoming `nodata`. Written beside `path` and renamed into place,
/// so an interrupted write leaves nothing at `path`.
pub fn write_geotiff(
    path: &Path,
    raster: &Raster,
    grid: &GridSpec,
    band_type: GdalDataType,
    nodata: Option<f64>,
) -> Result<()> {
    output::write_through_partial(path, "", |partial| {
        // Ask the OS first: its message says why a path cannot be written.
        std::fs::File::create(partial)
            .map_err(|e| anyhow!("{}: cannot write ({e})", path.display()))?;
        write_geotiff_at(partial, raster, grid, band_type, nodata)
    })
}

fn write_geotiff_at(
    path: &Path,
    raster: &Raster,
    grid: &GridSpec,
    band_type: GdalDataType,
    nodata: Option<f64>,
) -> Result<()> {
    macro_rules! typed {
        ($t:ty) => {
            write_typed::<$t>(path, raster, grid, nodata)
        };
    }
    match band_type {
        GdalDataType::UInt8 => typed!(u8),
        GdalDataType::UInt16 => typed!(u16),
        GdalDataType::Int16 => typed!(i16),
        GdalDataType::UInt32 => typed!(u32),
        GdalDataType::Int32 => typed!(i32),
        GdalDataType::Float32 => typed!(f32),
        _ => typed!(f64),
    }
}

/// Conversion of a computed f64 to a band's type: integers round half away
/// from zero and saturate.
trait FromF64: GdalType + Copy {
    fn from_f64(v: f64) -> Self;
}
macro_rules! from_f64_int {
    ($($t:ty),*) => {$(impl FromF64 for $t { fn from_f64(v: f64) -> Self { v.round() as $t } })*};
}
from_f64_int!(u8, u16, i16, u32, i32);
impl FromF64 for f32 {
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}
impl FromF64 for f64 {
    fn from_f64(v: f64) -> Self {
        v
    }
}

fn write_typed<T: FromF64>(
    path: &Path,
    raster: &Raster,
    grid: &GridSpec,
    nodata: Option<f64>,
) -> Result<()> {
    let driver = DriverManager::get_driver_by_name("GTiff")?;
    let mut options = RasterCreationOptions::new();
    for (k, v) in [
        ("COMPRESS", "DEFLATE"),
        ("ZLEVEL", "1"),
        ("TILED", "YES"),
        ("BIGTIFF", "IF_SAFER"),
        ("NUM_THREADS", "ALL_CPUS"),
    ] {
        options.set_name_value(k, v)?;
    }
    clear_errors();
    let mut ds = driver
        .create_with_band_type_with_options::<T, _>(
            path,
            raster.width,
            raster.height,
            raster.bands,
            &options,
        )
        .map_err(|_| {
            anyhow!(
                "{}: cannot create ({})",
                path.display(),
                last_error("create failed")
            )
        })?;
    if grid.geotransform != GeoTransform::IDENTITY {
        ds.set_geo_transform(&grid.geotransform.0)?;
    }
    if !grid.crs_wkt.is_empty() {
        ds.set_projection(&grid.crs_wkt)?;
    }
    let fill = nodata.unwrap_or(f64::NAN);
    for b in 0..raster.bands {
        let mut band = ds.rasterband(b + 1)?;
        if let Some(nd) = nodata {
            band.set_no_data_value(Some(nd))?;
        }
        let data: Vec<T> = raster
            .band(b)
            .iter()
            .map(|&v| T::from_f64(if v.is_nan() { fill } else { v }))
            .collect();
        let mut buffer = Buffer::new((raster.width, raster.height), data);
        band.write((0, 0), (raster.width, raster.height), &mut buffer)
            .map_err(|_| {
                anyhow!(
                    "{}: cannot write ({})",
                    path.display(),
                    last_error("write failed")
                )
            })?;
    }
    ds.flush_cache()?;
    ds.close().map_err(|_| {
        anyhow!(
            "{}: cannot finish writing ({})",
            path.display(),
            last_error("close failed")
        )
    })?;
    Ok(())
}

/// The no-data value to write for `band_type` when none is given.
pub fn default_nodata(band_type: GdalDataType) -> f64 {
    match band_type {
        GdalDataType::UInt8 | GdalDataType::UInt16 | GdalDataType::UInt32 => 0.0,
        GdalDataType::Int16 => i16::MIN as f64,
        GdalDataType::Int32 => i32::MIN as f64,
        _ => f64::NAN,
    }
}

/// True for band types that hold floating-point values.
pub fn is_float(band_type: GdalDataType) -> bool {
    matches!(band_type, GdalDataType::Float32 | GdalDataType::Float64)
}
