//! Learning class signatures from marked samples and classifying regions by
//! the nearest learnt signature (the seed's buildDB workflow: signatures of
//! the marked regions, then a search for compatible signatures everywhere).

use super::haar::region_signature;
use super::samples::Sample;
use super::segment::Segmentation;
use super::Image;
use crate::{Error, Result};
use rayon::prelude::*;

/// The region covering most pixel centres of a sample (lowest index on ties).
fn dominant_region(segmentation: &Segmentation, sample: &Sample) -> Option<usize> {
    let w = segmentation.width;
    let [x0, y0, x1, y1] = sample.pixel_bounds(w, segmentation.height);
    let mut counts = std::collections::BTreeMap::new();
    for y in y0..y1 {
        for x in x0..x1 {
            if sample.contains(x as f64 + 0.5, y as f64 + 0.5) {
                *counts
                    .entry(segmentation.labels[y * w + x] as usize)
                    .or_insert(0u64) += 1;
            }
        }
    }
    counts
        .into_iter()
        .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
        .map(|(k, _)| k)
}

/// The signatures one sample gives in a segmentation: every region whose
/// centroid lies in the sample, and the region covering most of the sample.
pub fn sample_signatures(
    image: &Image,
    segmentation: &Segmentation,
    sample: &Sample,
    crown: bool,
    window_px: u32,
) -> Vec<Vec<f32>> {
    // A crown is round: the corners of the rectangle around it are what
    // it stands on, so its regions are those centred in the inscribed
    // ellipse.
    let [x0, y0, x1, y1] = sample.bounds();
    let (cx, cy, rx, ry) = (
        (x0 + x1) / 2.0,
        (y0 + y1) / 2.0,
        (x1 - x0) / 2.0,
        (y1 - y0) / 2.0,
    );
    let in_crown = |x: f64, y: f64| {
        !crown || ((x - cx) / rx.max(0.5)).powi(2) + ((y - cy) / ry.max(0.5)).powi(2) <= 1.0
    };
    let mut inside: Vec<usize> = segmentation
        .regions
        .iter()
        .enumerate()
        .filter(|(_, r)| {
            let (x, y) = (r.centroid[0] as f64, r.centroid[1] as f64);
            sample.contains(x, y) && in_crown(x, y)
        })
        .map(|(k, _)| k)
        .collect();
    if let Some(k) = dominant_region(segmentation, sample) {
        if !inside.contains(&k) {
            inside.push(k);
        }
    }
    inside
        .into_iter()
        .map(|k| region_signature(image, segmentation, k, window_px))
        .collect()
}

/// Learnt signatures whose distances are summed side by side.
const LANES: usize = 8;

/// Buffers of one classification, reused between regions.
#[derive(Default)]
struct Scratch {
    /// The signature's features standardised.
    standard: Vec<f32>,
    /// Per lane, the smallest distances its learnt signatures of one class
    /// gave, sorted: `nearest_in_lanes[j][lane]` the `j`-th smallest.
    nearest_in_lanes: Vec<[f32; LANES]>,
    /// The smallest distances of one class over all lanes, sorted.
    smallest: Vec<[f32; 1]>,
    /// Mean distance to each class's nearest signatures.
    nearest: Vec<f32>,
}

/// A class's distance averages at most one in this many of its signatures.
const NEIGHBOURS_SHARE: usize = 3;

/// Signatures learnt per class, standardised per feature.
#[derive(Debug, Clone)]
pub struct Classifier {
    /// Class names in order of first appearance in the samples.
    pub classes: Vec<String>,
    /// Per feature: 1 / spread over all learnt signatures.
    inverse_scale: Vec<f32>,
    /// Learnt signatures of each class.
    class_signatures: Vec<usize>,
    /// The standardised learnt signatures, feature-major and grouped by
    /// class: feature `f` of stored signature `e` at `f · stride + e`. Each
    /// class's signatures take whole groups of [`LANES`] (the last padded
    /// with infinite features, whose distance is infinite), so one
    /// feature's values are contiguous and a group's distances accumulate
    /// in lanes.
    example_features: Vec<f32>,
    /// The groups of [`LANES`] stored signatures each class takes.
    class_groups: Vec<std::ops::Range<usize>>,
    /// Smallest window side a signature is taken over (pixels).
    window_px: u32,
    /// How many nearest signatures of each class its distance averages:
    /// the `neighbours` option, capped at a third of the class's signatures.
    class_neighbours: Vec<usize>,
}

/// A region's class and how clearly it won, in `[0.5, 1]`: `d₂ / (d₁ + d₂)`
/// with `d₁` the winning class's distance and `d₂` the next class's (1 when
/// there is a single class).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Label {
    pub class: usize,
    pub score: f32,
}

impl Classifier {
    /// Learn from the signatures of marked regions: `(class, signature)`
    /// pairs in the order the samples were marked (their first appearance
    /// orders the classes), e.g. from [`sample_signatures`].
    pub fn learn(
        marked: Vec<(String, Vec<f32>)>,
        window_px: u32,
        neighbours: usize,
    ) -> Result<Classifier> {
        if marked.is_empty() {
            return Err(Error::Input("no samples to learn from".into()));
        }
        let mut classes: Vec<String> = Vec::new();
        let mut raw: Vec<(usize, Vec<f32>)> = Vec::with_capacity(marked.len());
        for (name, signature) in marked {
            let class = match classes.iter().position(|c| *c == name) {
                Some(k) => k,
                None => {
                    classes.push(name);
                    classes.len() - 1
                }
            };
            raw.push((class, signature));
        }
        let features = raw[0].1.len();
        let n = raw.len() as f32;
        let inverse_scale: Vec<f32> = (0..features)
            .map(|f| {
                let mean = raw.iter().map(|(_, s)| s[f]).sum::<f32>() / n;
                let var = raw.iter().map(|(_, s)| (s[f] - mean).powi(2)).sum::<f32>() / n;
                1.0 / var.sqrt().max(1e-3)
            })
            .collect();
        let mut class_signatures = vec![0; classes.len()];
        for (class, _) in &raw {
            class_signatures[*class] += 1;
        }
        let class_neighbours = class_signatures
            .iter()
            .map(|&signatures| (signatures / NEIGHBOURS_SHARE).clamp(1, neighbours.max(1)))
            .collect();
        // Stored order: class by class, each padded to whole groups.
        let mut stored: Vec<Option<&[f32]>> = Vec::new();
        let mut class_groups = Vec::with_capacity(classes.len());
        for class in 0..classes.len() {
            let first = stored.len() / LANES;
            stored.extend(
                raw.iter()
                    .filter(|(c, _)| *c == class)
                    .map(|(_, s)| Some(s.as_slice())),
            );
            stored.resize(stored.len().next_multiple_of(LANES), None);
            class_groups.push(first..stored.len() / LANES);
        }
        let example_features = (0..features)
            .flat_map(|f| {
                let scale = inverse_scale[f];
                stored
                    .iter()
                    .map(move |s| s.map_or(f32::INFINITY, |s| s[f] * scale))
            })
            .collect();
        Ok(Classifier {
            classes,
            inverse_scale,
            class_signatures,
            example_features,
            class_groups,
            window_px,
            class_neighbours,
        })
    }

    /// Number of learnt signatures per class.
    pub fn signatures_per_class(&self) -> &[usize] {
        &self.class_signatures
    }

    /// Class of one signature: the class whose `neighbours` nearest learnt
    /// signatures are nearest on average (a local-mean nearest-neighbour
    /// rule, Mitani & Hamamoto 2006; with one neighbour, plain nearest
    /// neighbour). Averaging a few keeps one stray sample region, such as a
    /// shadow inside a crown's rectangle, from claiming everything that
    /// resembles it. A class with few signatures averages fewer (at most a
    /// third of them): uniform canopy in coarse imagery merges into a few
    /// large regions, and averaging over most of those would bring in the
    /// odd clearing its rectangles also hold, so that a densely sampled
    /// class wins by numbers alone. Distances are Euclidean over features
    /// standardised by their spread in the samples.
    pub fn classify(&self, signature: &[f32]) -> Label {
        self.classify_with(signature, &mut Scratch::default())
    }

    /// [`Classifier::classify`] with buffers reused between calls.
    fn classify_with(&self, signature: &[f32], scratch: &mut Scratch) -> Label {
        scratch.standard.clear();
        scratch.standard.extend(
            signature
                .iter()
                .zip(&self.inverse_scale)
                .map(|(v, s)| v * s),
        );
        self.class_distances(scratch);
        let nearest = &scratch.nearest;
        let (best, d1) = nearest
            .iter()
            .enumerate()
            .fold(
                (0, f32::INFINITY),
                |acc, (c, &d)| if d < acc.1 { (c, d) } else { acc },
            );
        let d2 = nearest
            .iter()
            .enumerate()
            .filter(|(c, _)| *c != best)
            .map(|(_, &d)| d)
            .fold(f32::INFINITY, f32::min);
        let score = if d2.is_infinite() || d1 + d2 == 0.0 {
            1.0
        } else {
            d2 / (d1 + d2)
        };
        Label { class: best, score }
    }

    /// Each class's distance from the standardised features in
    /// `scratch.standard`, into `scratch.nearest`: the mean of the square
    /// roots of its `class_neighbours` smallest squared distances, in
    /// ascending order.
    fn class_distances(&self, scratch: &mut Scratch) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the machine has AVX2 (checked just above).
            unsafe { self.class_distances_avx2(scratch) };
            return;
        }
        self.class_distances_in_lanes(scratch);
    }

    /// [`Classifier::class_distances_in_lanes`] compiled for AVX2: a
    /// group's eight sums in one register (the same operations, each
    /// rounded as before: no fused multiply-add).
    ///
    /// # Safety
    /// The machine must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn class_distances_avx2(&self, scratch: &mut Scratch) {
        self.class_distances_in_lanes(scratch);
    }

    /// [`Classifier::class_distances`] with [`LANES`] learnt signatures at
    /// a time: their squared distances summed in registers in feature
    /// order, each lane keeping its own smallest few, and the class's
    /// smallest taken from the lanes' at the end (the same values, hence
    /// the same sums, as one sorted list over all signatures).
    #[inline(always)]
    fn class_distances_in_lanes(&self, scratch: &mut Scratch) {
        let Scratch {
            standard,
            nearest_in_lanes,
            smallest,
            nearest,
        } = scratch;
        let stride = self.class_groups.last().map_or(0, |g| g.end * LANES);
        nearest.clear();
        for (groups, &k) in self.class_groups.iter().zip(&self.class_neighbours) {
            nearest_in_lanes.clear();
            nearest_in_lanes.resize(k, [f32::INFINITY; LANES]);
            for group in groups.clone() {
                let mut sum = [0.0f32; LANES];
                for (column, &value) in self.example_features.chunks_exact(stride).zip(&*standard) {
                    let lanes = &column[group * LANES..][..LANES];
                    for (acc, &e) in sum.iter_mut().zip(lanes) {
                        *acc += (e - value) * (e - value);
                    }
                }
                keep_smallest(nearest_in_lanes, sum);
            }
            smallest.clear();
            smallest.resize(k, [f32::INFINITY]);
            for lane in 0..LANES {
                for row in nearest_in_lanes.iter() {
                    keep_smallest(smallest, [row[lane]]);
                }
            }
            let total: f32 = smallest.iter().map(|[d]| d.sqrt()).sum();
            nearest.push(total / k as f32);
        }
    }

    /// Classify every region of a segmentation.
    pub fn classify_regions(&self, image: &Image, segmentation: &Segmentation) -> Vec<Label> {
        (0..segmentation.regions.len())
            .into_par_iter()
            .map_init(Scratch::default, |scratch, k| {
                let signature = region_signature(image, segmentation, k, self.window_px);
                self.classify_with(&signature, scratch)
            })
            .collect()
    }
}

/// Put `value` into `sorted`, lane by lane: each lane of `sorted` holds
/// the smallest values it was given, ascending; a value no smaller than
/// the lane's last (or NaN) leaves it as it was. Compare-and-swap down the
/// list, without branches, so the lanes go side by side.
#[inline(always)]
fn keep_smallest<const L: usize>(sorted: &mut [[f32; L]], value: [f32; L]) {
    let mut carry = value;
    for slot in sorted {
        for (kept, carried) in slot.iter_mut().zip(carry.iter_mut()) {
            let smaller = *carried < *kept;
            let (low, high) = if smaller {
                (*carried, *kept)
            } else {
                (*kept, *carried)
            };
            *kept = low;
            *carried = high;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The class distances in lanes, plain and compiled for AVX2, are bit
    /// for bit those of one sorted list of every signature's distance.
    #[test]
    fn class_distances_in_lanes_are_those_of_one_sorted_list() {
        let mut state = 0x9e37_79b9u32;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state % 2000) as f32 / 7.0 - 100.0
        };
        // Classes of 29, 11 and 2 signatures, interleaved as marked: the
        // groups are padded, the neighbours 3, 3 and 1.
        let class_of = |k: usize| match k {
            k if k < 22 => k % 2,
            k if k < 40 => 0,
            _ => 2,
        };
        let marked: Vec<(String, Vec<f32>)> = (0..42)
            .map(|k| {
                (
                    format!("class {}", class_of(k)),
                    (0..39).map(|_| next()).collect(),
                )
            })
            .collect();
        let classifier = Classifier::learn(marked.clone(), 8, 3).unwrap();
        assert_eq!(classifier.signatures_per_class(), [29, 11, 2]);
        assert_eq!(classifier.class_neighbours, [3, 3, 1]);
        let mut scratch = Scratch {
            standard: (0..39).map(|_| next()).collect(),
            ..Scratch::default()
        };
        let expected: Vec<f32> = (0..3)
            .map(|class| {
                let name = format!("class {class}");
                let mut distances: Vec<f32> = marked
                    .iter()
                    .filter(|(c, _)| *c == name)
                    .map(|(_, s)| {
                        s.iter()
                            .zip(&classifier.inverse_scale)
                            .zip(&scratch.standard)
                            .fold(0.0, |sum, ((v, scale), value)| {
                                let e = v * scale;
                                sum + (e - value) * (e - value)
                            })
                    })
                    .collect();
                distances.sort_by(f32::total_cmp);
                let k = classifier.class_neighbours[class];
                distances[..k].iter().map(|d| d.sqrt()).sum::<f32>() / k as f32
            })
            .collect();
        let bits = |v: &[f32]| v.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
        classifier.class_distances_in_lanes(&mut scratch);
        assert_eq!(bits(&scratch.nearest), bits(&expected));
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            scratch.nearest.clear();
            // SAFETY: the machine has AVX2 (checked just above).
            unsafe { classifier.class_distances_avx2(&mut scratch) };
            assert_eq!(bits(&scratch.nearest), bits(&expected));
        }
        assert!(expected.iter().all(|d| d.is_finite() && *d > 0.0));
    }

    /// A class marked by two signatures (its canopy and a clearing in the
    /// same rectangle) against one marked by nine: averaging the sparse
    /// class's two would let the clearing lose it the canopy it was marked
    /// on; capped at a third of its signatures it averages one and wins.
    #[test]
    fn a_sparsely_marked_class_averages_fewer_neighbours() {
        let mut marked = vec![
            ("forest".to_string(), vec![0.0, 0.0]),
            ("forest".to_string(), vec![10.0, 0.0]),
        ];
        marked.extend((-4..=4).map(|y| ("other".to_string(), vec![2.0, y as f32])));
        let classifier = Classifier::learn(marked, 8, 3).unwrap();
        assert_eq!(classifier.class_neighbours, [1, 3]);
        assert_eq!(classifier.classify(&[0.5, 0.0]).class, 0);
        assert_eq!(classifier.classify(&[2.2, 0.5]).class, 1);
        // Without the cap (both classes averaging up to three), the
        // clearing drags the forest's distance past the other class's.
        let uncapped = Classifier {
            class_neighbours: vec![3, 3],
            ..classifier
        };
        assert_eq!(uncapped.classify(&[0.5, 0.0]).class, 1);
    }
}
