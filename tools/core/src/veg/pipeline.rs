//! The whole extraction on one image, as `relevo veg detect`, `relevo prep`
//! and the viewer run it: split-and-merge, signatures learnt from the
//! samples, classification of every region and object placement, with a
//! report of what was found and an overlay for people to check it.

use super::classify::{Classifier, Label};
use super::db::VegObject;
use super::detect::{detect, Placement};
use super::samples::Sample;
use super::segment::{segment, SegmentParams, Segmentation};
use super::Image;
use crate::geo::GeoTransform;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
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
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
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
                return Err(Error::Input(format!("{name} must be positive, got {v}")));
            }
        }
        let crowns = match self.mode {
            Mode::Auto => pixel_m <= 1.0,
            Mode::Crowns => true,
            Mode::Fill => false,
        };
        // Crowns closer than a pixel cannot be told apart in the image, and
        // filled objects denser than one per square metre are not
        // vegetation; either would make the object count grow without bound.
        if crowns && self.crown_spacing_m < pixel_m {
            return Err(Error::Input(format!(
                "crown_spacing_m: crowns {:.3} m apart are closer than one {pixel_m:.3} m pixel",
                self.crown_spacing_m
            )));
        }
        if !crowns && self.density_per_ha > MAX_DENSITY_PER_HA {
            return Err(Error::Input(format!(
                "density_per_ha: {} objects per ha is denser than one per square metre \
                 (at most {MAX_DENSITY_PER_HA})",
                self.density_per_ha
            )));
        }
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

/// Densest fill a vegetation class may ask for: one object per square
/// metre.
pub const MAX_DENSITY_PER_HA: f64 = 10_000.0;

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
    /// The RGB of a drape image (RGBA8, alpha 255 where it has data) as the
    /// bundle shows it, georeferenced by `geotransform` in `crs_wkt`.
    pub fn from_drape(
        rgba: &[u8],
        width: usize,
        height: usize,
        geotransform: GeoTransform,
        crs_wkt: &str,
    ) -> Result<VegImage> {
        let pixels: Vec<u8> = rgba
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        let valid: Vec<bool> = rgba.chunks_exact(4).map(|p| p[3] == 255).collect();
        let (cell_w, cell_h) = geotransform.cell_size();
        Ok(VegImage {
            image: Image::new(width, height, 3, pixels)?,
            crs_wkt: crs_wkt.to_string(),
            geotransform: Some(geotransform),
            pixel_m: cell_w.abs().min(cell_h.abs()),
            valid: valid.iter().any(|v| !v).then_some(valid),
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

/// Progress and cancellation of an extraction running elsewhere (a
/// viewer's background thread): the stages done out of [`Watch::STAGES`]
/// (split-and-merge, classification, placement), and a flag that stops the
/// extraction at the next stage boundary.
#[derive(Debug, Default)]
pub struct Watch {
    cancelled: std::sync::atomic::AtomicBool,
    stages_done: std::sync::atomic::AtomicUsize,
}

impl Watch {
    pub const STAGES: usize = 3;

    /// Ask the extraction to stop at the next stage boundary.
    pub fn cancel(&self) {
        self.cancelled
            .store(true, std::sync::atomic::Ordering::Relaxed);
    }

    /// Share of the stages done, 0–1.
    pub fn fraction(&self) -> f32 {
        self.stages_done.load(std::sync::atomic::Ordering::Relaxed) as f32 / Self::STAGES as f32
    }

    /// A stage is done: count it, and stop if cancelled.
    fn stage_done(&self) -> Result<()> {
        self.stages_done
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        if self.cancelled.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(Error::Input("the extraction was cancelled".into()));
        }
        Ok(())
    }
}

/// Segment, learn from the samples, classify every region and place objects.
pub fn extract(image: &VegImage, samples: &[Sample], options: &VegOptions) -> Result<Extraction> {
    extract_watched(image, samples, options, &Watch::default())
}

/// [`extract`], reporting each stage to `watch` and stopping when it is
/// cancelled.
pub fn extract_watched(
    image: &VegImage,
    samples: &[Sample],
    options: &VegOptions,
    watch: &Watch,
) -> Result<Extraction> {
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
    watch.stage_done()?;
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
    watch.stage_done()?;
    let vegetation: Vec<bool> = classifier
        .classes
        .iter()
        .map(|c| *c != options.negative_class)
        .collect();
    if !vegetation.iter().any(|&v| v) {
        return Err(Error::Input(format!(
            "every sample is of the negative class {:?}: mark some vegetation",
            options.negative_class
        )));
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
    watch.stage_done()?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testdata;
    use crate::veg::{eval, samples};

    /// The NEON crop at 0.1 m with its ten marked samples.
    fn soap_061() -> (VegImage, Vec<Sample>) {
        let image = VegImage {
            image: testdata::soap_061(),
            crs_wkt: String::new(),
            geotransform: None,
            pixel_m: 0.1,
            valid: None,
        };
        let marks = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../data/trees/soap_061_samples.csv");
        let samples = samples::read_file(&marks, None, 400, 400).unwrap();
        (image, samples)
    }

    #[test]
    fn crowns_found_on_a_real_image_score_against_its_annotations() {
        let (image, samples) = soap_061();
        let options = VegOptions::default();
        let found = extract(&image, &samples, &options).unwrap();
        let truth = std::fs::read_to_string(testdata::path("SOAP_061.xml")).unwrap();
        let boxes = eval::parse_voc(&truth).unwrap();
        let points: Vec<(f64, f64, f32)> =
            found.objects.iter().map(|o| (o.x, o.y, o.score)).collect();
        let e = eval::evaluate(&points, &eval::bounds(&boxes));
        eprintln!(
            "SOAP_061: P {:.3} R {:.3} F1 {:.3}",
            e.precision, e.recall, e.f1
        );
        // Regression floor under the recorded 0.627 (docs/benchmarks.md).
        assert!(e.f1 >= 0.60, "F1 {}", e.f1);
        // Every object sits on a region of a vegetation class, inside the image.
        let seg = &found.segmentation;
        for o in &found.objects {
            let (x, y) = (o.x as usize, o.y as usize);
            assert!(x < 400 && y < 400);
            let class = found.labels[seg.labels[y * 400 + x] as usize].class;
            assert_ne!(found.classifier.classes[class], options.negative_class);
        }
        assert_eq!(found.report.objects, found.objects.len());
        // The overlay is the image's size and marks the objects in red.
        let rgba = overlay(&image, &found, &options.negative_class);
        assert_eq!(rgba.len(), 400 * 400 * 4);
        assert!(rgba.chunks_exact(4).any(|p| p[..3] == [255, 0, 0]));
    }

    #[test]
    fn only_counter_examples_are_refused() {
        let (image, samples) = soap_061();
        let others: Vec<Sample> = samples.into_iter().filter(|s| s.class == "other").collect();
        let error = extract(&image, &others, &VegOptions::default()).err();
        assert!(error.is_some_and(|e| e.to_string().contains("mark some vegetation")));
    }

    #[test]
    fn a_watch_follows_the_stages_and_cancels_at_the_next() {
        let (image, samples) = soap_061();
        let watch = Watch::default();
        let whole = extract_watched(&image, &samples, &VegOptions::default(), &watch).unwrap();
        assert_eq!(watch.fraction(), 1.0);
        assert_eq!(
            whole.objects,
            extract(&image, &samples, &VegOptions::default())
                .unwrap()
                .objects
        );
        let cancelled = Watch::default();
        cancelled.cancel();
        let Err(e) = extract_watched(&image, &samples, &VegOptions::default(), &cancelled) else {
            panic!("a cancelled extraction finished");
        };
        assert!(e.to_string().contains("cancelled"), "{e}");
        assert_eq!(
            cancelled.fraction(),
            1.0 / Watch::STAGES as f32,
            "stopped after the first stage"
        );
    }
}
