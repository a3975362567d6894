//! Exact Euclidean distance transform.
//!
//! Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled Functions"
//! (Theory of Computing, 2012): the squared distance is separable, so a 1-D
//! lower envelope of parabolas along every column and then every row gives
//! the exact 2-D result in linear time.

use rayon::prelude::*;

/// Distance reported when a grid has no seed.
pub const NO_SEED: f32 = f32::MAX;

/// Distance in cells from each cell centre to the nearest seed cell centre
/// (`seed[i] == true`); seeds get 0. Row-major, `width·height` values. With no
/// seed at all every distance is [`NO_SEED`].
pub fn distance_to_seeds(seed: &[bool], width: usize, height: usize) -> Vec<f32> {
    assert_eq!(seed.len(), width * height);
    let (w, h) = (width, height);
    let far = ((w * w + h * h) as f64) * 4.0;
    let is_inside = |x: usize, y: usize| !seed[y * width + x];

    // Pass 1: along columns, stored column-major. For a binary input the 1-D
    // transform is the distance to the nearest seed above or below: two sweeps.
    let mut by_column = vec![0.0f64; w * h];
    by_column
        .par_chunks_mut(h)
        .enumerate()
        .for_each(|(x, column)| {
            let mut last: Option<usize> = None;
            for (y, value) in column.iter_mut().enumerate() {
                if !is_inside(x, y) {
                    last = Some(y);
                }
                *value = last.map_or(f64::INFINITY, |s| (y - s) as f64);
            }
            last = None;
            for (y, value) in column.iter_mut().enumerate().rev() {
                if !is_inside(x, y) {
                    last = Some(y);
                }
                let below = last.map_or(f64::INFINITY, |s| (s - y) as f64);
                let d = value.min(below);
                *value = if d.is_finite() { d * d } else { far };
            }
        });

    // Pass 2: along rows, reading the column pass transposed.
    let mut out = vec![0.0f32; width * height];
    out.par_chunks_mut(width).enumerate().for_each_init(
        || (Envelope::new(w), vec![0.0f64; w]),
        |(env, row), (y, out_row)| {
            for (x, value) in row.iter_mut().enumerate() {
                *value = by_column[x * h + y];
            }
            env.transform(row);
            for (value, squared) in out_row.iter_mut().zip(row.iter()) {
                *value = if *squared >= far {
                    NO_SEED
                } else {
                    squared.sqrt() as f32
                };
            }
        },
    );
    out
}

/// Scratch space for one 1-D squared distance transform.
struct Envelope {
    /// Positions of the parabolas in the lower envelope.
    vertex: Vec<usize>,
    /// Boundaries between consecutive parabolas.
    boundary: Vec<f64>,
    input: Vec<f64>,
}

impl Envelope {
    fn new(n: usize) -> Self {
        Envelope {
            vertex: vec![0; n],
            boundary: vec![0.0; n + 1],
            input: vec![0.0; n],
        }
    }

    /// Replaces `f` by `min_q ((p − q)² + f(q))` (Felzenszwalb & Huttenlocher, Alg. 1).
    fn transform(&mut self, f: &mut [f64]) {
        let n = f.len();
        self.input[..n].copy_from_slice(f);
        let g = &self.input;
        let intersect = |q: usize, p: usize| {
            ((g[q] + (q * q) as f64) - (g[p] + (p * p) as f64)) / (2.0 * (q as f64 - p as f64))
        };
        let mut k = 0usize;
        self.vertex[0] = 0;
        self.boundary[0] = f64::NEG_INFINITY;
        self.boundary[1] = f64::INFINITY;
        for q in 1..n {
            let mut s = intersect(q, self.vertex[k]);
            while s <= self.boundary[k] {
                k -= 1;
                s = intersect(q, self.vertex[k]);
            }
            k += 1;
            self.vertex[k] = q;
            self.boundary[k] = s;
            self.boundary[k + 1] = f64::INFINITY;
        }
        k = 0;
        for (q, out) in f.iter_mut().enumerate() {
            while self.boundary[k + 1] < q as f64 {
                k += 1;
            }
            let d = q as f64 - self.vertex[k] as f64;
            *out = d * d + g[self.vertex[k]];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force reference: nearest seed by exhaustive search.
    fn brute(seed: &[bool], w: usize, h: usize) -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                (0..w * h)
                    .filter(|&j| seed[j])
                    .map(|j| ((j % w) as f64 - x).hypot((j / w) as f64 - y))
                    .fold(f64::INFINITY, f64::min) as f32
            })
            .collect()
    }

    #[test]
    fn matches_brute_force_on_irregular_seeds() {
        let (w, h) = (23, 17);
        let seed: Vec<bool> = (0..w * h).map(|i| (i * 7919 + 13) % 29 == 0).collect();
        assert_eq!(distance_to_seeds(&seed, w, h), brute(&seed, w, h));
    }

    #[test]
    fn no_seed_is_reported() {
        let d = distance_to_seeds(&[false; 5 * 3], 5, 3);
        assert!(d.iter().all(|&v| v == NO_SEED));
    }
}
