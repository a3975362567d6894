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
//! gaps and a template holds 9×9 to 13×13 taps whatever the crowns' size.
//! The correlation is computed on a grid of that pitch fixed to the whole
//! image (a tile's values are the whole image's) and bilinear between its
//! nodes.

use rayon::prelude::*;

/// The template spans this many marked crowns' sides (its square's side
/// over the marked side, [`super::spacing::marked_crown_size_px`]): the
/// crown and the ground around it.
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

/// The most taps from a template's centre to its edge a template read
/// from a file may have (those learnt have about 5).
const MAX_REACH: usize = 64;

/// The largest tap window radius a template read from a file may have,
/// pixels.
const MAX_TAP_RADIUS_PX: usize = 1024;

/// A tap pattern's place and size, from the marked crowns' side.
fn layout(side_px: f32) -> (usize, usize) {
    let span_px = SPAN_SIDES * side_px;
    let tap_radius_px = ((span_px / PITCHES_ACROSS - 1.0) / 2.0).round().max(0.0) as usize;
    let pitch = (2 * tap_radius_px + 1) as f32;
    let reach = ((span_px / 2.0) / pitch).round().max(1.0) as usize;
    (tap_radius_px, reach)
}

impl CrownTemplate {
    /// Why a template (read from a file) cannot be used, if it cannot: taps
    /// out of bounds, weights not one per tap or not finite, a contrast
    /// not positive.
    pub fn problem(&self) -> Option<String> {
        let taps = (2 * self.reach + 1).pow(2);
        if self.reach == 0 || self.reach > MAX_REACH || self.tap_radius_px > MAX_TAP_RADIUS_PX {
            Some(format!(
                "crown template of reach {} and tap radius {} px (at most {MAX_REACH} and {MAX_TAP_RADIUS_PX})",
                self.reach, self.tap_radius_px
            ))
        } else if self.weights.len() != taps || !self.weights.iter().all(|w| w.is_finite()) {
            Some(format!(
                "crown template with {} weights where its {taps} taps need one finite weight each",
                self.weights.len()
            ))
        } else if !(self.contrast.is_finite() && self.contrast > 0.0) {
            Some(format!(
                "crown template of contrast {}: not positive",
                self.contrast
            ))
        } else {
            None
        }
    }

    /// The template of marked crowns of side `side_px`, each given
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
    /// assert!(t.likeness(&disc, w, h, [0, 0]).at(30, 30) > 0.99);
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

    /// The likeness of a `w`×`h` grid of `brightness`, whose first cell is
    /// cell `origin` of a larger image (`[0, 0]` for a whole image), to the
    /// template. Taps read windows clipped at the grid's edges, so a tile's
    /// margin must hold the template's reach for its core to agree with
    /// the whole image.
    pub fn likeness(&self, brightness: &[f32], w: usize, h: usize, origin: [usize; 2]) -> Likeness {
        let pitch = 2 * self.tap_radius_px + 1;
        let blocks = Blocks::of(brightness, w, h, origin, self.tap_radius_px);
        // The blocks padded with their edges' copies as far as a node's
        // taps reach (a node lies at most one pitch before the first block
        // and one after the last), so taps index them directly.
        let pad = self.reach + 1;
        let across = blocks.size[0] + 2 * pad;
        let padded: Vec<f32> = (0..across * (blocks.size[1] + 2 * pad))
            .map(|k| {
                let bx = (blocks.first[0] + k % across) as isize - pad as isize;
                let by = (blocks.first[1] + k / across) as isize - pad as isize;
                blocks.mean(bx, by)
            })
            .collect();
        // The block at the padded grid's first cell.
        let corner = blocks.first.map(|f| f as isize - pad as isize);
        // Nodes at multiples of the pitch of the whole image, one beyond
        // the grid's last cell for the interpolation.
        let first = [origin[0] / pitch, origin[1] / pitch];
        let count = |a: usize, n: usize| (origin[a] + n - 1) / pitch + 2 - first[a];
        let size = [count(0, w), count(1, h)];
        let nodes = (0..size[0] * size[1])
            .into_par_iter()
            .map(|k| {
                // The node's first tap, in the padded blocks.
                let tx = (first[0] + k % size[0]) as isize - self.reach as isize - corner[0];
                let ty = (first[1] + k / size[0]) as isize - self.reach as isize - corner[1];
                self.correlation_at(&padded, across, tx as usize + ty as usize * across)
            })
            .collect();
        Likeness {
            pitch,
            origin,
            first,
            size,
            nodes,
            contrast: self.contrast,
        }
    }

    /// The correlation of the taps whose first lies at index `start` of
    /// `blocks`, a grid `across` wide.
    fn correlation_at(&self, blocks: &[f32], across: usize, start: usize) -> f32 {
        let taps = 2 * self.reach + 1;
        let (mut cross, mut sum, mut squares) = (0.0f64, 0.0f64, 0.0f64);
        for (row, weights) in self.weights.chunks_exact(taps).enumerate() {
            let values = &blocks[start + row * across..][..taps];
            for (&weight, &v) in weights.iter().zip(values) {
                let v = v as f64;
                cross += weight as f64 * v;
                sum += v;
                squares += v * v;
            }
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

/// A grid's likeness to a [`CrownTemplate`]: correlations (−1..1) at the
/// nodes of a grid of the tap pitch fixed to the whole image, bilinear
/// between them.
pub struct Likeness {
    pitch: usize,
    /// The grid's first cell in the whole image.
    origin: [usize; 2],
    /// The first node, in pitches of the whole image.
    first: [usize; 2],
    /// Nodes across and down.
    size: [usize; 2],
    nodes: Vec<f32>,
    /// The marked crowns' contrast (brightness units).
    contrast: f32,
}

impl Likeness {
    /// The likeness at cell `(x, y)` of the grid.
    pub fn at(&self, x: usize, y: usize) -> f32 {
        let (j, fy) = self.along(1, y);
        self.between(j, fy, self.along(0, x))
    }

    /// Replace each of `values` (a grid `w` wide, brightness) by itself in
    /// units of the marked crowns' contrast plus `weight` times the
    /// likeness there.
    pub fn blend_into(&self, values: &mut [f32], w: usize, weight: f32) {
        let columns: Vec<(usize, f32)> = (0..w).map(|x| self.along(0, x)).collect();
        values.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let (j, fy) = self.along(1, y);
            for (v, &column) in row.iter_mut().zip(&columns) {
                *v = *v / self.contrast + weight * self.between(j, fy, column);
            }
        });
    }

    /// Bilinear between the nodes of rows `j` and `j + 1`, `fy` of the way
    /// down, at `column` (the node before it and the fraction across).
    #[inline]
    fn between(&self, j: usize, fy: f32, (i, fx): (usize, f32)) -> f32 {
        let at = |i: usize, j: usize| self.nodes[j * self.size[0] + i];
        let top = at(i, j) * (1.0 - fx) + at(i + 1, j) * fx;
        let bottom = at(i, j + 1) * (1.0 - fx) + at(i + 1, j + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// Along axis `a`, the node before cell `c` of the grid (an index into
    /// the nodes) and the cell's fraction of the way to the next.
    fn along(&self, a: usize, c: usize) -> (usize, f32) {
        let g = self.origin[a] + c;
        (
            g / self.pitch - self.first[a],
            (g % self.pitch) as f32 / self.pitch as f32,
        )
    }
}

/// The brightness averaged over square blocks of side `2r+1` centred at the
/// multiples of `2r+1` of the whole image (the windows the taps read),
/// clipped to a grid.
struct Blocks {
    /// The first block, in pitches of the whole image.
    first: [usize; 2],
    /// Blocks across and down.
    size: [usize; 2],
    means: Vec<f32>,
}

impl Blocks {
    /// The blocks of a `w`×`h` grid of `values` whose first cell is cell
    /// `origin` of the whole image.
    fn of(values: &[f32], w: usize, h: usize, origin: [usize; 2], r: usize) -> Blocks {
        let pitch = 2 * r + 1;
        // Cell c of the grid lies in block (origin + c + r) / pitch.
        let block = |a: usize, c: usize| (origin[a] + c + r) / pitch;
        let first = [block(0, 0), block(1, 0)];
        let size = [
            block(0, w - 1) - first[0] + 1,
            block(1, h - 1) - first[1] + 1,
        ];
        let columns: Vec<usize> = (0..w).map(|x| block(0, x) - first[0]).collect();
        let mut means = vec![0.0f32; size[0] * size[1]];
        means
            .par_chunks_mut(size[0])
            .enumerate()
            .for_each(|(j, out)| {
                let mut sums = vec![0.0f64; size[0]];
                let mut counts = vec![0usize; size[0]];
                let centre = (first[1] + j) * pitch;
                let top = centre.saturating_sub(r).max(origin[1]) - origin[1];
                let bottom = (centre + r + 1 - origin[1]).min(h);
                for y in top..bottom {
                    for (&v, &b) in values[y * w..(y + 1) * w].iter().zip(&columns) {
                        sums[b] += v as f64;
                        counts[b] += 1;
                    }
                }
                for ((m, s), n) in out.iter_mut().zip(&sums).zip(&counts) {
                    *m = (s / (*n).max(1) as f64) as f32;
                }
            });
        Blocks { first, size, means }
    }

    /// The mean of block `(bx, by)` (in pitches of the whole image), the
    /// nearest block of the grid where it lies beyond.
    fn mean(&self, bx: isize, by: isize) -> f32 {
        let clip = |b: isize, a: usize| {
            (b - self.first[a] as isize).clamp(0, self.size[a] as isize - 1) as usize
        };
        self.means[clip(by, 1) * self.size[0] + clip(bx, 0)]
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
    fn a_template_read_from_a_file_is_checked() {
        let values = field(80, 80);
        let good = CrownTemplate::learn([(&values[..], 80, 80, [40.5, 40.5])], 20.0).unwrap();
        assert_eq!(good.problem(), None);
        let mut short = good.clone();
        short.weights.pop();
        assert!(short.problem().unwrap().contains("weights"));
        let far = CrownTemplate {
            reach: 1_000_000,
            ..good.clone()
        };
        assert!(far.problem().unwrap().contains("reach"));
        let flat = CrownTemplate {
            contrast: 0.0,
            ..good
        };
        assert!(flat.problem().unwrap().contains("contrast"));
    }

    #[test]
    fn blocks_are_the_windows_the_taps_read() {
        for (w, h, r, origin) in [
            (37, 150, 3, [0, 0]),
            (40, 33, 2, [11, 23]),
            (9, 9, 12, [5, 0]),
        ] {
            let values = field(w, h);
            let blocks = Blocks::of(&values, w, h, origin, r);
            let pitch = 2 * r + 1;
            for by in blocks.first[1]..blocks.first[1] + blocks.size[1] {
                for bx in blocks.first[0]..blocks.first[0] + blocks.size[0] {
                    // The block's centre in the grid (it may lie outside).
                    let x = (bx * pitch) as isize - origin[0] as isize;
                    let y = (by * pitch) as isize - origin[1] as isize;
                    let want = window_mean(&values, w, h, x, y, r);
                    let got = blocks.mean(bx as isize, by as isize) as f64;
                    let inside = (0..w as isize).contains(&x) && (0..h as isize).contains(&y);
                    if inside {
                        assert!(
                            (got - want).abs() < 1e-3,
                            "block {bx},{by}: {got} vs {want}"
                        );
                    }
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
        let whole = template.likeness(&values, w, h, [0, 0]);
        assert!((0..h).all(|y| (0..w).all(|x| (-1.0001..=1.0001).contains(&whole.at(x, y)))));
        // A tile with a margin wider than the template's reach and a node
        // pitch: its cells away from the cut edges are the whole image's.
        let pitch = 2 * template.tap_radius_px + 1;
        let margin = (template.reach + 2) * pitch + template.tap_radius_px;
        let [x0, y0, x1, y1] = [37, 51, 260, 240];
        let tile: Vec<f32> = (y0..y1)
            .flat_map(|y| values[y * w + x0..y * w + x1].to_vec())
            .collect();
        let (tw, th) = (x1 - x0, y1 - y0);
        let tiled = template.likeness(&tile, tw, th, [x0, y0]);
        let mut compared = 0;
        for y in margin..th {
            for x in margin..tw - margin {
                let (a, b) = (tiled.at(x, y), whole.at(x + x0, y + y0));
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
        let likeness = template.likeness(&flat, w, h, [0, 0]);
        assert!((0..h).all(|y| (0..w).all(|x| likeness.at(x, y) == 0.0)));
        // At its own mark a single crown's template matches exactly.
        let own = template.likeness(&values, w, h, [0, 0]).at(c, c);
        assert!(own > 0.99, "{own}");
    }
}
