//! The leave-one-image-out protocol for vegetation extraction: over the
//! annotated images of the shared `trees/` folder, each with the samples a
//! user marked on it, the options are chosen on the other images (a grid
//! of the settings people reach for first; the best mean F1 at IoU 0.4,
//! ties to the grid point nearest the defaults) and reported on the image
//! left out, beside the shipped defaults and the excess-green +
//! local-maximum baseline (its crown spacing chosen the same way); then the
//! simulated user's correction loop with the defaults on every image, the
//! defaults with marks drawn at random from the truth instead of the
//! person's, and the defaults on contrast-changed copies.

use crate::measure::emit;
use anyhow::Result;
use relevo_core::veg::eval;
use relevo_core::veg::pipeline::{Contrast, VegImage, VegOptions};
use relevo_core::veg::protocol::{self, Annotated, Scores};
use relevo_core::veg::samples::{self, Sample};
use relevo_core::veg::Image;
use serde_json::json;
use std::path::Path;

pub fn run(repo: &Path, data: &Path, rounds_dir: Option<&Path>, json_lines: bool) -> Result<()> {
    let images = relevo::veg_io::annotated_crops(repo, data)?;
    let held_out = protocol::leave_one_out(&images, &protocol::grid())?;
    let f = |e: &eval::Evaluation| format!("P {:.3} R {:.3} F1 {:.3}", e.precision, e.recall, e.f1);
    for h in &held_out {
        emit(
            json_lines,
            json!({"bench": "veg-leave-one-out", "held_out": h}),
            format!(
                "veg leave-one-out {}: chosen on the others (F1 {:.3}: brightness {:.0}, chroma {:.0}, neighbours {}) IoU 0.4 {} | IoU 0.5 {} | defaults IoU 0.4 {} | excess green + local maximum ({:.1} m) IoU 0.4 {}",
                h.image, h.chosen_on_f1, h.options.brightness_std, h.options.chroma_std, h.options.neighbours,
                f(&h.chosen.iou_0_4), f(&h.chosen.iou_0_5), f(&h.defaults.iou_0_4),
                h.baseline_spacing_m, f(&h.baseline.iou_0_4)
            ),
        );
    }
    let spread = |v: Vec<f64>| {
        let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
        let (lo, hi) = v
            .iter()
            .fold((f64::MAX, f64::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        json!({"mean": mean, "min": lo, "max": hi})
    };
    emit(
        json_lines,
        json!({"bench": "veg-leave-one-out-summary",
               "chosen_f1_iou_0_4": spread(held_out.iter().map(|h| h.chosen.iou_0_4.f1).collect()),
               "chosen_f1_iou_0_5": spread(held_out.iter().map(|h| h.chosen.iou_0_5.f1).collect()),
               "defaults_f1_iou_0_4": spread(held_out.iter().map(|h| h.defaults.iou_0_4.f1).collect()),
               "baseline_f1_iou_0_4": spread(held_out.iter().map(|h| h.baseline.iou_0_4.f1).collect())}),
        format!(
            "veg leave-one-out F1 at IoU 0.4 over {} images: chosen {} | defaults {} | baseline {}",
            held_out.len(),
            spread(held_out.iter().map(|h| h.chosen.iou_0_4.f1).collect()),
            spread(held_out.iter().map(|h| h.defaults.iou_0_4.f1).collect()),
            spread(held_out.iter().map(|h| h.baseline.iou_0_4.f1).collect())
        ),
    );
    for image in &images {
        let rounds = protocol::correction_loop(image, &VegOptions::default(), 2)?;
        if let Some(dir) = rounds_dir {
            std::fs::create_dir_all(dir)?;
            let (w, h) = (image.image.image.width, image.image.image.height);
            let mut marks = image.samples.clone();
            for r in &rounds {
                marks.extend(
                    r.added
                        .iter()
                        .map(|(class, b)| Sample::rectangle(class, *b)),
                );
                let path = dir.join(format!("{}_round{}.csv", image.name, r.round));
                std::fs::write(&path, samples::to_csv(&marks, w, h))?;
            }
        }
        let line: Vec<String> = rounds
            .iter()
            .map(|r| {
                format!(
                    "round {} ({} marks): IoU 0.4 {}, by centre F1 {:.3}, {} marks contradicted",
                    r.round,
                    r.marks,
                    f(&r.scores.iou_0_4),
                    r.scores.centre.f1,
                    r.marks_contradicted
                )
            })
            .collect();
        emit(
            json_lines,
            json!({"bench": "veg-correction-loop", "image": image.name, "rounds": rounds}),
            format!("veg correction loop {}: {}", image.name, line.join(" | ")),
        );
    }
    let defaults = VegOptions::default();
    for image in &images {
        if let Some(dir) = rounds_dir {
            let (w, h) = (image.image.image.width, image.image.image.height);
            for seed in 0..protocol::DRAWN_SETS {
                let marks = protocol::drawn_marks(image, seed, &defaults.negative_class);
                let path = dir.join(format!("{}_drawn{seed}.csv", image.name));
                std::fs::write(&path, samples::to_csv(&marks, w, h))?;
            }
        }
        let sets = protocol::with_drawn_marks(image, &defaults)?;
        let f1: Vec<f64> = sets.iter().map(|s| s.iou_0_4.f1).collect();
        let text: Vec<String> = f1.iter().map(|v| format!("{v:.3}")).collect();
        let f1 = spread(f1);
        let [mean, low, high] = ["mean", "min", "max"].map(|k| f1[k].as_f64().unwrap_or(f64::NAN));
        emit(
            json_lines,
            json!({"bench": "veg-drawn-marks", "image": image.name, "iou": 0.4,
                   "f1": f1, "sets": sets}),
            format!(
                "veg drawn marks {} ({} sets of {} crowns and {} counter-examples): F1 at IoU 0.4 mean {mean:.3} ({low:.3}–{high:.3}): {}",
                image.name,
                protocol::DRAWN_SETS,
                protocol::DRAWN_OF_EACH,
                protocol::DRAWN_OF_EACH,
                text.join(", ")
            ),
        );
    }
    defaults_on_contrast_changes(&images, json_lines)
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

/// Contrast gains applied about each image's mean value: images duller and
/// harsher than the annotated crops, as other flights give.
const GAINS_ABOUT_THE_MEAN: [f64; 4] = [0.7, 0.85, 1.15, 1.3];

/// The shipped defaults on each image and on contrast-changed copies — a
/// dull one (half the contrast), a stretched one (1.4×, clipped) and the
/// contrast scaled by each of [`GAINS_ABOUT_THE_MEAN`] about the image's
/// mean — with absolute thresholds and with thresholds scaled to the
/// samples (the default where crowns are placed).
fn defaults_on_contrast_changes(images: &[Annotated], json_lines: bool) -> Result<()> {
    for contrast in [Contrast::Absolute, Contrast::Samples] {
        let options = VegOptions {
            contrast,
            ..VegOptions::default()
        };
        for image in images {
            let e = Scores::of(&image.detect(&image.samples, &options)?, &image.truth).iou_0_4;
            let on_copy = |gain: f32, offset: f32| -> Result<eval::Evaluation> {
                let copy = Annotated {
                    name: image.name.clone(),
                    image: contrast_changed(&image.image, gain, offset)?,
                    samples: image.samples.clone(),
                    truth: image.truth.clone(),
                    truth_classes: image.truth_classes.clone(),
                };
                Ok(Scores::of(&copy.detect(&copy.samples, &options)?, &copy.truth).iou_0_4)
            };
            let copies = [on_copy(0.5, 64.0)?, on_copy(1.4, -40.0)?];
            let pixels = &image.image.image.pixels;
            let mean = pixels.iter().map(|&v| v as f64).sum::<f64>() / pixels.len().max(1) as f64;
            let about_the_mean = GAINS_ABOUT_THE_MEAN
                .iter()
                .map(|&g| Ok((g, on_copy(g as f32, (mean * (1.0 - g)) as f32)?)))
                .collect::<Result<Vec<_>>>()?;
            let text: Vec<String> = about_the_mean
                .iter()
                .map(|(g, e)| format!("×{g:.2} F1 {:.3}", e.f1))
                .collect();
            emit(
                json_lines,
                json!({"bench": "veg-defaults", "image": image.name, "contrast": contrast, "iou": 0.4,
                       "defaults": e, "dull": copies[0], "stretched": copies[1]}),
                format!(
                    "veg defaults ({contrast:?} thresholds) on {} at IoU 0.4: P {:.3} R {:.3} F1 {:.3} | dull copy F1 {:.3}, stretched copy F1 {:.3}",
                    image.name, e.precision, e.recall, e.f1, copies[0].f1, copies[1].f1
                ),
            );
            emit(
                json_lines,
                json!({"bench": "veg-contrast-gains", "image": image.name, "contrast": contrast, "iou": 0.4,
                       "mean_value": mean,
                       "gains": about_the_mean.iter().map(|(g, e)| json!({"gain": g, "scores": e})).collect::<Vec<_>>()}),
                format!(
                    "veg contrast about the mean ({contrast:?} thresholds) on {} at IoU 0.4: {}",
                    image.name,
                    text.join(", ")
                ),
            );
        }
    }
    Ok(())
}
