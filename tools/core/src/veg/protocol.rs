//! How well extraction does on images it was not tuned on, measured the
//! way a user meets it: leave one annotated image out, choose the options
//! on the others, score the one left out; and a correction loop in which a
//! simulated user adds a few marks where detection is wrong and detects
//! again.
//!
//! The simulated user was fixed before any figure was looked at. Each round
//! it adds at most [`MARKS_PER_ROUND`] rectangles, alternating, starting
//! with a crown: a crown mark (the truth box itself, of the vegetation class
//! the truth names, else the first marked one) on the largest truth box
//! still missed, and a counter-example around the densest cluster of false
//! detections — the union of the crown boxes of the false detections within
//! two typical crowns of the one with most such neighbours, shrunk to that
//! one's own box where the union would cover a truth box. When one kind
//! runs out, the other fills the round. Places already marked are never
//! marked again.
//!
//! A person's marks are one draw among many: people mark the crowns that
//! stand out. [`with_drawn_marks`] scores the defaults with
//! [`DRAWN_SETS`] sets of marks drawn at random from the truth instead, so
//! the figures show how much they depend on which crowns were marked.

use super::detect::splitmix64;
use super::eval::{self, Criterion, Detection, Evaluation};
use super::pipeline::{extract, VegImage, VegOptions};
use super::samples::Sample;
use crate::Result;
use serde::Serialize;

/// Rectangles the simulated user adds in one round, at most.
pub const MARKS_PER_ROUND: usize = 5;

/// The overlap thresholds figures are reported at (intersection over union
/// of crown boxes): 0.4 as in NeonTreeEvaluation, and the stricter 0.5.
pub const IOU_THRESHOLDS: [f64; 2] = [0.4, 0.5];

/// An annotated image with the samples a user marked on it.
pub struct Annotated {
    pub name: String,
    pub image: VegImage,
    pub samples: Vec<Sample>,
    /// Truth boxes `[xmin, ymin, xmax, ymax]`, pixels.
    pub truth: Vec<[f64; 4]>,
    /// The truth's class names (lower case), for the simulated user's
    /// crown marks.
    pub truth_classes: Vec<String>,
}

impl Annotated {
    /// The objects extracted with `samples` and `options`, as detections in
    /// pixels.
    pub fn detect(&self, samples: &[Sample], options: &VegOptions) -> Result<Vec<Detection>> {
        let found = extract(&self.image, samples, options)?;
        Ok(Detection::of_objects(&found.objects, self.image.pixel_m))
    }
}

/// Precision, recall and F1 at each of [`IOU_THRESHOLDS`] and by centre.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Scores {
    pub iou_0_4: Evaluation,
    pub iou_0_5: Evaluation,
    pub centre: Evaluation,
}

impl Scores {
    /// The scores of `detections` against `truth`.
    pub fn of(detections: &[Detection], truth: &[[f64; 4]]) -> Scores {
        let at = |criterion| eval::evaluate(detections, truth, criterion);
        Scores {
            iou_0_4: at(Criterion::Iou {
                min: IOU_THRESHOLDS[0],
            }),
            iou_0_5: at(Criterion::Iou {
                min: IOU_THRESHOLDS[1],
            }),
            centre: at(Criterion::Centre),
        }
    }
}

/// Choose among `candidates` (each with its distance from the defaults) the
/// one with the best mean of `f1(candidate, image)` over `images`, ties
/// going to the nearer one: what a user tuning on those images would pick.
pub fn choose<T>(
    candidates: &[(T, usize)],
    images: &[usize],
    f1: impl Fn(usize, usize) -> f64,
) -> usize {
    let mean =
        |c: usize| images.iter().map(|&i| f1(c, i)).sum::<f64>() / images.len().max(1) as f64;
    (0..candidates.len())
        .max_by(|&a, &b| {
            mean(a)
                .total_cmp(&mean(b))
                .then(candidates[b].1.cmp(&candidates[a].1))
                .then(b.cmp(&a))
        })
        .unwrap_or(0)
}

/// The options the protocol chooses among, each with its distance from the
/// defaults in grid steps.
pub fn grid() -> Vec<(VegOptions, usize)> {
    let defaults = VegOptions::default();
    let brightness = [20.0f32, 28.0, 36.0];
    let chroma = [4.0f32, 6.0, 8.0];
    let neighbours = [1usize, 3, 5];
    let steps = |values: &[f32], v: f32, default: f32| {
        let at = |x: f32| {
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
                let options = VegOptions {
                    brightness_std: b,
                    chroma_std: c,
                    neighbours: n,
                    ..defaults.clone()
                };
                let distance = steps(&brightness, b, defaults.brightness_std)
                    + steps(&chroma, c, defaults.chroma_std)
                    + steps(
                        &neighbours.map(|n| n as f32),
                        n as f32,
                        defaults.neighbours as f32,
                    );
                points.push((options, distance));
            }
        }
    }
    points
}

/// The baseline's windows (m: crown spacing and size) chosen among, each
/// with its distance from 3 m.
const BASELINE_SPACINGS_M: [(f64, usize); 5] = [(2.0, 1), (3.0, 0), (4.0, 1), (5.0, 2), (6.0, 3)];

/// The baseline's crowns on `image` at `spacing_m`, the detector's
/// smallest crown radius.
fn baseline_crowns(image: &VegImage, spacing_m: f64) -> Vec<Detection> {
    let min_radius_px = (VegOptions::default().crown_min_radius_m / image.pixel_m) as f32;
    super::baseline::excess_green_crowns(
        &image.image,
        (spacing_m / image.pixel_m) as f32,
        min_radius_px,
    )
}

/// One image's leave-one-out figures.
#[derive(Debug, Clone, Serialize)]
pub struct HeldOut {
    pub image: String,
    /// The grid's options chosen on the other images.
    pub options: VegOptions,
    /// Their mean F1 at IoU 0.4 on the images they were chosen on.
    pub chosen_on_f1: f64,
    pub chosen: Scores,
    pub defaults: Scores,
    pub baseline_spacing_m: f64,
    pub baseline: Scores,
}

/// Leave each of `images` out in turn: choose the options among `grid` on
/// the others and score them on it, with the defaults and the baseline.
pub fn leave_one_out(images: &[Annotated], grid: &[(VegOptions, usize)]) -> Result<Vec<HeldOut>> {
    let at_04 = |d: &[Detection], a: &Annotated| {
        eval::evaluate(
            d,
            &a.truth,
            Criterion::Iou {
                min: IOU_THRESHOLDS[0],
            },
        )
    };
    // Every grid point and baseline spacing on every image, once.
    let scores: Vec<Vec<Scores>> = grid
        .iter()
        .map(|(options, _)| {
            images
                .iter()
                .map(|a| Ok(Scores::of(&a.detect(&a.samples, options)?, &a.truth)))
                .collect::<Result<Vec<Scores>>>()
        })
        .collect::<Result<_>>()?;
    let f1 = |g: usize, i: usize| scores[g][i].iou_0_4.f1;
    let baseline_f1: Vec<Vec<f64>> = BASELINE_SPACINGS_M
        .iter()
        .map(|&(s, _)| {
            images
                .iter()
                .map(|a| at_04(&baseline_crowns(&a.image, s), a).f1)
                .collect()
        })
        .collect();
    // The defaults are a grid point: their scores are already there.
    let defaults = VegOptions::default();
    let on_grid = grid.iter().position(|(o, _)| *o == defaults);
    images
        .iter()
        .enumerate()
        .map(|(h, image)| {
            let others: Vec<usize> = (0..images.len()).filter(|&i| i != h).collect();
            let g = choose(grid, &others, f1);
            let chosen_on_f1 =
                others.iter().map(|&i| f1(g, i)).sum::<f64>() / others.len().max(1) as f64;
            let b = choose(&BASELINE_SPACINGS_M, &others, |c, i| baseline_f1[c][i]);
            let spacing_m = BASELINE_SPACINGS_M[b].0;
            Ok(HeldOut {
                image: image.name.clone(),
                options: grid[g].0.clone(),
                chosen_on_f1,
                chosen: scores[g][h],
                defaults: match on_grid {
                    Some(d) => scores[d][h],
                    None => Scores::of(&image.detect(&image.samples, &defaults)?, &image.truth),
                },
                baseline_spacing_m: spacing_m,
                baseline: Scores::of(&baseline_crowns(&image.image, spacing_m), &image.truth),
            })
        })
        .collect()
}

/// One round of the correction loop: its detections' scores and the marks
/// it had added before detecting.
#[derive(Debug, Clone, Serialize)]
pub struct Round {
    /// 0 for the first detection with the user's own marks.
    pub round: usize,
    /// Marks detection ran with.
    pub marks: usize,
    /// The rectangles this round added, `(class, [xmin, ymin, xmax, ymax])`.
    pub added: Vec<(String, [f64; 4])>,
    pub scores: Scores,
    /// Marked places detection disagreed with: counter-examples holding a
    /// detection's centre, crown marks holding none or several.
    pub marks_contradicted: usize,
}

/// Detect with the user's samples, then `rounds` times add the simulated
/// user's marks and detect again (see the module's description).
pub fn correction_loop(
    image: &Annotated,
    options: &VegOptions,
    rounds: usize,
) -> Result<Vec<Round>> {
    let mut samples = image.samples.clone();
    let mut added = Vec::new();
    let mut out = Vec::new();
    for round in 0..=rounds {
        let detections = image.detect(&samples, options)?;
        out.push(Round {
            round,
            marks: samples.len(),
            added: added
                .iter()
                .map(|s: &Sample| (s.class.clone(), s.bounds()))
                .collect(),
            scores: Scores::of(&detections, &image.truth),
            marks_contradicted: contradicted(&samples, &detections, &options.negative_class),
        });
        if round == rounds {
            break;
        }
        added = simulated_marks(image, &samples, &detections, &options.negative_class);
        if added.is_empty() {
            break;
        }
        samples.extend(added.iter().cloned());
    }
    Ok(out)
}

/// Marks that `detections` disagree with: a counter-example holding a
/// detection's centre, a crown mark holding none or more than one.
pub fn contradicted(samples: &[Sample], detections: &[Detection], negative_class: &str) -> usize {
    samples
        .iter()
        .filter(|s| {
            let inside = detections.iter().filter(|d| s.contains(d.x, d.y)).count();
            if s.class == negative_class {
                inside > 0
            } else {
                inside != 1
            }
        })
        .count()
}

/// The simulated user's marks for one round (see the module's
/// description), given the marks so far and the detections they gave.
pub fn simulated_marks(
    image: &Annotated,
    samples: &[Sample],
    detections: &[Detection],
    negative_class: &str,
) -> Vec<Sample> {
    let truth = &image.truth;
    let matched = eval::matches(
        detections,
        truth,
        Criterion::Iou {
            min: IOU_THRESHOLDS[0],
        },
    );
    let found: Vec<bool> = {
        let mut f = vec![false; truth.len()];
        matched.iter().flatten().for_each(|&t| f[t] = true);
        f
    };
    let marked = |x: f64, y: f64| samples.iter().any(|s| s.contains(x, y));
    let middle = |b: &[f64; 4]| ((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
    let area = |b: &[f64; 4]| (b[2] - b[0]) * (b[3] - b[1]);
    // Crowns missed, largest first, not under a mark already.
    let mut missed: Vec<usize> = (0..truth.len())
        .filter(|&t| {
            !found[t] && {
                let (x, y) = middle(&truth[t]);
                !marked(x, y)
            }
        })
        .collect();
    missed.sort_by(|&a, &b| area(&truth[b]).total_cmp(&area(&truth[a])).then(a.cmp(&b)));
    let crown_class = |t: usize| {
        let vegetation = samples.iter().filter(|s| s.class != negative_class);
        let named = image.truth_classes.get(t).and_then(|c| {
            vegetation
                .clone()
                .find(|s| s.class.to_lowercase() == *c)
                .map(|s| s.class.clone())
        });
        named
            .or_else(|| vegetation.clone().next().map(|s| s.class.clone()))
            .unwrap_or_else(|| "tree".into())
    };
    let mut crowns = missed
        .into_iter()
        .map(|t| Sample::rectangle(&crown_class(t), truth[t]));
    // False detections not under a mark already.
    let mut false_ones: Vec<Detection> = detections
        .iter()
        .zip(&matched)
        .filter(|(d, m)| m.is_none() && !marked(d.x, d.y))
        .map(|(d, _)| *d)
        .collect();
    let mut sides: Vec<f64> = truth
        .iter()
        .map(|b| (b[2] - b[0] + b[3] - b[1]) / 2.0)
        .collect();
    sides.sort_by(f64::total_cmp);
    let reach = 2.0 * sides.get(sides.len() / 2).copied().unwrap_or(10.0);
    let covers_truth = |r: &[f64; 4]| truth.iter().any(|b| eval::iou(*r, *b) > 0.0);
    let mut counter_example = || -> Option<Sample> {
        loop {
            if false_ones.is_empty() {
                return None;
            }
            let near = |a: &Detection, b: &Detection| (a.x - b.x).hypot(a.y - b.y) <= reach;
            let seed = (0..false_ones.len())
                .max_by_key(|&k| {
                    let n = false_ones
                        .iter()
                        .filter(|d| near(d, &false_ones[k]))
                        .count();
                    (n, std::cmp::Reverse(k))
                })
                .unwrap_or(0);
            let seed_box = false_ones[seed].bounds();
            let cluster: Vec<usize> = (0..false_ones.len())
                .filter(|&k| near(&false_ones[k], &false_ones[seed]))
                .collect();
            let union = cluster.iter().fold(seed_box, |u, &k| {
                let b = false_ones[k].bounds();
                [
                    u[0].min(b[0]),
                    u[1].min(b[1]),
                    u[2].max(b[2]),
                    u[3].max(b[3]),
                ]
            });
            let rectangle = if !covers_truth(&union) {
                Some(union)
            } else if !covers_truth(&seed_box) {
                Some(seed_box)
            } else {
                None
            };
            let Some(r) = rectangle else {
                false_ones.swap_remove(seed);
                continue;
            };
            false_ones.retain(|d| !(r[0] <= d.x && d.x <= r[2] && r[1] <= d.y && d.y <= r[3]));
            return Some(Sample::rectangle(negative_class, r));
        }
    };
    let mut marks = Vec::new();
    let (mut crowns_done, mut others_done) = (false, false);
    while marks.len() < MARKS_PER_ROUND && !(crowns_done && others_done) {
        let crown_turn = marks.len() % 2 == 0;
        let next = if (crown_turn && !crowns_done) || others_done {
            let c = crowns.next();
            crowns_done |= c.is_none();
            c
        } else {
            let o = counter_example();
            others_done |= o.is_none();
            o
        };
        marks.extend(next);
    }
    marks
}

/// Sets of marks drawn from the truth that [`with_drawn_marks`] scores.
pub const DRAWN_SETS: u64 = 8;

/// Crown marks, and counter-examples, in one drawn set.
pub const DRAWN_OF_EACH: usize = 5;

/// A crown drawn as a mark is at least this wide and tall (metres): one a
/// person can see.
const DRAWN_CROWN_MIN_M: f64 = 2.0;

/// Counter-examples drawn are squares of this range of sides (metres).
const DRAWN_SQUARE_M: [f64; 2] = [3.0, 8.0];

/// Places tried for the counter-examples of one set, at most.
const DRAWN_TRIES: u64 = 10_000;

/// Set `seed` of marks drawn at random from the truth: a user who marks
/// any crowns rather than those that stand out. [`DRAWN_OF_EACH`] truth
/// boxes at least 2 m a side, each marked as its truth class, then as
/// many squares of 3 to 8 m sides, marked `negative_class`, that meet no
/// truth box's middle half (the box with a quarter of its width and
/// height cut off each side), in whole pixels. The same seed draws the
/// same marks.
pub fn drawn_marks(image: &Annotated, seed: u64, negative_class: &str) -> Vec<Sample> {
    let base = splitmix64(seed);
    let draw = |k: u64| splitmix64(base ^ k);
    let uniform = |k: u64| (draw(k) >> 11) as f64 / (1u64 << 53) as f64;
    let pixel_m = image.image.pixel_m.max(1e-9);
    let truth = &image.truth;
    let mut crowns: Vec<(u64, usize)> = (0..truth.len())
        .filter(|&t| {
            let [x0, y0, x1, y1] = truth[t];
            (x1 - x0).min(y1 - y0) * pixel_m >= DRAWN_CROWN_MIN_M
        })
        .map(|t| (draw(t as u64), t))
        .collect();
    crowns.sort_unstable();
    let mut marks: Vec<Sample> = crowns
        .iter()
        .take(DRAWN_OF_EACH)
        .map(|&(_, t)| {
            let class = image.truth_classes.get(t).map_or("tree", |c| c.as_str());
            Sample::rectangle(class, truth[t])
        })
        .collect();
    let (w, h) = (
        image.image.image.width as f64,
        image.image.image.height as f64,
    );
    let middle_half = |b: &[f64; 4]| {
        let (qx, qy) = ((b[2] - b[0]) / 4.0, (b[3] - b[1]) / 4.0);
        [b[0] + qx, b[1] + qy, b[2] - qx, b[3] - qy]
    };
    let meets =
        |a: &[f64; 4], b: &[f64; 4]| a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3];
    let mut others = 0;
    for attempt in 0..DRAWN_TRIES {
        if others == DRAWN_OF_EACH {
            break;
        }
        // Past the crowns' keys: the squares' own draws.
        let k = (1 << 40) + 3 * attempt;
        let [low, high] = DRAWN_SQUARE_M;
        // Whole pixels, as a person draws them.
        let side = ((low + (high - low) * uniform(k)) / pixel_m)
            .round()
            .min(w)
            .min(h);
        let (x, y) = (
            (uniform(k + 1) * (w - side)).floor(),
            (uniform(k + 2) * (h - side)).floor(),
        );
        let square = [x, y, x + side, y + side];
        if truth.iter().any(|b| meets(&square, &middle_half(b))) {
            continue;
        }
        marks.push(Sample::rectangle(negative_class, square));
        others += 1;
    }
    marks
}

/// The scores of `options` with each of the [`DRAWN_SETS`] sets of
/// [`drawn_marks`] in turn, in the order of their seeds.
pub fn with_drawn_marks(image: &Annotated, options: &VegOptions) -> Result<Vec<Scores>> {
    (0..DRAWN_SETS)
        .map(|seed| {
            let marks = drawn_marks(image, seed, &options.negative_class);
            Ok(Scores::of(&image.detect(&marks, options)?, &image.truth))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::veg::Image;

    fn annotated(truth: Vec<[f64; 4]>) -> Annotated {
        Annotated {
            name: "test".into(),
            image: VegImage {
                image: Image::new(100, 100, 3, vec![0; 30_000]).unwrap(),
                crs_wkt: String::new(),
                geotransform: None,
                pixel_m: 0.1,
                valid: None,
            },
            samples: Vec::new(),
            truth_classes: vec!["tree".into(); truth.len()],
            truth,
        }
    }

    fn at(x: f64, y: f64) -> Detection {
        Detection {
            x,
            y,
            diameter: 4.0,
            score: 0.5,
        }
    }

    #[test]
    fn the_simulated_user_marks_the_largest_misses_and_the_densest_false_detections() {
        let image = annotated(vec![
            [0.0, 0.0, 10.0, 10.0],
            [20.0, 0.0, 40.0, 20.0],
            [50.0, 0.0, 56.0, 6.0],
            [70.0, 0.0, 80.0, 10.0],
        ]);
        let samples = vec![Sample::rectangle("tree", [72.0, 2.0, 78.0, 8.0])];
        // The first box found; three false detections close together, one
        // alone.
        let first = Detection {
            diameter: 10.0,
            ..at(5.0, 5.0)
        };
        let detections = [
            first,
            at(10.0, 80.0),
            at(13.0, 82.0),
            at(11.0, 85.0),
            at(80.0, 80.0),
        ];
        let marks = simulated_marks(&image, &samples, &[detections[0]], "other");
        // Nothing false: the misses only, largest first; the marked box is
        // left alone.
        assert_eq!(
            marks.iter().map(|m| m.bounds()).collect::<Vec<_>>(),
            [[20.0, 0.0, 40.0, 20.0], [50.0, 0.0, 56.0, 6.0]]
        );
        let marks = simulated_marks(&image, &samples, &detections, "other");
        let classes: Vec<&str> = marks.iter().map(|m| m.class.as_str()).collect();
        assert_eq!(classes, ["tree", "other", "tree", "other"]);
        // The cluster of three as one rectangle, then the lone one.
        assert_eq!(marks[1].bounds(), [8.0, 78.0, 15.0, 87.0]);
        assert_eq!(marks[3].bounds(), [78.0, 78.0, 82.0, 82.0]);
    }

    #[test]
    fn a_counter_example_never_covers_a_truth_box() {
        let image = annotated(vec![[10.0, 10.0, 20.0, 20.0]]);
        // Two false detections on either side of the box: their union would
        // cover it, so the mark is the densest one's own box.
        let detections = [at(5.0, 15.0), at(25.0, 15.0)];
        let marks = simulated_marks(&image, &[], &detections, "other");
        assert_eq!(marks[0].class, "tree");
        let others: Vec<[f64; 4]> = marks[1..].iter().map(|m| m.bounds()).collect();
        assert_eq!(others, [[3.0, 13.0, 7.0, 17.0], [23.0, 13.0, 27.0, 17.0]]);
    }

    #[test]
    fn drawn_marks_are_visible_crowns_and_squares_clear_of_every_crown() {
        // 1 m crowns (too small to be drawn) and 3 m ones, at 0.1 m.
        let truth: Vec<[f64; 4]> = (0..40)
            .map(|k| {
                let (x, y) = ((k % 8) as f64 * 12.0, (k / 8) as f64 * 12.0);
                let side = if k % 2 == 0 { 10.0 } else { 30.0 };
                [x, y, x + side, y + side]
            })
            .collect();
        let mut image = annotated(truth.clone());
        image.image.image = Image::new(400, 300, 3, vec![0; 400 * 300 * 3]).unwrap();
        let marks = drawn_marks(&image, 3, "other");
        assert_eq!(marks, drawn_marks(&image, 3, "other"), "not repeatable");
        assert_ne!(marks, drawn_marks(&image, 4, "other"), "seeds draw alike");
        let (crowns, others): (Vec<_>, Vec<_>) = marks.iter().partition(|m| m.class == "tree");
        assert_eq!((crowns.len(), others.len()), (DRAWN_OF_EACH, DRAWN_OF_EACH));
        for c in &crowns {
            let b = c.bounds();
            assert!(truth.contains(&b) && b[2] - b[0] == 30.0, "{b:?}");
        }
        for o in &others {
            let [x0, y0, x1, y1] = o.bounds();
            let side = x1 - x0;
            assert!((30.0..=80.0).contains(&side) && side == y1 - y0);
            assert!(x0.fract() == 0.0 && y0.fract() == 0.0 && side.fract() == 0.0);
            assert!(x0 >= 0.0 && y0 >= 0.0 && x1 <= 400.0 && y1 <= 300.0);
            for b in &truth {
                let (qx, qy) = ((b[2] - b[0]) / 4.0, (b[3] - b[1]) / 4.0);
                let clear =
                    x1 <= b[0] + qx || b[2] - qx <= x0 || y1 <= b[1] + qy || b[3] - qy <= y0;
                assert!(clear, "{:?} meets the middle of {b:?}", o.bounds());
            }
        }
    }

    #[test]
    fn contradicted_marks_are_counted() {
        let samples = vec![
            Sample::rectangle("other", [0.0, 0.0, 10.0, 10.0]),
            Sample::rectangle("tree", [20.0, 0.0, 30.0, 10.0]),
            Sample::rectangle("tree", [40.0, 0.0, 50.0, 10.0]),
        ];
        let d = [at(5.0, 5.0), at(25.0, 5.0), at(45.0, 5.0), at(46.0, 6.0)];
        assert_eq!(contradicted(&samples, &d, "other"), 2);
        assert_eq!(contradicted(&samples, &d[1..3], "other"), 0);
    }
}
