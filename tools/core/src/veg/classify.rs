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
    window_px: u32,
) -> Vec<Vec<f32>> {
    let mut inside: Vec<usize> = segmentation
        .regions
        .iter()
        .enumerate()
        .filter(|(_, r)| sample.contains(r.centroid[0] as f64, r.centroid[1] as f64))
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
    /// Squared distance to every learnt signature (padded to [`LANES`]).
    distances: Vec<f32>,
    /// The smallest distances of each class, sorted.
    smallest: Vec<f32>,
    /// Learnt signatures per class.
    found: Vec<usize>,
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
    /// Class index of every learnt signature.
    example_class: Vec<usize>,
    /// The standardised learnt signatures, feature-major: feature `f` of
    /// signature `e` at `f · stride + e`, `stride` the number of signatures
    /// rounded up to [`LANES`] (padded with zeros), so one feature's values
    /// for all signatures are contiguous and their distances accumulate in
    /// lanes.
    example_features: Vec<f32>,
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
        let example_class: Vec<usize> = raw.iter().map(|(c, _)| *c).collect();
        let class_neighbours = (0..classes.len())
            .map(|c| {
                let signatures = example_class.iter().filter(|&&e| e == c).count();
                (signatures / NEIGHBOURS_SHARE).clamp(1, neighbours.max(1))
            })
            .collect();
        let padding = raw.len().next_multiple_of(LANES) - raw.len();
        let example_features = (0..features)
            .flat_map(|f| {
                let scale = inverse_scale[f];
                raw.iter()
                    .map(move |(_, s)| s[f] * scale)
                    .chain(std::iter::repeat_n(0.0, padding))
            })
            .collect();
        Ok(Classifier {
            classes,
            inverse_scale,
            example_class,
            example_features,
            window_px,
            class_neighbours,
        })
    }

    /// Number of learnt signatures per class.
    pub fn signatures_per_class(&self) -> Vec<usize> {
        let mut counts = vec![0; self.classes.len()];
        for &c in &self.example_class {
            counts[c] += 1;
        }
        counts
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
        let Scratch {
            standard,
            distances,
            smallest,
            found,
            nearest,
        } = scratch;
        standard.clear();
        standard.extend(
            signature
                .iter()
                .zip(&self.inverse_scale)
                .map(|(v, s)| v * s),
        );
        distances.clear();
        distances.resize(self.example_class.len().next_multiple_of(LANES), 0.0);
        self.squared_distances(standard, distances);
        // The `k` smallest distances per class, kept sorted by insertion.
        let k = self.class_neighbours.iter().copied().max().unwrap_or(1);
        smallest.clear();
        smallest.resize(self.classes.len() * k, f32::INFINITY);
        found.clear();
        found.resize(self.classes.len(), 0);
        for (&class, &d) in self.example_class.iter().zip(distances.iter()) {
            let list = &mut smallest[class * k..(class + 1) * k];
            if d < list[k - 1] {
                // Shift the larger ones up a place (the last drops out) and
                // put `d` after the last that is not larger, as a few moves
                // (the list is a handful long: no call to copy memory).
                let mut at = k - 1;
                while at > 0 && list[at - 1] > d {
                    list[at] = list[at - 1];
                    at -= 1;
                }
                list[at] = d;
            }
            found[class] += 1;
        }
        nearest.clear();
        nearest.extend((0..self.classes.len()).map(|c| {
            let n = found[c].min(self.class_neighbours[c]).max(1);
            smallest[c * k..c * k + n]
                .iter()
                .map(|d| d.sqrt())
                .sum::<f32>()
                / n as f32
        }));
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

    /// Squared distances from the standardised features `standard` to every
    /// learnt signature (`distances` holds one per padded signature).
    fn squared_distances(&self, standard: &[f32], distances: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the machine has AVX2 (checked just above).
            unsafe { self.squared_distances_avx2(standard, distances) };
            return;
        }
        self.squared_distances_in_lanes(standard, distances);
    }

    /// [`Classifier::squared_distances_in_lanes`] compiled for AVX2: a
    /// group's eight sums in one register (the same operations, each
    /// rounded as before: no fused multiply-add).
    ///
    /// # Safety
    /// The machine must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn squared_distances_avx2(&self, standard: &[f32], distances: &mut [f32]) {
        self.squared_distances_in_lanes(standard, distances);
    }

    /// Squared distances to [`LANES`] learnt signatures at a time, summed
    /// in registers in feature order.
    #[inline(always)]
    fn squared_distances_in_lanes(&self, standard: &[f32], distances: &mut [f32]) {
        let stride = distances.len();
        for (group, out) in distances.chunks_exact_mut(LANES).enumerate() {
            let mut sum = [0.0f32; LANES];
            for (column, &value) in self.example_features.chunks_exact(stride).zip(standard) {
                let lanes = &column[group * LANES..][..LANES];
                for (acc, &e) in sum.iter_mut().zip(lanes) {
                    *acc += (e - value) * (e - value);
                }
            }
            out.copy_from_slice(&sum);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX2 build of the distances rounds as the plain one, bit for bit.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn distances_compiled_for_avx2_are_the_plain_ones() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut state = 0x9e37_79b9u32;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state % 2000) as f32 / 7.0 - 100.0
        };
        let marked: Vec<(String, Vec<f32>)> = (0..21)
            .map(|k| {
                (
                    format!("class {}", k % 3),
                    (0..48).map(|_| next()).collect(),
                )
            })
            .collect();
        let classifier = Classifier::learn(marked, 8, 3).unwrap();
        let standard: Vec<f32> = (0..48).map(|_| next()).collect();
        let mut plain = vec![0.0; 24];
        let mut avx2 = vec![0.0; 24];
        classifier.squared_distances_in_lanes(&standard, &mut plain);
        // SAFETY: the machine has AVX2 (checked above).
        unsafe { classifier.squared_distances_avx2(&standard, &mut avx2) };
        let bits = |v: &[f32]| v.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&plain), bits(&avx2));
        assert!(plain[..21].iter().all(|&d| d > 0.0));
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
