//! Vegetation files through GDAL: reading the analysed bands of any raster
//! (stretched to 8 bits), and writing the objects as a GeoPackage and the
//! labels as a GeoTIFF. The extraction itself is
//! [`relevo_core::veg::pipeline`].

use crate::ingest::crs;
use crate::ingest::gdalio::{self, GridSpec};
use crate::output;
use anyhow::{anyhow, bail, Context, Result};
use gdal::raster::GdalDataType;
use gdal::spatial_ref::SpatialRef;
use gdal::vector::{Feature, FieldValue, Geometry, LayerAccess, LayerOptions, OGRFieldType};
use gdal::DriverManager;
use rayon::prelude::*;
use relevo_core::geo::GeoTransform;
use relevo_core::raster::stretch::{stretch_or_default, stretch_ranges, to_u8};
use relevo_core::raster::Raster;
use relevo_core::veg::db::VegObject;
use relevo_core::veg::pipeline::{Extraction, PixelSource, TileImage, VegImage};
use relevo_core::veg::samples::Sample;
use relevo_core::veg::Image;
use std::path::Path;

/// Rows read at a time.
const STRIP_ROWS: usize = 256;

/// Most cells of the view stretch percentiles are taken from.
const STRETCH_VIEW_CELLS: usize = 1 << 22;

/// What a band holds, as vegetation extraction tells it from the band's
/// colour interpretation or description.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum BandRole {
    Red,
    Green,
    Blue,
    NearInfrared,
}

impl BandRole {
    /// The role GDAL's colour interpretation (by name, so that those newer
    /// than this binary read as unknown) or the band's description names.
    fn of(band: &gdal::raster::RasterBand) -> Option<BandRole> {
        use gdal::Metadata;
        // SAFETY: the band handle is valid while `band` lives; the name is
        // a static string GDAL owns.
        let interpretation = unsafe {
            let c = gdal_sys::GDALGetRasterColorInterpretation(band.c_rasterband());
            let name = gdal_sys::GDALGetColorInterpretationName(c);
            if name.is_null() {
                String::new()
            } else {
                std::ffi::CStr::from_ptr(name)
                    .to_string_lossy()
                    .to_lowercase()
            }
        };
        let description = band.description().unwrap_or_default().to_lowercase();
        let says = |words: &[&str]| {
            words.iter().any(|w| {
                interpretation == *w
                    || description
                        .split(|c: char| !c.is_alphanumeric())
                        .any(|d| d == *w)
            })
        };
        let near_infrared = says(&["nir", "nir1"])
            || description.contains("near infrared")
            || description.contains("near-infrared");
        if near_infrared {
            Some(BandRole::NearInfrared)
        } else if says(&["red"]) {
            Some(BandRole::Red)
        } else if says(&["green"]) {
            Some(BandRole::Green)
        } else if says(&["blue"]) {
            Some(BandRole::Blue)
        } else {
            None
        }
    }

    fn name(self) -> &'static str {
        match self {
            BandRole::Red => "red",
            BandRole::Green => "green",
            BandRole::Blue => "blue",
            BandRole::NearInfrared => "near-infrared",
        }
    }
}

/// `roles` with the untagged fourth band of an image whose first three are
/// red, green and blue taken as near-infrared, as 4-band aerial imagery
/// (NAIP) carries it.
fn with_near_infrared_inferred(mut roles: Vec<Option<BandRole>>) -> Vec<Option<BandRole>> {
    use BandRole::{Blue, Green, NearInfrared, Red};
    if let [Some(Red), Some(Green), Some(Blue), fourth @ None] = roles.as_mut_slice() {
        *fourth = Some(NearInfrared);
    }
    roles
}

/// The bands analysed when none are asked for (1-based), from each band's
/// role: red, green and blue and the near-infrared band when the image has
/// one; otherwise the first three.
fn default_bands(roles: &[Option<BandRole>]) -> Vec<usize> {
    let find = |role: BandRole| roles.iter().position(|&r| r == Some(role)).map(|i| i + 1);
    let rgb = [BandRole::Red, BandRole::Green, BandRole::Blue].map(find);
    match (rgb, find(BandRole::NearInfrared)) {
        ([Some(r), Some(g), Some(b)], Some(n)) => vec![r, g, b, n],
        (_, Some(n)) if roles.len() >= 3 => {
            let mut bands: Vec<usize> = (1..=3).filter(|&b| b != n).collect();
            bands.push(n);
            bands
        }
        _ => (1..=roles.len().min(3)).collect(),
    }
}

/// Read `bands` (1-based) of `path` whole; see [`ImageReader`].
pub fn read_image(
    path: &Path,
    bands: Option<&[usize]>,
    stretch: Option<[f64; 2]>,
    pixel_m: Option<f64>,
) -> Result<VegImage> {
    ImageReader::open(path, bands, stretch, pixel_m)?.whole()
}

/// An image opened for vegetation extraction, read whole or window by
/// window (each window as the whole image holds it): `bands` (1-based);
/// 8-bit data kept, deeper data stretched between the `stretch`
/// percentiles (default 2, 98) to 8 bits (percentiles of the whole image,
/// or of a view decimated to about 4 M cells when it is larger); `pixel_m`
/// the pixel size of an image that is not georeferenced.
pub struct ImageReader {
    path: std::path::PathBuf,
    bands: Vec<usize>,
    /// What each analysed band is ("red", "near-infrared", "band 5").
    pub band_roles: Vec<String>,
    /// Per band, the values stretched to 0 and 255.
    ranges: Vec<(f64, f64)>,
    /// 8-bit bands copied as they are.
    as_bytes: bool,
    /// The no-data value of 8-bit bands, when one is set.
    byte_nodata: Option<f64>,
    /// Whether pixels are checked for data.
    masked: bool,
    nodata: Option<f64>,
    pub width: usize,
    pub height: usize,
    pub crs_wkt: String,
    pub geotransform: Option<GeoTransform>,
    pub pixel_m: f64,
}

impl ImageReader {
    pub fn open(
        path: &Path,
        bands: Option<&[usize]>,
        stretch: Option<[f64; 2]>,
        pixel_m: Option<f64>,
    ) -> Result<ImageReader> {
        let source = gdalio::open(path)?;
        let roles = with_near_infrared_inferred(
            (1..=source.bands)
                .map(|b| {
                    source
                        .dataset
                        .rasterband(b)
                        .ok()
                        .and_then(|band| BandRole::of(&band))
                })
                .collect(),
        );
        let bands: Vec<usize> = match bands {
            Some(b) => b.to_vec(),
            None => default_bands(&roles),
        };
        if bands.is_empty() || bands.len() > relevo_core::veg::MAX_BANDS {
            bail!(
                "{}: choose 1 to {} bands, got {}",
                path.display(),
                relevo_core::veg::MAX_BANDS,
                bands.len()
            );
        }
        if let Some(&b) = bands.iter().find(|&&b| b == 0 || b > source.bands) {
            bail!(
                "{}: has {} band(s), no band {b}",
                path.display(),
                source.bands
            );
        }
        let (w, h) = (source.width, source.height);
        // Stretch ranges from a view of the whole image decimated to at
        // most STRETCH_VIEW_CELLS (the whole image when smaller).
        let stretch = stretch_or_default(stretch, source.band_type == GdalDataType::UInt8);
        let ranges = match stretch {
            None => vec![(0.0, 255.0); bands.len()],
            Some(_) => {
                let factor = ((w * h) as f64 / STRETCH_VIEW_CELLS as f64).sqrt().max(1.0);
                let view = (
                    ((w as f64 / factor).ceil() as usize).max(1),
                    ((h as f64 / factor).ceil() as usize).max(1),
                );
                let decimated =
                    source.read_window_as(0, 0, w, h, view, Some(&bands), source.nodata)?;
                stretch_ranges(&decimated, stretch)
            }
        };
        // 8-bit bands without a stretch are copied as they are, without a
        // detour through f64; then only a no-data value asks for the
        // validity mask, so a large image pays no mask it does not need.
        let as_bytes = stretch.is_none()
            && bands.iter().all(|&b| {
                source
                    .dataset
                    .rasterband(b)
                    .is_ok_and(|band| band.band_type() == GdalDataType::UInt8)
            });
        let byte_nodata = source
            .nodata
            .filter(|v| (0.0..=255.0).contains(v) && v.fract() == 0.0);
        let crs_wkt = match &source.srs {
            Some(srs) => crs::to_wkt(srs)?,
            None => String::new(),
        };
        let ground = source.geotransform.map(|g| {
            let cell = g.smallest_cell_side();
            // Geographic CRS: degrees to metres along a meridian.
            match &source.srs {
                Some(srs) if srs.is_geographic() => cell * 111_320.0,
                _ => cell,
            }
        });
        let pixel_m = match (pixel_m, ground) {
            (Some(p), _) if p.is_finite() && p > 0.0 => p,
            (Some(p), _) => bail!("--pixel-size must be positive, got {p}"),
            (None, Some(g)) => g,
            (None, None) => {
                tracing::warn!(
                    "{}: not georeferenced; taking 1 m pixels (set --pixel-size)",
                    path.display()
                );
                1.0
            }
        };
        let band_roles = bands
            .iter()
            .map(|&b| match roles[b - 1] {
                Some(role) => format!("{b} {}", role.name()),
                None => format!("{b}"),
            })
            .collect();
        Ok(ImageReader {
            path: path.to_path_buf(),
            bands,
            band_roles,
            ranges,
            as_bytes,
            byte_nodata,
            masked: !as_bytes || byte_nodata.is_some(),
            nodata: source.nodata,
            width: w,
            height: h,
            crs_wkt,
            geotransform: source.geotransform,
            pixel_m,
        })
    }

    /// The whole image, its pixels and validity held in memory (checked
    /// against the budget first).
    pub fn whole(self) -> Result<VegImage> {
        let (w, h) = (self.width, self.height);
        // Kept whole: the 8-bit bands, the valid mask and the region label
        // of every pixel; the extraction checks its tiles' working memory.
        relevo_core::memory::check(
            &format!(
                "{}: vegetation extraction on {w}×{h} pixels",
                self.path.display()
            ),
            (w as u64).saturating_mul(h as u64),
            self.bands.len() as u64 + 5,
            "crop the image first (gdal_translate -srcwin), or split it across jobs (--plan)",
        )?;
        let (pixels, valid) = self.read([0, 0, w, h])?;
        let image = Image::new(w, h, self.bands.len(), pixels)
            .map_err(|e| anyhow!("{}: {e}", self.path.display()))?;
        Ok(VegImage {
            image,
            crs_wkt: self.crs_wkt,
            geotransform: self.geotransform,
            pixel_m: self.pixel_m,
            valid,
        })
    }

    /// The pixels of `rect` (`[x0, y0, x1, y1)`), interleaved, and which
    /// have data (`None`: all): strips of rows read in parallel, each
    /// worker through its own handle on the file (a GDAL dataset is not
    /// shared between threads), so the f64 copies hold a strip per thread.
    pub fn read(&self, [x0, y0, x1, y1]: [usize; 4]) -> Result<(Vec<u8>, Option<Vec<bool>>)> {
        let (w, h, n) = (x1 - x0, y1 - y0, self.bands.len());
        let mut pixels = vec![0u8; w * h * n];
        let mut valid = if self.masked {
            vec![true; w * h]
        } else {
            Vec::new()
        };
        let strip_cells = STRIP_ROWS * w;
        let valid_strips: Vec<Option<&mut [bool]>> = if self.masked {
            valid.chunks_mut(strip_cells).map(Some).collect()
        } else {
            (0..h.div_ceil(STRIP_ROWS)).map(|_| None).collect()
        };
        pixels
            .par_chunks_mut(strip_cells * n)
            .zip(valid_strips)
            .enumerate()
            .try_for_each_init(
                || gdalio::open(&self.path),
                |handle, (k, (strip, valid))| -> Result<()> {
                    let source = handle.as_ref().map_err(|e| anyhow!("{e:#}"))?;
                    let (row, rows) = (y0 + k * STRIP_ROWS, strip.len() / (w * n));
                    if self.as_bytes {
                        return read_byte_strip(
                            source,
                            [x0, row, w, rows],
                            &self.bands,
                            self.byte_nodata,
                            strip,
                            valid,
                        );
                    }
                    let values =
                        source.read_window(x0, row, w, rows, Some(&self.bands), self.nodata)?;
                    let valid = valid.context("a mask for every strip read through f64")?;
                    for (i, (px, ok)) in strip.chunks_exact_mut(n).zip(valid).enumerate() {
                        for (b, v) in px.iter_mut().enumerate() {
                            *v = to_u8(values.band(b)[i], self.ranges[b]);
                        }
                        *ok = values.is_valid(i);
                    }
                    Ok(())
                },
            )?;
        Ok((
            pixels,
            (self.masked && valid.contains(&false)).then_some(valid),
        ))
    }
}

impl PixelSource for ImageReader {
    fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    fn window(&self, rect: [usize; 4], _: Vec<u8>) -> relevo_core::Result<TileImage<'_>> {
        let (pixels, valid) = self
            .read(rect)
            .map_err(|e| relevo_core::Error::Input(format!("{e:#}")))?;
        let image = Image::new(
            rect[2] - rect[0],
            rect[3] - rect[1],
            self.bands.len(),
            pixels,
        )?;
        Ok(TileImage::Window(image, valid))
    }
}

/// Read the window `[x, row, width, rows]` of 8-bit `bands` into `strip`
/// (interleaved) and, with a no-data value, its validity (every band
/// differs from it) into `valid`.
fn read_byte_strip(
    source: &gdalio::Source,
    [x, row, width, rows]: [usize; 4],
    bands: &[usize],
    nodata: Option<f64>,
    strip: &mut [u8],
    mut valid: Option<&mut [bool]>,
) -> Result<()> {
    let mut band_values = vec![0u8; width * rows];
    gdalio::clear_errors();
    for (k, &b) in bands.iter().enumerate() {
        source
            .dataset
            .rasterband(b)?
            .read_into_slice(
                (x as isize, row as isize),
                (width, rows),
                (width, rows),
                &mut band_values,
                None,
            )
            .map_err(|_| {
                anyhow!(
                    "{}: cannot read band {b} ({})",
                    source.path.display(),
                    gdalio::last_error("read failed")
                )
            })?;
        for (px, &v) in strip.chunks_exact_mut(bands.len()).zip(&band_values) {
            px[k] = v;
        }
        if let (Some(nd), Some(valid)) = (nodata, valid.as_deref_mut()) {
            for (ok, &v) in valid.iter_mut().zip(&band_values) {
                *ok &= v as f64 != nd;
            }
        }
    }
    Ok(())
}

/// The annotated NEON crops (0.1 m RGB) vegetation extraction is measured
/// on (`relevo-bench veg-protocol`, the regression tests): name, image and
/// truth stem under the shared data folder, the samples a user marked on
/// it (in this repository).
pub const ANNOTATED_CROPS: [(&str, &str, &str); 3] = [
    (
        "yellowstone",
        "trees/2019_YELL_2_541000_4977000_image_crop",
        "data/trees/yellowstone_samples.csv",
    ),
    (
        "soap_061",
        "trees/SOAP_061",
        "data/trees/soap_061_samples.csv",
    ),
    (
        "yellowstone_meadow",
        "trees/2019_YELL_2_528000_4978000_image_crop2",
        "data/trees/yellowstone_meadow_samples.csv",
    ),
];

/// The annotated crops ([`ANNOTATED_CROPS`]) with their samples and truth
/// boxes, from the repository `repo` and the shared data folder `data`.
pub fn annotated_crops(
    repo: &Path,
    data: &Path,
) -> Result<Vec<relevo_core::veg::protocol::Annotated>> {
    ANNOTATED_CROPS
        .into_iter()
        .map(|(name, stem, samples)| {
            annotated_crop(
                name,
                &data.join(format!("{stem}.png")),
                &data.join(format!("{stem}.xml")),
                &repo.join(samples),
                0.1,
            )
        })
        .collect()
}

/// An annotated crop for [`relevo_core::veg::protocol`]: the image (its
/// first three bands, pixels of `pixel_m` metres where it is not
/// georeferenced), the samples a user marked on it and its truth boxes
/// (Pascal VOC, or CSV lines `xmin,ymin,xmax,ymax[,class]`).
pub fn annotated_crop(
    name: &str,
    image: &Path,
    truth: &Path,
    samples: &Path,
    pixel_m: f64,
) -> Result<relevo_core::veg::protocol::Annotated> {
    use relevo_core::veg::eval;
    let image = read_image(image, None, None, Some(pixel_m))?;
    let (w, h) = (image.image.width, image.image.height);
    let samples = relevo_core::veg::samples::read_file(samples, None, w, h)?;
    let text = relevo_core::files::read_to_string(truth)?;
    let boxes = eval::parse_truth(&text).map_err(|e| anyhow!("{}: {e}", truth.display()))?;
    Ok(relevo_core::veg::protocol::Annotated {
        name: name.into(),
        image,
        samples,
        truth: eval::bounds(&boxes),
        truth_classes: boxes
            .iter()
            .map(|b| b.class.clone().unwrap_or_default().to_lowercase())
            .collect(),
    })
}

/// Write the objects as points of a GeoPackage layer `vegetation` (QGIS,
/// GDAL and most GIS open it), through a partial file renamed into place.
pub fn write_gpkg(path: &Path, objects: &[VegObject], crs_wkt: &str) -> Result<()> {
    // Fixed timestamps make the file depend on its content only.
    gdal::config::set_config_option("OGR_CURRENT_DATE", "2000-01-01T00:00:00.000Z")?;
    let result = output::write_through_partial(path, "gpkg", |partial| {
        let driver = DriverManager::get_driver_by_name("GPKG")?;
        let mut dataset = driver
            .create_vector_only(partial)
            .map_err(|e| anyhow!("{}: cannot create ({e})", path.display()))?;
        let srs = if crs_wkt.is_empty() {
            None
        } else {
            Some(SpatialRef::from_wkt(crs_wkt)?)
        };
        let mut txn = dataset.start_transaction()?;
        {
            let layer = txn.create_layer(LayerOptions {
                name: "vegetation",
                srs: srs.as_ref(),
                ty: gdal::vector::OGRwkbGeometryType::wkbPoint,
                options: None,
            })?;
            layer.create_defn_fields(&[
                ("id", OGRFieldType::OFTInteger64),
                ("class", OGRFieldType::OFTString),
                ("size", OGRFieldType::OFTReal),
                ("score", OGRFieldType::OFTReal),
            ])?;
            for o in objects {
                let mut feature = Feature::new(layer.defn())?;
                let mut point = Geometry::empty(gdal::vector::OGRwkbGeometryType::wkbPoint)?;
                point.add_point_2d((o.x, o.y));
                feature.set_geometry(point)?;
                feature.set_field(0, &FieldValue::Integer64Value(o.id as i64))?;
                feature.set_field(1, &FieldValue::StringValue(o.class.clone()))?;
                feature.set_field(2, &FieldValue::RealValue(o.size))?;
                feature.set_field(3, &FieldValue::RealValue(o.score as f64))?;
                feature.create(&layer)?;
            }
        }
        txn.commit()?;
        Ok(())
    });
    gdal::config::clear_config_option("OGR_CURRENT_DATE")?;
    result
}

/// Land-cover labels from any vector file GDAL reads (GeoPackage, GeoJSON,
/// Shapefile): each feature's `field` names its class; polygons (their
/// outer rings) and points (the pixel each falls in) are placed on the pixel
/// grid of `image`, reprojected from the layer's CRS to the image's.
pub fn read_land_cover(path: &Path, field: &str, image: &VegImage) -> Result<Vec<Sample>> {
    let dataset = gdal::Dataset::open(path)
        .map_err(|e| anyhow!("{}: cannot open as vector data ({e})", path.display()))?;
    let Some(geo) = image.geotransform else {
        bail!(
            "{}: the image is not georeferenced, so land-cover labels cannot be placed on it",
            path.display()
        );
    };
    let target = match image.crs_wkt.as_str() {
        "" => None,
        wkt => Some(SpatialRef::from_wkt(wkt)?),
    };
    let mut labels = Vec::new();
    for mut layer in dataset.layers() {
        let source = layer.spatial_ref();
        for feature in layer.features() {
            let index = feature.field_index(field).map_err(|_| {
                anyhow!(
                    "{}: no field {field:?} (--land-cover-field)",
                    path.display()
                )
            })?;
            let Some(class) = feature.field_as_string(index)?.filter(|c| !c.is_empty()) else {
                continue;
            };
            let Some(geometry) = feature.geometry() else {
                continue;
            };
            let mut shapes = Vec::new();
            outer_rings(geometry, &mut shapes);
            for (mut points, is_point) in shapes {
                if let (Some(from), Some(to)) = (&source, &target) {
                    let (mut xs, mut ys): (Vec<f64>, Vec<f64>) = points.iter().copied().unzip();
                    crs::transform_points(from, to, &mut xs, &mut ys)?;
                    points = xs.into_iter().zip(ys).collect();
                }
                let pixels: Option<Vec<[f64; 2]>> = points
                    .iter()
                    .map(|&(x, y)| geo.invert(x, y).map(|(c, r)| [c, r]))
                    .collect();
                let Some(mut polygon) = pixels else {
                    bail!(
                        "{}: the image's georeferencing cannot be inverted",
                        path.display()
                    );
                };
                if is_point {
                    let [c, r] = [polygon[0][0].floor(), polygon[0][1].floor()];
                    polygon = vec![[c, r], [c + 1.0, r], [c + 1.0, r + 1.0], [c, r + 1.0]];
                }
                labels.push(Sample {
                    class: class.clone(),
                    polygon,
                });
            }
        }
    }
    if labels.is_empty() {
        bail!("{}: no labelled points or polygons", path.display());
    }
    Ok(labels)
}

/// The points of each outer ring of `geometry` (polygons, also inside
/// multi-geometries), and each point, flagged as a point.
fn outer_rings(geometry: &Geometry, out: &mut Vec<(Vec<(f64, f64)>, bool)>) {
    use gdal::vector::{geometry_type_flatten, OGRwkbGeometryType as T};
    let points = |g: &Geometry| {
        let mut p = Vec::new();
        g.get_points(&mut p);
        p.into_iter().map(|(x, y, _)| (x, y)).collect::<Vec<_>>()
    };
    match geometry_type_flatten(geometry.geometry_type()) {
        T::wkbPoint => out.push((points(geometry), true)),
        T::wkbPolygon if geometry.geometry_count() > 0 => {
            out.push((points(&geometry.get_geometry(0)), false));
        }
        T::wkbMultiPoint | T::wkbMultiPolygon | T::wkbGeometryCollection => {
            for k in 0..geometry.geometry_count() {
                outer_rings(&geometry.get_geometry(k), out);
            }
        }
        _ => {}
    }
}

/// Write the labels as a two-band UInt32 GeoTIFF: band 1 the region of each
/// pixel (from 1), band 2 its class (1-based in the samples' order); pixels
/// without image data (a no-data collar) are no-data (0) in both bands,
/// belonging to no region and no class.
pub fn write_labels(path: &Path, image: &VegImage, extraction: &Extraction) -> Result<()> {
    let region_map = extraction.pixel_regions()?;
    let valid = |i: usize| image.valid.as_ref().is_none_or(|v| v[i]);
    let regions =
        region_map
            .iter()
            .enumerate()
            .map(|(i, &r)| if valid(i) { r as f64 + 1.0 } else { f64::NAN });
    let classes = region_map.iter().enumerate().map(|(i, &r)| {
        if valid(i) {
            extraction.labels[r as usize].class as f64 + 1.0
        } else {
            f64::NAN
        }
    });
    let data: Vec<f64> = regions.chain(classes).collect();
    let raster = Raster::from_data(image.image.width, image.image.height, 2, data);
    let grid = GridSpec {
        crs_wkt: image.crs_wkt.clone(),
        geotransform: image.geotransform.unwrap_or(GeoTransform::IDENTITY),
        width: image.image.width,
        height: image.image.height,
    };
    gdalio::write_geotiff(path, &raster, &grid, GdalDataType::UInt32, Some(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_infrared_is_analysed_by_default_where_the_bands_tell_it() {
        use BandRole::{Blue, Green, NearInfrared, Red};
        // NAIP and 4-band aerial imagery: R, G, B tagged, the fourth not.
        let naip = with_near_infrared_inferred(vec![Some(Red), Some(Green), Some(Blue), None]);
        assert_eq!(naip[3], Some(NearInfrared));
        assert_eq!(default_bands(&naip), [1, 2, 3, 4]);
        // Landsat-like stacks with descriptions, in any order.
        assert_eq!(
            default_bands(&[Some(Blue), Some(Green), Some(Red), Some(NearInfrared), None]),
            [3, 2, 1, 4]
        );
        // A named near-infrared band without colour tags.
        assert_eq!(
            default_bands(&[None, None, None, None, Some(NearInfrared)]),
            [1, 2, 3, 5]
        );
        // RGB, an RGB with an untagged fifth band, untagged bands: the
        // first three.
        assert_eq!(
            default_bands(&[Some(Red), Some(Green), Some(Blue)]),
            [1, 2, 3]
        );
        let five =
            with_near_infrared_inferred(vec![Some(Red), Some(Green), Some(Blue), None, None]);
        assert_eq!(default_bands(&five), [1, 2, 3]);
        assert_eq!(default_bands(&[None; 6]), [1, 2, 3]);
        assert_eq!(default_bands(&[None]), [1]);
    }
}
