//! `relevo veg`: vegetation extraction on an image file, with GDAL reading
//! the bands and writing the GeoPackage and the label GeoTIFF. The algorithms
//! are in [`relevo_core::veg`]; this module turns files into their inputs and
//! their results into files.

use crate::gdalio::{self, GridSpec};
use anyhow::{anyhow, bail, Context, Result};
use gdal::raster::GdalDataType;
use gdal::spatial_ref::SpatialRef;
use gdal::vector::{Feature, FieldValue, Geometry, LayerAccess, LayerOptions, OGRFieldType};
use gdal::DriverManager;
use relevo_core::geo::GeoTransform;
use relevo_core::raster::Raster;
use relevo_core::veg::classify::{Classifier, Label};
use relevo_core::veg::db::{self, VegObject};
use relevo_core::veg::detect::{detect, Placement};
use relevo_core::veg::samples::{self, Sample};
use relevo_core::veg::segment::{segment, SegmentParams, Segmentation};
use relevo_core::veg::Image;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// Every setting of vegetation extraction, as in REGION.toml's
/// `[vegetation.options]` and the `veg detect` flags.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VegOptions {
    /// Split-and-merge thresholds (see `relevo_core::veg::segment`).
    pub brightness_std: f32,
    pub chroma_std: f32,
    pub min_region_px: u32,
    pub min_block_px: u32,
    /// Smallest side, in pixels, of the window a region's signature covers.
    pub window_px: u32,
    /// Nearest learnt signatures per class a region's distance averages.
    pub neighbours: usize,
    /// The class that marks counter-examples (never vegetation).
    pub negative_class: String,
    /// How regions become objects.
    pub mode: Mode,
    /// Crowns: smallest distance between crown centres (m).
    pub crown_spacing_m: f64,
    /// Crowns: smallest crown radius kept (m).
    pub crown_min_radius_m: f64,
    /// Fill: objects per hectare of vegetation.
    pub density_per_ha: f64,
}

impl Default for VegOptions {
    fn default() -> Self {
        let s = SegmentParams::default();
        VegOptions {
            brightness_std: s.brightness_std,
            chroma_std: s.chroma_std,
            min_region_px: s.min_region_px,
            min_block_px: s.min_block_px,
            window_px: 8,
            neighbours: 3,
            negative_class: "other".into(),
            mode: Mode::Auto,
            crown_spacing_m: 2.5,
            crown_min_radius_m: 0.5,
            density_per_ha: 100.0,
        }
    }
}

/// Crowns in fine imagery, filled regions in coarse imagery.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Crowns when a pixel is at most 1 m, else fill.
    Auto,
    Crowns,
    Fill,
}

impl VegOptions {
    /// The split-and-merge thresholds among these options.
    pub fn segment_params(&self) -> SegmentParams {
        SegmentParams {
            brightness_std: self.brightness_std,
            chroma_std: self.chroma_std,
            min_region_px: self.min_region_px,
            min_block_px: self.min_block_px,
        }
    }

    /// The placement for pixels of `pixel_m` metres.
    pub fn placement(&self, pixel_m: f64) -> Result<Placement> {
        for (name, v) in [
            ("crown_spacing_m", self.crown_spacing_m),
            ("crown_min_radius_m", self.crown_min_radius_m),
            ("density_per_ha", self.density_per_ha),
        ] {
            if !(v.is_finite() && v > 0.0) {
                bail!("{name} must be positive, got {v}");
            }
        }
        let crowns = match self.mode {
            Mode::Auto => pixel_m <= 1.0,
            Mode::Crowns => true,
            Mode::Fill => false,
        };
        Ok(if crowns {
            Placement::Crowns {
                spacing_px: (self.crown_spacing_m / pixel_m) as f32,
                min_radius_px: (self.crown_min_radius_m / pixel_m) as f32,
            }
        } else {
            let spacing_m = (10_000.0 / self.density_per_ha).sqrt();
            Placement::Fill {
                spacing_px: (spacing_m / pixel_m) as f32,
                diameter_px: (spacing_m / pixel_m) as f32,
            }
        })
    }
}

/// An image ready for analysis, with where its pixels are.
pub struct VegImage {
    pub image: Image,
    /// Empty when the image is not georeferenced.
    pub crs_wkt: String,
    pub geotransform: Option<GeoTransform>,
    /// Ground size of a pixel in metres.
    pub pixel_m: f64,
    /// Pixels with data in every band; `None` when all have.
    pub valid: Option<Vec<bool>>,
}

impl VegImage {
    /// Read `bands` (1-based) of `path`; 8-bit data is kept, deeper data is
    /// stretched between the `stretch` percentiles (default 2, 98) to 8 bits.
    /// `pixel_m` sets the pixel size of an image that is not georeferenced.
    pub fn read(
        path: &Path,
        bands: Option<&[usize]>,
        stretch: Option<[f64; 2]>,
        pixel_m: Option<f64>,
    ) -> Result<VegImage> {
        let source = gdalio::open(path)?;
        let bands: Vec<usize> = match bands {
            Some(b) => b.to_vec(),
            None => (1..=source.bands.min(3)).collect(),
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
        let selected = source.read_window(
            0,
            0,
            source.width,
            source.height,
            Some(&bands),
            source.nodata,
        )?;
        let stretch = crate::prep::stretch_or_default(stretch, source.band_type);
        let ranges = crate::prep::stretch_ranges(&selected, stretch);
        let n = selected.cells();
        let mask = selected.valid_mask();
        let valid = mask.contains(&false).then_some(mask);
        let mut pixels = vec![0u8; n * bands.len()];
        for (b, &range) in ranges.iter().enumerate() {
            for (i, v) in selected.band(b).iter().enumerate() {
                pixels[i * bands.len() + b] = crate::prep::to_u8(*v, range);
            }
        }
        let image = Image::new(selected.width, selected.height, bands.len(), pixels)
            .map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let crs_wkt = match &source.srs {
            Some(srs) => crate::crs::to_wkt(srs)?,
            None => String::new(),
        };
        let ground = source.geotransform.map(|g| {
            let (w, h) = g.cell_size();
            let cell = w.abs().min(h.abs());
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
        Ok(VegImage {
            image,
            crs_wkt,
            geotransform: source.geotransform,
            pixel_m,
            valid,
        })
    }

    /// World coordinates of a point in pixel coordinates.
    pub fn to_world(&self, x: f64, y: f64) -> (f64, f64) {
        match &self.geotransform {
            Some(g) => g.apply(x, y),
            None => (x, y),
        }
    }
}

/// Read a samples file for a `width`×`height` image georeferenced by
/// `geotransform`: `.geojson`/`.json` polygons in the image CRS, else the
/// semicolon CSV of pixel rectangles. Errors name the file.
pub fn read_samples(
    path: &Path,
    geotransform: Option<GeoTransform>,
    w: usize,
    h: usize,
) -> Result<Vec<Sample>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read samples", path.display()))?;
    let is_json = matches!(
        path.extension().and_then(|e| e.to_str()),
        Some("geojson" | "json")
    );
    let parsed = if is_json {
        let geo = geotransform.unwrap_or(GeoTransform::IDENTITY);
        samples::parse_geojson(&text, |x, y| geo.invert(x, y).map(|(c, r)| [c, r]), w, h)
    } else {
        samples::parse_csv(&text, w, h)
    };
    parsed.map_err(|e| anyhow!("{}: {e}", path.display()))
}

/// Everything one extraction produced.
pub struct Extraction {
    pub segmentation: Segmentation,
    pub classifier: Classifier,
    pub labels: Vec<Label>,
    pub objects: Vec<VegObject>,
    pub report: Report,
}

/// What `veg detect --json` prints.
#[derive(Debug, Serialize)]
pub struct Report {
    pub width: usize,
    pub height: usize,
    pub pixel_m: f64,
    /// 1st to 99th percentile of brightness, in 8-bit units.
    pub brightness_span: f32,
    pub placement: Placement,
    pub leaves: usize,
    pub regions: usize,
    pub classes: Vec<ClassReport>,
    pub objects: usize,
    pub segment_ms: f64,
    pub classify_ms: f64,
    pub detect_ms: f64,
}

#[derive(Debug, Serialize)]
pub struct ClassReport {
    pub class: String,
    pub vegetation: bool,
    pub signatures: usize,
    pub regions: usize,
    pub pixels: u64,
    pub objects: usize,
}

/// Segment, learn from the samples, classify every region and place objects.
pub fn extract(image: &VegImage, samples: &[Sample], options: &VegOptions) -> Result<Extraction> {
    let placement = options.placement(image.pixel_m)?;
    let brightness_span = image.image.brightness_span();
    if brightness_span < 128.0 {
        tracing::warn!(
            brightness_span,
            "the image is low in contrast (1st to 99th percentile of brightness span {brightness_span:.0} of 255): \
             thresholds are in 8-bit units, so regions will be few and large; stretch it (--stretch, image.stretch)"
        );
    }
    let start = Instant::now();
    let segmentation = segment(&image.image, &options.segment_params())?;
    let segment_ms = start.elapsed().as_secs_f64() * 1e3;
    tracing::info!(
        leaves = segmentation.leaves,
        regions = segmentation.regions.len(),
        segment_ms,
        "split and merge"
    );
    let start = Instant::now();
    let classifier = Classifier::train(
        &image.image,
        &segmentation,
        samples,
        options.window_px,
        options.neighbours,
    )?;
    let labels = classifier.classify_regions(&image.image, &segmentation);
    let classify_ms = start.elapsed().as_secs_f64() * 1e3;
    let vegetation: Vec<bool> = classifier
        .classes
        .iter()
        .map(|c| *c != options.negative_class)
        .collect();
    if !vegetation.iter().any(|&v| v) {
        bail!(
            "every sample is of the negative class {:?}: mark some vegetation",
            options.negative_class
        );
    }
    let start = Instant::now();
    let found = detect(
        &image.image,
        &segmentation,
        &labels,
        &vegetation,
        image.valid.as_deref(),
        placement,
    );
    let detect_ms = start.elapsed().as_secs_f64() * 1e3;
    let objects: Vec<VegObject> = found
        .iter()
        .enumerate()
        .map(|(k, o)| {
            let (x, y) = image.to_world(o.x, o.y);
            VegObject {
                id: k as u64 + 1,
                x,
                y,
                class: classifier.classes[o.class].clone(),
                size: o.size_px as f64 * image.pixel_m,
                score: o.score,
            }
        })
        .collect();
    let signatures = classifier.signatures_per_class();
    let classes = classifier
        .classes
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let of_class = || {
                labels
                    .iter()
                    .zip(&segmentation.regions)
                    .filter(move |(l, _)| l.class == c)
            };
            ClassReport {
                class: name.clone(),
                vegetation: vegetation[c],
                signatures: signatures[c],
                regions: of_class().count(),
                pixels: of_class().map(|(_, r)| r.pixels as u64).sum(),
                objects: found.iter().filter(|o| o.class == c).count(),
            }
        })
        .collect();
    let report = Report {
        width: image.image.width,
        height: image.image.height,
        pixel_m: image.pixel_m,
        brightness_span,
        placement,
        leaves: segmentation.leaves,
        regions: segmentation.regions.len(),
        classes,
        objects: objects.len(),
        segment_ms,
        classify_ms,
        detect_ms,
    };
    Ok(Extraction {
        segmentation,
        classifier,
        labels,
        objects,
        report,
    })
}

/// Write the database atomically.
pub fn write_csv(path: &Path, objects: &[VegObject]) -> Result<()> {
    gdalio::write_atomic(path, db::to_csv(objects).as_bytes())
}

/// Write the objects as points of a GeoPackage layer `vegetation` (QGIS,
/// GDAL and most GIS open it), through a partial file renamed into place.
pub fn write_gpkg(path: &Path, objects: &[VegObject], crs_wkt: &str) -> Result<()> {
    let partial = gdalio::partial_path(path).with_extension("gpkg");
    let _ = std::fs::remove_file(&partial);
    // Fixed timestamps make the file depend on its content only.
    gdal::config::set_config_option("OGR_CURRENT_DATE", "2000-01-01T00:00:00.000Z")?;
    let result = (|| -> Result<()> {
        let driver = DriverManager::get_driver_by_name("GPKG")?;
        let mut dataset = driver
            .create_vector_only(&partial)
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
    })();
    gdal::config::clear_config_option("OGR_CURRENT_DATE")?;
    let result = result.and_then(|()| {
        std::fs::rename(&partial, path)
            .with_context(|| format!("{}: cannot move into place", path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&partial);
    }
    result
}

/// Write the labels as a two-band UInt32 GeoTIFF: band 1 the region of each
/// pixel (from 1), band 2 its class (1-based in the samples' order).
pub fn write_labels(path: &Path, image: &VegImage, extraction: &Extraction) -> Result<()> {
    let seg = &extraction.segmentation;
    let regions = seg.labels.iter().map(|&r| r as f64 + 1.0);
    let classes = seg
        .labels
        .iter()
        .map(|&r| extraction.labels[r as usize].class as f64 + 1.0);
    let data: Vec<f64> = regions.chain(classes).collect();
    let raster = Raster::from_data(seg.width, seg.height, 2, data);
    let grid = GridSpec {
        crs_wkt: image.crs_wkt.clone(),
        geotransform: image.geotransform.unwrap_or(GeoTransform::IDENTITY),
        width: seg.width,
        height: seg.height,
    };
    gdalio::write_geotiff(path, &raster, &grid, GdalDataType::UInt32, None)
}

/// An RGBA picture for people: the image, vegetation regions tinted by class,
/// region borders darkened, and each object as a red ring of its size (a
/// single red pixel when smaller than 3 pixels, as in fill mode on coarse
/// imagery).
pub fn overlay(image: &VegImage, extraction: &Extraction, negative: &str) -> Vec<u8> {
    const TINTS: [[u8; 3]; 6] = [
        [255, 220, 0],
        [255, 60, 200],
        [0, 220, 255],
        [255, 120, 0],
        [120, 255, 120],
        [200, 120, 255],
    ];
    let img = &image.image;
    let seg = &extraction.segmentation;
    let (w, h) = (img.width, img.height);
    let mut rgba = vec![255u8; w * h * 4];
    let tint_of = |class: usize| {
        (extraction.classifier.classes[class] != negative).then(|| TINTS[class % TINTS.len()])
    };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let px = &img.pixels[i * img.bands..(i + 1) * img.bands];
            let mut rgb = [px[0], px[1.min(img.bands - 1)], px[2.min(img.bands - 1)]];
            let region = seg.labels[i];
            if let Some(t) = tint_of(extraction.labels[region as usize].class) {
                for c in 0..3 {
                    rgb[c] = ((rgb[c] as u16 * 3 + t[c] as u16) / 4) as u8;
                }
            }
            let border = (x + 1 < w && seg.labels[i + 1] != region)
                || (y + 1 < h && seg.labels[i + w] != region);
            if border {
                rgb = rgb.map(|v| v / 2);
            }
            rgba[i * 4..i * 4 + 3].copy_from_slice(&rgb);
        }
    }
    for o in &extraction.objects {
        let (px, py) = match &image.geotransform {
            Some(g) => g.invert(o.x, o.y).unwrap_or((o.x, o.y)),
            None => (o.x, o.y),
        };
        let r = o.size / image.pixel_m / 2.0;
        if r < 1.5 {
            if px >= 0.0 && py >= 0.0 && (px as usize) < w && (py as usize) < h {
                let i = (py as usize * w + px as usize) * 4;
                rgba[i..i + 3].copy_from_slice(&[255, 0, 0]);
            }
            continue;
        }
        let steps = (r * 8.0).ceil() as usize;
        for s in 0..steps {
            let a = s as f64 / steps as f64 * std::f64::consts::TAU;
            let (x, y) = (px + r * a.cos(), py + r * a.sin());
            if x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h {
                let i = (y as usize * w + x as usize) * 4;
                rgba[i..i + 3].copy_from_slice(&[255, 0, 0]);
            }
        }
    }
    rgba
}
