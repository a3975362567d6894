//! The cross-image protocol for vegetation extraction: tune the options on
//! one annotated image, report on the other with those options, both ways;
//! then the shipped defaults on both, and on contrast-changed copies, with
//! absolute thresholds and with thresholds scaled to the samples' contrast.
//!
//! Tuning is a grid search over the options people would reach for first
//! (the two split-and-merge thresholds, the neighbours a class distance
//! averages, the crown spacing); the best F1 on the tuning image wins, ties
//! going to the grid point nearest the shipped defaults.

use crate::measure::emit;
use anyhow::Result;
use relevo_core::veg::eval::{self, Evaluation};
use relevo_core::veg::pipeline::{extract, Contrast, VegImage, VegOptions};
use relevo_core::veg::samples::{read_file as read_samples, Sample};
use relevo_core::veg::Image;
use serde_json::json;
use std::path::Path;

/// An annotated image with the samples a user marked on it.
pub struct Annotated {
    pub name: &'static str,
    pub image: VegImage,
    pub samples: Vec<Sample>,
    pub truth: Vec<[f64; 4]>,
}

impl Annotated {
    fn score(&self, options: &VegOptions) -> Result<Evaluation> {
        score(&self.image, &self.samples, &self.truth, options)
    }
}

fn score(
    image: &VegImage,
    samples: &[Sample],
    truth: &[[f64; 4]],
    options: &VegOptions,
) -> Result<Evaluation> {
    let found = extract(image, samples, options)?;
    let points: Vec<(f64, f64, f32)> = found.objects.iter().map(|o| (o.x, o.y, o.score)).collect();
    Ok(eval::evaluate(&points, truth))
}

/// The NEON crops of the shared `trees/` folder with their committed samples.
pub fn annotated(repo: &Path, data: &Path) -> Result<Vec<Annotated>> {
    let crops = [
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
    ];
    crops
        .into_iter()
        .map(|(name, stem, samples)| {
            let image = relevo::veg_io::read_image(
                &data.join(format!("{stem}.png")),
                None,
                None,
                Some(0.1),
            )?;
            let (w, h) = (image.image.width, image.image.height);
            let samples = read_samples(&repo.join(samples), None, w, h)?;
            let truth = eval::bounds(&eval::parse_voc(&std::fs::read_to_string(
                data.join(format!("{stem}.xml")),
            )?)?);
            Ok(Annotated {
                name,
                image,
                samples,
                truth,
            })
        })
        .collect()
}

/// The grid the tuning searches over `spacings` (`None`: learnt from the
/// marked crowns), each point with its distance to the defaults in grid
/// steps.
fn grid(spacings: &[Option<f64>]) -> Vec<(VegOptions, usize)> {
    let defaults = VegOptions::default();
    let brightness = [20.0f32, 24.0, 28.0, 32.0, 36.0];
    let chroma = [4.0f32, 5.0, 6.0, 7.0, 8.0, 9.0];
    let neighbours = [1usize, 3, 5];
    // Grid steps between `v` and `default` along `values`.
    let steps = |values: &[f64], v: f64, default: f64| {
        let at = |x: f64| {
            values
                .iter()
                .position(|&y| (y - x).abs() < 1e-6)
                .unwrap_or(values.len())
        };
        at(v).abs_diff(at(default))
    };
    let mut points = Vec::new();
    for &b in &brightness {
        for &c in &chroma {
            for &n in &neighbours {
                for &s in spacings {
                    let options = VegOptions {
                        brightness_std: b,
                        chroma_std: c,
                        neighbours: n,
                        crown_spacing_m: s,
                        ..defaults.clone()
                    };
                    let distance =
                        steps(
                            &brightness.map(f64::from),
                            b as f64,
                            defaults.brightness_std as f64,
                        ) + steps(&chroma.map(f64::from), c as f64, defaults.chroma_std as f64)
                            + steps(
                                &neighbours.map(|n| n as f64),
                                n as f64,
                                defaults.neighbours as f64,
                            )
                            + usize::from(s != defaults.crown_spacing_m);
                    points.push((options, distance));
                }
            }
        }
    }
    points
}

/// `v' = gain·v + offset`, clipped to 0..255, on every band.
fn contrast_changed(image: &VegImage, gain: f32, offset: f32) -> Result<VegImage> {
    let i = &image.image;
    let pixels = i
        .pixels
        .iter()
        .map(|&v| (gain * v as f32 + offset).round().clamp(0.0, 255.0) as u8)
        .collect();
    Ok(VegImage {
        image: Image::new(i.width, i.height, i.bands, pixels)?,
        crs_wkt: image.crs_wkt.clone(),
        geotransform: image.geotransform,
        pixel_m: image.pixel_m,
        valid: image.valid.clone(),
    })
}

pub fn run(repo: &Path, data: &Path, json_lines: bool) -> Result<()> {
    let images = annotated(repo, data)?;
    // The crown spacing learnt from the samples (the default), then also
    // tuned by hand.
    for spacings in [vec![None], vec![Some(2.0), Some(2.5), Some(3.0)]] {
        protocol(&images, &grid(&spacings), json_lines)?;
    }
    defaults(&images, json_lines)
}

/// Tune on each image over `grid`, report on the other.
fn protocol(images: &[Annotated], grid: &[(VegOptions, usize)], json_lines: bool) -> Result<()> {
    let describe = |o: &VegOptions| {
        format!(
            "brightness {:.0}, chroma {:.0}, neighbours {}, spacing {}",
            o.brightness_std,
            o.chroma_std,
            o.neighbours,
            o.crown_spacing_m
                .map_or("learnt".into(), |s| format!("{s:.1} m"))
        )
    };
    // Every grid point on every image, once.
    let mut f1 = vec![vec![0.0f64; grid.len()]; images.len()];
    for (i, image) in images.iter().enumerate() {
        for (g, (options, _)) in grid.iter().enumerate() {
            f1[i][g] = image.score(options)?.f1;
            if json_lines {
                emit(
                    true,
                    json!({"bench": "veg-protocol-grid", "image": image.name, "f1": f1[i][g],
                           "brightness_std": options.brightness_std, "chroma_std": options.chroma_std,
                           "neighbours": options.neighbours, "crown_spacing_m": options.crown_spacing_m}),
                    String::new(),
                );
            }
        }
    }
    for (t, tuned_on) in images.iter().enumerate() {
        let best = (0..grid.len())
            .max_by(|&a, &b| {
                f1[t][a]
                    .total_cmp(&f1[t][b])
                    .then(grid[b].1.cmp(&grid[a].1))
            })
            .unwrap_or(0);
        let options = &grid[best].0;
        for (r, reported_on) in images.iter().enumerate() {
            if r == t {
                continue;
            }
            let e = reported_on.score(options)?;
            // How much of the grid would have done as well on the held-out image.
            let share_at_least =
                f1[r].iter().filter(|&&v| v >= 0.6).count() as f64 / grid.len() as f64;
            emit(
                json_lines,
                json!({"bench": "veg-protocol", "tuned_on": tuned_on.name, "tuned_f1": f1[t][best],
                       "reported_on": reported_on.name, "held_out": e,
                       "options": {"brightness_std": options.brightness_std, "chroma_std": options.chroma_std,
                                   "neighbours": options.neighbours, "crown_spacing_m": options.crown_spacing_m},
                       "grid_points": grid.len(), "grid_share_f1_at_least_0_6_on_held_out": share_at_least}),
                format!(
                    "veg protocol: tuned on {} (F1 {:.3} with {}), reported on {}: P {:.3} R {:.3} F1 {:.3} | {:.0} % of the {} grid points reach F1 0.6 on {}",
                    tuned_on.name, f1[t][best], describe(options), reported_on.name,
                    e.precision, e.recall, e.f1, share_at_least * 100.0, grid.len(), reported_on.name
                ),
            );
        }
    }
    Ok(())
}

/// The shipped defaults, on each image and on contrast-changed copies.
fn defaults(images: &[Annotated], json_lines: bool) -> Result<()> {
    // The shipped defaults, on each image and on contrast-changed copies:
    // a dull one (half the contrast) and a stretched one (1.4×, clipped);
    // with absolute thresholds and with thresholds scaled to the samples.
    for contrast in [Contrast::Absolute, Contrast::Samples] {
        let options = VegOptions {
            contrast,
            ..VegOptions::default()
        };
        for image in images {
            let e = image.score(&options)?;
            let mut copies = Vec::new();
            for (what, gain, offset) in [("dull", 0.5f32, 64.0f32), ("stretched", 1.4, -40.0)] {
                let copy = contrast_changed(&image.image, gain, offset)?;
                let c = score(&copy, &image.samples, &image.truth, &options)?;
                copies.push((what, c));
            }
            emit(
                json_lines,
                json!({"bench": "veg-defaults", "image": image.name, "contrast": contrast, "defaults": e,
                       "dull": copies[0].1, "stretched": copies[1].1}),
                format!(
                    "veg defaults ({contrast:?} thresholds) on {}: P {:.3} R {:.3} F1 {:.3} | dull copy F1 {:.3}, stretched copy F1 {:.3}",
                    image.name, e.precision, e.recall, e.f1, copies[0].1.f1, copies[1].1.f1
                ),
            );
        }
    }
    Ok(())
}
