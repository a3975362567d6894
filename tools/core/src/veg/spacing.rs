//! The crown spacing learnt from the marked crowns. A person marks single
//! crowns, so the distance kept between crown centres should be the
//! smallest at which no marked crown yields two centres: smaller, one crown
//! with several bright branches (a dead crown, a broadleaf) splits; larger,
//! neighbouring crowns merge. Each marked crown is cut with its
//! neighbourhood from the segmentation it was learnt on, classified with the
//! learnt classifier, and crowns are placed on it at every candidate spacing.
//!
//! The same marked crowns tell how large crowns are, and what they look
//! like (their brightness pattern: [`crown_template`]).

use super::classify::{Classifier, Label};
use super::detect::{detect, DetectBuffers, Object, Placement};
use super::haar::region_signature;
use super::samples::Sample;
use super::segment::{SegmentSteps, Segmentation};
use super::template::CrownTemplate;
use super::Image;

/// The spacings tried (m), in increasing order.
pub const CROWN_SPACINGS_M: [f64; 5] = [1.0, 1.5, 2.0, 2.5, 3.0];

/// The largest spacing that may be learnt (m): tiles take their margins
/// from it before it is known.
pub const MAX_CROWN_SPACING_M: f64 = CROWN_SPACINGS_M[CROWN_SPACINGS_M.len() - 1];

/// A marked crown with the neighbourhood crown placement looks at.
pub struct MarkedCrown {
    /// Which of the extraction's samples it is (an index into them).
    sample_index: usize,
    image: Image,
    valid: Option<Vec<bool>>,
    /// Every pixel's region as an index into `signatures` (no region
    /// descriptions: placement needs only the labels).
    segmentation: Segmentation,
    /// The signature of each region the neighbourhood holds.
    signatures: Vec<Vec<f32>>,
    /// The mark, in the neighbourhood's pixels.
    sample: Sample,
}

impl MarkedCrown {
    /// Cut `sample` (in the pixels of `image`; the extraction's sample
    /// number `sample_index`) with `margin_px` around it from `image`, its
    /// validity and its `segmentation`; region signatures over windows of
    /// at least `window_px` (as the classifier takes them).
    pub fn cut(
        image: &Image,
        valid: Option<&[bool]>,
        segmentation: &Segmentation,
        (sample_index, sample): (usize, &Sample),
        margin_px: usize,
        window_px: u32,
    ) -> MarkedCrown {
        let (w, h) = (image.width, image.height);
        let [x0, y0, x1, y1] = sample.pixel_bounds(w, h);
        let (x0, y0) = (x0.saturating_sub(margin_px), y0.saturating_sub(margin_px));
        let (x1, y1) = ((x1 + margin_px).min(w), (y1 + margin_px).min(h));
        let mut regions: Vec<u32> = Vec::new();
        let mut local_of = std::collections::HashMap::new();
        let mut labels = Vec::with_capacity((x1 - x0) * (y1 - y0));
        let mut window_valid = valid.map(|_| Vec::with_capacity(labels.capacity()));
        for y in y0..y1 {
            for x in x0..x1 {
                let region = segmentation.labels[y * w + x];
                let local = *local_of.entry(region).or_insert_with(|| {
                    regions.push(region);
                    regions.len() as u32 - 1
                });
                labels.push(local);
                if let (Some(out), Some(v)) = (window_valid.as_mut(), valid) {
                    out.push(v[y * w + x]);
                }
            }
        }
        let signatures = regions
            .iter()
            .map(|&r| region_signature(image, segmentation, r as usize, window_px))
            .collect();
        MarkedCrown {
            sample_index,
            image: image.window([x0, y0, x1, y1], Vec::new()),
            valid: window_valid,
            segmentation: Segmentation {
                width: x1 - x0,
                height: y1 - y0,
                labels,
                regions: Vec::new(),
                leaves: 0,
                steps: SegmentSteps::default(),
            },
            signatures,
            sample: sample.translated(-(x0 as f64), -(y0 as f64)),
        }
    }

    /// The crowns placed inside the mark, with the regions' `classes`.
    fn crowns(&self, classes: &[Label], vegetation: &[bool], placement: &Placement) -> Vec<Object> {
        detect(
            &self.image,
            &self.segmentation,
            classes,
            vegetation,
            self.valid.as_deref(),
            placement,
            [0, 0],
            &mut DetectBuffers::default(),
        )
        .into_iter()
        .filter(|o| self.sample.contains(o.x, o.y))
        .collect()
    }
}

/// Each marked crown's regions classified by `classifier`.
fn classified(crowns: &[MarkedCrown], classifier: &Classifier) -> Vec<Vec<Label>> {
    crowns
        .iter()
        .map(|c| {
            c.signatures
                .iter()
                .map(|s| classifier.classify(s))
                .collect()
        })
        .collect()
}

/// The crown spacing learnt, and the marked crown that kept it from being
/// closer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearntSpacing {
    pub spacing_m: f64,
    /// The marked crown holding the most centres at the largest spacing
    /// tried that split a marked crown: the spacing just before the one
    /// learnt, or the one learnt itself when every spacing splits one.
    /// None when the closest spacing tried keeps every marked crown whole.
    pub split: Option<SplitMark>,
}

/// A marked crown that holds several crown centres at a spacing: the mark
/// a person may redraw (around one crown) or leave, knowing that it keeps
/// every crown of the image at least the spacing learnt apart.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SplitMark {
    /// Which of the extraction's samples it is (an index into them).
    pub sample: usize,
    /// The spacing (m) at which it holds `centres` centres (two or more).
    pub spacing_m: f64,
    pub centres: usize,
}

impl SplitMark {
    /// For a person, with the extraction's `samples` (pixels) and the
    /// spacing learnt: which mark held several centres at which spacing,
    /// and what to do about it.
    ///
    /// ```
    /// use relevo_core::veg::samples::Sample;
    /// use relevo_core::veg::spacing::SplitMark;
    /// let marks = [Sample::rectangle("tree", [147.0, 403.0, 188.0, 449.0])];
    /// let split = SplitMark { sample: 0, spacing_m: 2.0, centres: 2 };
    /// assert_eq!(
    ///     split.describe(&marks, 2.5).unwrap(),
    ///     "at 2.0 m apart, the tree marked as sample 1 (x 147–188, y 403–449 px) holds 2 \
    ///      centres: if it holds more than one crown, redraw it around one; \
    ///      --crown-spacing sets the spacing"
    /// );
    /// ```
    pub fn describe(&self, samples: &[Sample], spacing_learnt_m: f64) -> Option<String> {
        let sample = samples.get(self.sample)?;
        let [x0, y0, x1, y1] = sample.bounds();
        let at = if self.spacing_m < spacing_learnt_m {
            format!("at {:.1} m apart,", self.spacing_m)
        } else {
            format!("even at {:.1} m apart,", self.spacing_m)
        };
        Some(format!(
            "{at} the {} marked as sample {} (x {x0:.0}–{x1:.0}, y {y0:.0}–{y1:.0} px) holds {} \
             centres: if it holds more than one crown, redraw it around one; \
             --crown-spacing sets the spacing",
            sample.class,
            self.sample + 1,
            self.centres
        ))
    }
}

/// The smallest of [`CROWN_SPACINGS_M`], at least a pixel of `pixel_m`, at
/// which no marked crown holds two centres (placed with the crowns'
/// `template`, where there is one); the largest when every one splits a
/// crown. With it, the crown that split at the spacing tried before.
pub fn learn_spacing(
    crowns: &[MarkedCrown],
    classifier: &Classifier,
    vegetation: &[bool],
    pixel_m: f64,
    min_radius_px: f32,
    template: Option<&CrownTemplate>,
) -> LearntSpacing {
    let classes = classified(crowns, classifier);
    let mut split = None;
    for spacing_m in CROWN_SPACINGS_M.into_iter().filter(|&s| s >= pixel_m) {
        let placement = Placement::Crowns {
            spacing_px: (spacing_m / pixel_m) as f32,
            min_radius_px,
            marked_size_px: None,
            template: template.cloned(),
        };
        // The crown holding the most centres (the first found, on a tie).
        let most = crowns
            .iter()
            .zip(&classes)
            .map(|(crown, classes)| (crown.crowns(classes, vegetation, &placement).len(), crown))
            .reduce(|a, b| if b.0 > a.0 { b } else { a });
        match most {
            Some((centres, crown)) if centres > 1 => {
                split = Some(SplitMark {
                    sample: crown.sample_index,
                    spacing_m,
                    centres,
                });
            }
            _ => return LearntSpacing { spacing_m, split },
        }
    }
    LearntSpacing {
        spacing_m: MAX_CROWN_SPACING_M,
        split,
    }
}

/// A size that most marked crowns reach (pixels): the lower quartile of
/// the marks' mean sides, `None` when no crown was marked. A person marks
/// crowns that stand out, and corrections add the crowns that were missed,
/// often the largest, so the marks run larger than the typical crown; the
/// lower quartile stays with the typical crown where a median follows the
/// added ones.
pub fn marked_crown_size_px(crowns: &[MarkedCrown]) -> Option<f32> {
    let mut sides: Vec<f32> = crowns
        .iter()
        .map(|c| {
            let [x0, y0, x1, y1] = c.sample.bounds();
            ((x1 - x0 + y1 - y0) / 2.0) as f32
        })
        .collect();
    lower_quartile(&mut sides)
}

/// The value a quarter of the way up `values` once sorted (sorting them;
/// the nearest rank, the second smallest of four to six): `None` when there
/// are none.
fn lower_quartile(values: &mut [f32]) -> Option<f32> {
    values.sort_by(f32::total_cmp);
    let last = values.len().checked_sub(1)?;
    Some(values[(last as f32 * 0.25).round() as usize])
}

/// The marked crowns' brightness pattern at `side_px` (their
/// [`marked_crown_size_px`]); `None` when none varies in brightness.
pub fn crown_template(crowns: &[MarkedCrown], side_px: f32) -> Option<CrownTemplate> {
    let brightness: Vec<Vec<f32>> = crowns
        .iter()
        .map(|c| {
            let mut values = Vec::new();
            c.image.brightness_into(&mut values);
            values
        })
        .collect();
    CrownTemplate::learn(
        crowns.iter().zip(&brightness).map(|(c, values)| {
            (
                &values[..],
                c.image.width,
                c.image.height,
                c.sample.centre(),
            )
        }),
        side_px,
    )
}

/// Pixels of neighbourhood a marked crown is cut with: placement at the
/// largest spacing looks this far (smoothing, the window a centre must top,
/// the disc of vegetation around it).
pub fn margin_px(pixel_m: f64) -> usize {
    (3.0 * MAX_CROWN_SPACING_M / pixel_m).ceil() as usize
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testdata;
    use crate::veg::pipeline::{extract, Model, VegOptions};

    #[test]
    fn the_lower_quartile_is_the_nearest_rank() {
        assert_eq!(lower_quartile(&mut []), None);
        assert_eq!(lower_quartile(&mut [7.0]), Some(7.0));
        assert_eq!(lower_quartile(&mut [9.0, 4.0, 6.0, 5.0]), Some(5.0));
        assert_eq!(
            lower_quartile(&mut [1.0, 9.0, 2.0, 8.0, 3.0, 7.0]),
            Some(2.0)
        );
        let mut seven = [7.0, 6.0, 5.0, 4.0, 3.0, 2.0, 1.0];
        assert_eq!(lower_quartile(&mut seven), Some(3.0));
    }

    /// On SOAP_061 a marked dead crown (several bright branches, each like
    /// the marked crowns' pattern) holds three centres at 2 m and two at
    /// 2.5 m: the spacing learnt is the largest, 3 m, and the report names
    /// that crown; a spacing given is used as it is, naming none.
    #[test]
    fn the_spacing_is_the_smallest_that_keeps_each_marked_crown_whole() {
        let (image, samples) = testdata::soap_061_marked();
        let extract_at = |crown_spacing_m: Option<f64>| {
            let options = VegOptions {
                crown_spacing_m,
                ..VegOptions::default()
            };
            let found = extract(&image, &samples, &options).unwrap();
            let spacing_m = match found.report.placement {
                Placement::Crowns { spacing_px, .. } => spacing_px as f64 * image.pixel_m,
                other => panic!("{other:?}"),
            };
            (found, spacing_m)
        };
        let (learnt, spacing_m) = extract_at(None);
        assert!((spacing_m - 3.0).abs() < 1e-6);
        let split = learnt.report.spacing_split.expect("the crown that split");
        assert_eq!(samples[split.sample].class, "dead");
        assert_eq!((split.spacing_m, split.centres), (2.5, 2));
        for (spacing_m, most) in [(2.0, 3), (2.5, 2)] {
            let (given, used_m) = extract_at(Some(spacing_m));
            assert!((used_m - spacing_m).abs() < 1e-6);
            assert_eq!(given.report.spacing_split, None);
            // The crowns placed before the marks are held (one in each).
            let options = VegOptions {
                crown_spacing_m: Some(spacing_m),
                ..VegOptions::default()
            };
            let model = Model::learn(&image, image.pixel_m, &samples, &options, 1.0).unwrap();
            let placed = model.analyse(&image, model.tiles()).unwrap();
            let in_marked_crowns = samples
                .iter()
                .filter(|s| s.class != "other")
                .map(|s| placed.iter().filter(|o| s.contains(o.x, o.y)).count())
                .max()
                .unwrap();
            assert_eq!(in_marked_crowns, most, "{spacing_m} m");
        }
    }
}
