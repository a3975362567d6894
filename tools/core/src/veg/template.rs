//! The marked crowns' mean brightness pattern, and how much each place of
//! an image looks like it.
//!
//! Brightness alone finds the tops of crowns that stand lit against dark
//! ground. Under a low sun a conifer's brightest point is its lit flank, and
//! in a meadow a shrub is as bright as a crown. What the marked crowns share
//! is a pattern at their size: the lit side, the shadow beside it, the ground
//! around. Each marked crown's brightness, sampled on a grid of taps around
//! its mark's centre and normalised to zero mean and unit variance, is
//! averaged into a template; an image's likeness to it at a place is the
//! normalised cross-correlation of the taps there with the template (the
//! Pearson correlation, in −1..1; Lewis, "Fast normalized
//! cross-correlation", 1995, eq. 2).
//!
//! A tap reads the brightness averaged over a `(2r+1)²` window, and taps
//! lie `2r+1` pixels apart, so the taps cover the template's square without
//! gaps and a template holds about 11×11 taps whatever the crowns' size.
//! The correlation is computed on a grid of that pitch fixed to the whole
//! image (a tile's values are the whole image's) and bilinear between its
//! nodes.

use rayon::prelude::*;

/// The template spans this many marked crowns' sides (its square's side
/// over the median side): the crown and the ground around it.
const SPAN_SIDES: f32 = 1.5;

/// About this many tap pitches across the template.
const PITCHES_ACROSS: f32 = 10.0;

/// The marked crowns' mean brightness pattern.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CrownTemplate {
    /// A tap reads the brightness averaged over the `(2r+1)²` window
    /// around it (pixels); taps lie `2r+1` pixels apart.
    pub tap_radius_px: usize,
    /// Taps from the centre to an edge: the template holds
    /// `(2·reach+1)²` taps.
    pub reach: usize,
    /// The taps' weights, row by row: zero mean, unit sum of squares.
    pub weights: Vec<f32>,
    /// The marked crowns' mean standard deviation of their taps
    /// (brightness units): the unit brightness is weighed in against the
    /// correlation.
    pub contrast: f32,
}

/// A tap pattern's place and size, from the marked crowns' median side.
fn layout(side_px: f32) -> (usize, usize) {
    let span_px = SPAN_SIDES * side_px;
    let tap_radius_px = ((span_px / PITCHES_ACROSS - 1.0) / 2.0).round().max(0.0) as usize;
    let pitch = (2 * tap_radius_px + 1) as f32;
    let reach = ((span_px / 2.0) / pitch).round().max(1.0) as usize;
    (tap_radius_px, reach)
}

impl CrownTemplate {
    /// The template of marked crowns of median side `side_px`, each given
    /// as a `w`×`h` grid of brightness and its mark's centre in that grid
    /// (pixels); windows are clipped at the grid's edges. `None` when no
    /// crown varies in brightness.
    ///
    /// ```
    /// use relevo_core::veg::template::CrownTemplate;
    /// // A bright disc on dark ground, marked twice.
    /// let (w, h) = (60, 60);
    /// let disc: Vec<f32> = (0..w * h)
    ///     .map(|i| {
    ///         let (dx, dy) = ((i % w) as f32 - 30.0, (i / w) as f32 - 30.0);
    ///         if dx * dx + dy * dy < 100.0 { 200.0 } else { 50.0 }
    ///     })
    ///     .collect();
    /// let crowns = [(&disc[..], w, h, [30.5, 30.5]), (&disc[..], w, h, [30.5, 30.5])];
    /// let t = CrownTemplate::learn(crowns, 20.0).unwrap();
    /// let mut likeness = disc.clone();
    /// t.correlate(&mut likeness, &mut Vec::new(), w, h, [0, 0]);
    /// assert!(likeness[30 * w + 30] > 0.99);
    /// ```
    pub fn learn<'a>(
        crowns: impl IntoIterator<Item = (&'a [f32], usize, usize, [f64; 2])>,
        side_px: f32,
    ) -> Option<CrownTemplate> {
        let (tap_radius_px, reach) = layout(side_px);
        let taps = 2 * reach + 1;
        let pitch = (2 * tap_radius_px + 1) as isize;
        let mut sum = vec![0.0f64; taps * taps];
        let (mut contrast_sum, mut n) = (0.0f64, 0usize);
        for (brightness, w, h, centre) in crowns {
            let (cx, cy) = (centre[0].floor() as isize, centre[1].floor() as isize);
            let values: Vec<f64> = (0..taps * taps)
                .map(|k| {
                    let x = cx + (k % taps) as isize * pitch - reach as isize * pitch;
                    let y = cy + (k / taps) as isize * pitch - reach as isize * pitch;
                    window_mean(brightness, w, h, x, y, tap_radius_px)
                })
                .collect();
            let Some((mean, std)) = mean_and_std(&values) else {
                continue;
            };
            for (s, v) in sum.iter_mut().zip(&values) {
                *s += (v - mean) / std;
            }
            contrast_sum += std;
            n += 1;
        }
        let (mean, _) = mean_and_std(&sum)?;
        let norm = sum.iter().map(|v| (v - mean).powi(2)).sum::<f64>().sqrt();
        Some(CrownTemplate {
            tap_radius_px,
            reach,
            weights: sum.iter().map(|v| ((v - mean) / norm) as f32).collect(),
            contrast: (contrast_sum / n as f64) as f32,
        })
    }

    /// Replace `values`, a `w`×`h` grid of brightness whose first cell is
    /// cell `origin` of a larger image (`[0, 0]` for a whole image), by its
    /// correlation with the template at every cell (−1..1; 0 where the
    /// brightness is flat). Values near the grid's edges read clipped
    /// windows: a tile's margin must hold the template's reach. `scratch`
    /// is working memory, resized to the grid.
    pub fn correlate(
        &self,
        values: &mut [f32],
        scratch: &mut Vec<f32>,
        w: usize,
        h: usize,
        origin: [usize; 2],
    ) {
        let pitch = 2 * self.tap_radius_px + 1;
        window_means(values, scratch, w, h, self.tap_radius_px);
        let means = &*values;
        // Nodes at multiples of the pitch of the whole image, one beyond
        // the grid on each side for the interpolation.
        let first = |o: usize| (o / pitch) as isize;
        let last = |o: usize, n: usize| ((o + n - 1) / pitch) as isize + 1;
        let (kx0, ky0) = (first(origin[0]), first(origin[1]));
        let (nx, ny) = (
            (last(origin[0], w) - kx0 + 1) as usize,
            (last(origin[1], h) - ky0 + 1) as usize,
        );
        let node_local = |k: isize, o: usize| k * pitch as isize - o as isize;
        let nodes: Vec<f32> = (0..nx * ny)
            .into_par_iter()
            .map(|k| {
                let x = node_local(kx0 + (k % nx) as isize, origin[0]);
                let y = node_local(ky0 + (k / nx) as isize, origin[1]);
                self.correlation_at(means, w, h, x, y)
            })
            .collect();
        values.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let gy = origin[1] + y;
            let (j, fy) = (
                gy / pitch - ky0 as usize,
                (gy % pitch) as f32 / pitch as f32,
            );
            for (x, v) in row.iter_mut().enumerate() {
                let gx = origin[0] + x;
                let (i, fx) = (
                    gx / pitch - kx0 as usize,
                    (gx % pitch) as f32 / pitch as f32,
                );
                let at = |i: usize, j: usize| nodes[j * nx + i];
                let top = at(i, j) * (1.0 - fx) + at(i + 1, j) * fx;
                let bottom = at(i, j + 1) * (1.0 - fx) + at(i + 1, j + 1) * fx;
                *v = top * (1.0 - fy) + bottom * fy;
            }
        });
    }

    /// The correlation of the taps around cell `(x, y)` (which may lie
    /// outside the grid: taps are clamped to it) of the window `means`.
    fn correlation_at(&self, means: &[f32], w: usize, h: usize, x: isize, y: isize) -> f32 {
        let taps = 2 * self.reach + 1;
        let pitch = (2 * self.tap_radius_px + 1) as isize;
        let start = self.reach as isize * pitch;
        let (mut cross, mut sum, mut squares) = (0.0f64, 0.0f64, 0.0f64);
        for (k, &weight) in self.weights.iter().enumerate() {
            let tx = (x + (k % taps) as isize * pitch - start).clamp(0, w as isize - 1);
            let ty = (y + (k / taps) as isize * pitch - start).clamp(0, h as isize - 1);
            let v = means[ty as usize * w + tx as usize] as f64;
            cross += weight as f64 * v;
            sum += v;
            squares += v * v;
        }
        // The weights sum to zero, so the cross term needs no mean taken
        // off; the taps' spread is the denominator (the weights' is 1).
        let spread = (squares - sum * sum / self.weights.len() as f64).max(0.0);
        if spread <= 1e-6 * squares.max(1.0) {
            0.0
        } else {
            (cross / spread.sqrt()) as f32
        }
    }
}

/// The mean of `values` over the `(2r+1)²` window around `(x, y)`, clipped
/// to the `w`×`h` grid (the nearest edge cell when the window lies wholly
/// outside).
fn window_mean(values: &[f32], w: usize, h: usize, x: isize, y: isize, r: usize) -> f64 {
    let r = r as isize;
    let clip = |v: isize, n: usize| v.clamp(0, n as isize - 1) as usize;
    let (x0, x1) = (clip(x - r, w), clip(x + r, w));
    let (y0, y1) = (clip(y - r, h), clip(y + r, h));
    let mut sum = 0.0f64;
    for row in values[y0 * w..(y1 + 1) * w].chunks_exact(w) {
        sum += row[x0..=x1].iter().map(|&v| v as f64).sum::<f64>();
    }
    sum / ((x1 - x0 + 1) * (y1 - y0 + 1)) as f64
}

/// Replace `values`, a `w`×`h` grid, by [`window_mean`] at every cell:
/// running means along the rows into `scratch`, then down the columns
/// back into `values`, in bands of rows.
fn window_means(values: &mut [f32], scratch: &mut Vec<f32>, w: usize, h: usize, r: usize) {
    scratch.resize(w * h, 0.0);
    scratch
        .par_chunks_mut(w)
        .zip(values.par_chunks(w))
        .for_each(|(out, line)| {
            let mut sum = 0.0f64;
            let (mut lo, mut hi) = (0, 0);
            for (x, o) in out.iter_mut().enumerate() {
                let (a, b) = (x.saturating_sub(r), (x + r + 1).min(w));
                for &v in &line[hi..b] {
                    sum += v as f64;
                }
                for &v in &line[lo..a] {
                    sum -= v as f64;
                }
                (lo, hi) = (a, b);
                *o = (sum / (b - a) as f64) as f32;
            }
        });
    const BAND: usize = 64;
    let rows = &*scratch;
    values
        .par_chunks_mut(BAND * w)
        .enumerate()
        .for_each(|(band, block)| {
            let y0 = band * BAND;
            let mut sums = vec![0.0f64; w];
            let (mut lo, mut hi) = (y0.saturating_sub(r), y0.saturating_sub(r));
            for (k, out) in block.chunks_exact_mut(w).enumerate() {
                let y = y0 + k;
                let (a, b) = (y.saturating_sub(r), (y + r + 1).min(h));
                for row in rows[hi * w..b * w].chunks_exact(w) {
                    sums.iter_mut().zip(row).for_each(|(s, &v)| *s += v as f64);
                }
                for row in rows[lo * w..a * w].chunks_exact(w) {
                    sums.iter_mut().zip(row).for_each(|(s, &v)| *s -= v as f64);
                }
                (lo, hi) = (a, b);
                let count = (b - a) as f64;
                out.iter_mut()
                    .zip(&sums)
                    .for_each(|(o, &s)| *o = (s / count) as f32);
            }
        });
}

/// The mean and standard deviation of `values`; `None` when they are flat.
fn mean_and_std(values: &[f64]) -> Option<(f64, f64)> {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (var > 1e-9 * mean.abs().max(1.0)).then(|| (mean, var.sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of varied brightness: crowns as bright bumps on a slope.
    fn field(w: usize, h: usize) -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let bumps = (x * 0.31).sin() * (y * 0.23).cos() * 60.0;
                100.0 + 0.2 * x + bumps + ((i * 7919) % 13) as f32
            })
            .collect()
    }

    #[test]
    fn window_means_are_the_clipped_window_means() {
        for (w, h, r) in [(37, 150, 3), (1, 20, 2), (20, 1, 4), (9, 9, 12)] {
            let values = field(w, h);
            let mut means = values.clone();
            window_means(&mut means, &mut Vec::new(), w, h, r);
            for y in 0..h {
                for x in 0..w {
                    let want = window_mean(&values, w, h, x as isize, y as isize, r);
                    let got = means[y * w + x] as f64;
                    assert!(
                        (got - want).abs() < 1e-3,
                        "{w}×{h} r {r} at {x},{y}: {got} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_tile_correlates_as_the_whole_image() {
        let (w, h) = (300, 240);
        let values = field(w, h);
        let marks = [[60.5, 70.5], [150.5, 120.5], [231.5, 180.5]];
        let template = CrownTemplate::learn(marks.map(|c| (&values[..], w, h, c)), 24.0).unwrap();
        assert_eq!(template.weights.len(), (2 * template.reach + 1).pow(2));
        let mut whole = values.clone();
        template.correlate(&mut whole, &mut Vec::new(), w, h, [0, 0]);
        assert!(whole.iter().all(|c| (-1.0001..=1.0001).contains(c)));
        // A tile with a margin wider than the template's reach and a node
        // pitch: its cells away from the cut edges are the whole image's.
        let pitch = 2 * template.tap_radius_px + 1;
        let margin = (template.reach + 2) * pitch + template.tap_radius_px;
        let [x0, y0, x1, y1] = [37, 51, 260, 240];
        let tile: Vec<f32> = (y0..y1)
            .flat_map(|y| values[y * w + x0..y * w + x1].to_vec())
            .collect();
        let (tw, th) = (x1 - x0, y1 - y0);
        let mut tiled = tile;
        template.correlate(&mut tiled, &mut Vec::new(), tw, th, [x0, y0]);
        let mut compared = 0;
        for y in margin..th {
            for x in margin..tw - margin {
                let (a, b) = (tiled[y * tw + x], whole[(y + y0) * w + x + x0]);
                assert!((a - b).abs() < 1e-4, "at {x},{y}: {a} vs {b}");
                compared += 1;
            }
        }
        assert!(compared > 10_000);
    }

    #[test]
    fn flat_brightness_is_no_likeness_and_flat_marks_no_template() {
        let (w, h) = (80, 80);
        let flat = vec![120.0f32; w * h];
        assert!(CrownTemplate::learn([(&flat[..], w, h, [40.5, 40.5])], 20.0).is_none());
        let values = field(w, h);
        // A mark centred on a node of the correlation's grid.
        let pitch = 2 * layout(20.0).0 + 1;
        let c = 40 / pitch * pitch;
        let centre = [c as f64 + 0.5; 2];
        let template = CrownTemplate::learn([(&values[..], w, h, centre)], 20.0).unwrap();
        let mut likeness = flat.clone();
        template.correlate(&mut likeness, &mut Vec::new(), w, h, [0, 0]);
        assert!(likeness.iter().all(|&c| c == 0.0));
        // At its own mark a single crown's template matches exactly.
        let mut own = values.clone();
        template.correlate(&mut own, &mut Vec::new(), w, h, [0, 0]);
        assert!(own[c * w + c] > 0.99, "{}", own[c * w + c]);
    }
}
