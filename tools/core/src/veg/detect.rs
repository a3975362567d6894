//! Vegetation objects from classified regions.
//!
//! - Crowns (fine imagery, about 1 m per pixel or finer): the pixels of
//!   vegetation regions form a mask; seen from above, a crown's sunlit top is
//!   its brightest part, so crown centres are the local maxima of brightness
//!   smoothed over about a quarter of the crown spacing, inside the mask
//!   (local-maximum filtering: Wulder, Niemann & Goodenough, "Local maximum
//!   filtering for the extraction of tree locations and basal area from high
//!   spatial resolution imagery", 2000). Where crowns were marked, the value
//!   whose maxima are centres adds the likeness to the marked crowns'
//!   brightness pattern ([`super::template`]), and a centre must look like
//!   them. Centres are kept greedily from the highest value with at least
//!   `spacing_px` between them. An object's size is what most marked crowns
//!   reach, or without marks the diameter of the largest disc of vegetation
//!   around its centre (see [`Placement::Crowns`]).
//! - Fill (coarse imagery, e.g. 30 m Landsat, where a pixel holds many trees):
//!   each vegetation pixel area receives objects from a jittered grid of
//!   `spacing_px`, the jitter a hash of the grid cell, so the same region
//!   always gets the same objects whatever order it is processed in.

use super::classify::Label;
use super::segment::Segmentation;
use super::template::{CrownTemplate, Likeness};
use rayon::prelude::*;

/// Weight of the likeness to the marked crowns (a correlation, −1..1)
/// against brightness (in units of the marked crowns' contrast) in the
/// value whose local maxima are crown centres: a correlation 0.25 higher
/// outweighs one unit of contrast.
pub const LIKENESS_WEIGHT: f32 = 4.0;

/// A centre whose likeness to the marked crowns is this or less is not a
/// crown.
pub const MIN_LIKENESS: f32 = 0.2;

/// A ray from a crown's centre stops once the placement value climbs this
/// much above the lowest it has passed: it is on the next crown's slope
/// (the value's units: the marks' contrasts, see [`place_crowns`]).
pub const VALLEY_RISE: f32 = 0.2;

/// A crown's size stays within these fractions of the marked size: the
/// span over which a box of the marked size still overlaps a crown's box
/// by IoU 0.4 (0.63–1.58).
pub const SIZE_RANGE: [f32; 2] = [0.6, 1.6];

/// How vegetation regions become objects.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "mode", rename_all = "lowercase")]
pub enum Placement {
    /// One object per crown.
    Crowns {
        /// Smallest distance between crown centres (pixels).
        spacing_px: f32,
        /// Crowns whose disc radius is smaller are dropped (pixels).
        min_radius_px: f32,
        /// What most marked crowns reach (pixels,
        /// [`super::spacing::marked_crown_size_px`]): each crown's size is
        /// drawn from it toward the valleys around the crown
        /// (valley following). None when no crown was marked: a crown's
        /// size is then the diameter of its disc of vegetation.
        #[serde(default)]
        marked_size_px: Option<f32>,
        /// The marked crowns' brightness pattern: crowns are centred
        /// where brightness and likeness to it together peak, and only
        /// where the likeness exceeds [`MIN_LIKENESS`]. None when no crown
        /// was marked (then brightness alone places them).
        #[serde(default)]
        template: Option<CrownTemplate>,
    },
    /// Objects on a jittered grid inside vegetation regions.
    Fill {
        /// Grid spacing (pixels); one object per `spacing_px²` of vegetation.
        spacing_px: f32,
        /// Size given to every object (pixels).
        diameter_px: f32,
    },
}

impl Placement {
    /// Why a placement read from a file cannot be used, if it cannot: a
    /// marked crown size that is not a positive number of pixels, or a
    /// crown template that does not hold together
    /// ([`CrownTemplate::problem`]).
    pub fn problem(&self) -> Option<String> {
        match self {
            Placement::Crowns {
                marked_size_px,
                template,
                ..
            } => match marked_size_px {
                Some(m) if !(m.is_finite() && *m > 0.0) => {
                    Some(format!("marked crown size of {m} px: not positive"))
                }
                _ => template.as_ref().and_then(CrownTemplate::problem),
            },
            Placement::Fill { .. } => None,
        }
    }
}

/// A detected object in pixel coordinates.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Object {
    pub x: f64,
    pub y: f64,
    pub class: usize,
    /// Diameter in pixels.
    pub size_px: f32,
    pub score: f32,
}

/// Per-pixel working arrays of crown placement (whether a pixel is outside
/// vegetation, its smoothed brightness, the blur's rows: 9 bytes a pixel),
/// kept by a worker that places crowns on tile after tile so their memory
/// is mapped once.
#[derive(Default)]
pub struct DetectBuffers {
    outside: Vec<bool>,
    value: Vec<f32>,
    rows: Vec<f32>,
}

/// Objects for every pixel whose region's class is in `vegetation` (and
/// that has data, where `valid` is given), sorted by row then column.
/// `origin` is where the image's first pixel lies in a larger image it is a
/// tile of (`[0, 0]` for a whole image): the fill grid is that image's.
/// `buffers` may hold an earlier call's arrays, to be reused.
#[allow(clippy::too_many_arguments)]
pub fn detect(
    image: &super::Image,
    segmentation: &Segmentation,
    labels: &[Label],
    vegetation: &[bool],
    valid: Option<&[bool]>,
    placement: &Placement,
    origin: [usize; 2],
    buffers: &mut DetectBuffers,
) -> Vec<Object> {
    let (w, h) = (segmentation.width, segmentation.height);
    let label_at = |i: usize| labels[segmentation.labels[i] as usize];
    // Per region: whether its class is vegetation (one lookup a pixel).
    let region_is_vegetation: Vec<bool> = labels.iter().map(|l| vegetation[l.class]).collect();
    let is_vegetation = |i: usize| {
        region_is_vegetation[segmentation.labels[i] as usize] && valid.is_none_or(|v| v[i])
    };
    let object = |x: f64, y: f64, size_px: f32| {
        let label = label_at(y as usize * w + x as usize);
        Object {
            x,
            y,
            class: label.class,
            size_px,
            score: label.score,
        }
    };
    let mut objects: Vec<Object> = match placement {
        &Placement::Fill {
            spacing_px,
            diameter_px,
        } => {
            let s = spacing_px.max(1e-3) as f64;
            let (ox, oy) = (origin[0] as f64, origin[1] as f64);
            let cells =
                |o: f64, n: usize| (o / s).floor() as u64..((o + n as f64) / s).ceil() as u64;
            let (columns, rows) = (cells(ox, w), cells(oy, h));
            rows.into_par_iter()
                .flat_map_iter(|j| {
                    columns.clone().filter_map(move |i| {
                        let r = splitmix64(j << 32 | i);
                        let u = (r >> 40) as f64 / (1u64 << 24) as f64;
                        let v = (r & 0xff_ffff) as f64 / (1u64 << 24) as f64;
                        let (x, y) = ((i as f64 + u) * s - ox, (j as f64 + v) * s - oy);
                        (x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64).then_some((x, y))
                    })
                })
                .filter(|&(x, y)| is_vegetation(y as usize * w + x as usize))
                .map(|(x, y)| object(x, y, diameter_px))
                .collect()
        }
        Placement::Crowns {
            spacing_px,
            min_radius_px,
            marked_size_px,
            template,
        } => {
            let (spacing_px, min_radius_px) = (*spacing_px, *min_radius_px);
            let DetectBuffers {
                outside,
                value,
                rows,
            } = buffers;
            outside.clear();
            outside.par_extend((0..w * h).into_par_iter().map(|i| !is_vegetation(i)));
            let outside: &[bool] = outside;
            // Sunlit tops: smoothed brightness, only inside vegetation.
            image.brightness_into(value);
            let likeness = template.as_ref().map(|t| t.likeness(value, w, h, origin));
            let kept = place_crowns(
                value,
                rows,
                outside,
                w,
                h,
                spacing_px,
                min_radius_px,
                likeness.as_ref(),
            );
            let value: &[f32] = value;
            kept.into_iter()
                .map(|(i, radius)| {
                    let (x, y) = (i % w, i / w);
                    let size_px = match *marked_size_px {
                        Some(marked) => valley_size_px(value, w, h, i, marked),
                        None => 2.0 * radius,
                    };
                    object(x as f64 + 0.5, y as f64 + 0.5, size_px)
                })
                .collect()
        }
    };
    objects.sort_by(|a, b| a.y.total_cmp(&b.y).then(a.x.total_cmp(&b.x)));
    objects
}

/// Crown centres on a `w`×`h` grid of `value`s (brightness, a greenness
/// index: larger at a crown's top), outside the cells marked `outside`:
/// the values are smoothed over about a third of `spacing_px` (and, with a
/// `likeness`, taken in its contrast's units plus [`LIKENESS_WEIGHT`] times
/// its correlation, and a centre must be liker than [`MIN_LIKENESS`]), a centre is
/// the maximum of its window of `spacing_px` inside the mask with a disc of
/// at least `min_radius_px` of mask around it, and centres are kept from
/// the highest value down, at least `spacing_px` apart (Wulder, Niemann &
/// Goodenough 2000). Returns each centre's cell index and disc radius
/// (pixels), best first; `value` is left smoothed (−∞-like outside) and
/// `rows` is scratch of the same size.
#[allow(clippy::too_many_arguments)]
pub fn place_crowns(
    value: &mut [f32],
    rows: &mut Vec<f32>,
    outside: &[bool],
    w: usize,
    h: usize,
    spacing_px: f32,
    min_radius_px: f32,
    likeness: Option<&Likeness>,
) -> Vec<(usize, f32)> {
    let blur = (0.3 * spacing_px).round() as usize;
    // The blur writes every row's means before it reads them.
    rows.resize(w * h, 0.0);
    box_blur(value, rows, w, h, blur);
    box_blur(value, rows, w, h, blur);
    if let Some(l) = likeness {
        l.blend_into(value, w, LIKENESS_WEIGHT);
    }
    value.par_iter_mut().zip(outside).for_each(|(v, &out)| {
        if out {
            *v = f32::MIN;
        }
    });
    // Candidates: maxima of their (2r+1)² window (each is first a
    // 3×3 maximum, a cheap test that few pixels pass) with a disc of
    // vegetation of at least the smallest radius around them.
    let r = (spacing_px.max(1.0) / 2.0).ceil() as usize;
    let limit = (2.0 * spacing_px).ceil().max(2.0) as usize;
    let min_radius = min_radius_px.max(1.0);
    let mut candidates: Vec<(usize, f32)> = local_maxima(value, outside, w, h)
        .into_par_iter()
        .filter(|&i| likeness.is_none_or(|l| l.at(i % w, i / w) > MIN_LIKENESS))
        .filter(|&i| is_window_max(value, w, h, i % w, i / w, r))
        .map(|i| (i, vegetation_radius(outside, w, h, i, limit)))
        .filter(|&(_, radius)| radius >= min_radius)
        .collect();
    candidates.sort_by(|a, b| value[b.0].total_cmp(&value[a.0]).then(a.0.cmp(&b.0)));
    suppress(&candidates, w, spacing_px.max(1.0))
}

/// The smallest and largest size a crown may be given when the marked
/// crowns' size is `marked` ([`SIZE_RANGE`] of it, same unit).
pub fn crown_size_range(marked: f32) -> [f32; 2] {
    SIZE_RANGE.map(|f| f * marked)
}

/// The size of the crown centred on cell `i` of the placement values
/// `value` (smoothed, `f32::MIN` outside vegetation, as [`place_crowns`]
/// leaves them), given the marked crowns' size `marked_px`: valley
/// following (Gougeon 1995) along eight rays from the centre, each ending
/// at the lowest value it passes before the value climbs [`VALLEY_RISE`]
/// again, or at the first cell outside vegetation; the crown's diameter
/// measured is twice the median ray. One crown's valleys are noisy (a
/// shadow, a gap, a branch), so the size is the geometric mean of the
/// measured and the marked sizes, within [`SIZE_RANGE`] of the marked.
fn valley_size_px(value: &[f32], w: usize, h: usize, i: usize, marked_px: f32) -> f32 {
    let [low, high] = crown_size_range(marked_px);
    // A ray looks as far as the largest crown's radius.
    let max_len_px = (high / 2.0).ceil();
    let (x, y) = ((i % w) as isize, (i / w) as isize);
    let mut rays: [f32; 8] = [
        (1, 0),
        (1, 1),
        (0, 1),
        (-1, 1),
        (-1, 0),
        (-1, -1),
        (0, -1),
        (1, -1),
    ]
    .map(|(dx, dy): (isize, isize)| {
        let step_px = ((dx * dx + dy * dy) as f32).sqrt();
        let (mut lowest, mut valley) = (value[i], 0);
        let mut n = 1;
        while n as f32 * step_px <= max_len_px {
            let (cx, cy) = (x + dx * n, y + dy * n);
            if cx < 0 || cy < 0 || cx >= w as isize || cy >= h as isize {
                break;
            }
            let v = value[cy as usize * w + cx as usize];
            if v == f32::MIN {
                valley = n;
                break;
            }
            if v < lowest {
                (lowest, valley) = (v, n);
            } else if v > lowest + VALLEY_RISE {
                break;
            }
            n += 1;
        }
        valley as f32 * step_px
    });
    rays.sort_by(f32::total_cmp);
    let measured_px = (rays[3] + rays[4]).max(1.0);
    (marked_px * measured_px).sqrt().clamp(low, high)
}

/// Replace each cell of `values` by the mean over the `(2r+1)²` window
/// around it, clipped at the edges (separable running sums; `rows` holds the
/// rows' means in between).
fn box_blur(values: &mut [f32], rows: &mut [f32], w: usize, h: usize, r: usize) {
    // Rows, a few at a time: their running sums side by side are independent
    // chains of additions the processor overlaps. The rows are first laid
    // out column by column (a pixel's ROWS values together), so each step
    // adds, subtracts and divides them as one vector.
    const ROWS: usize = 8;
    rows.par_chunks_mut(ROWS * w)
        .zip(values.par_chunks(ROWS * w))
        .for_each_init(
            || (vec![[0.0f32; ROWS]; w], vec![[0.0f32; ROWS]; w]),
            |(across, means), (out, lines)| {
                for (k, line) in lines.chunks_exact(w).enumerate() {
                    for (column, &v) in across.iter_mut().zip(line) {
                        column[k] = v;
                    }
                }
                slide_window(
                    &mut [0.0f64; ROWS],
                    w,
                    r,
                    0..w,
                    |sums, x| {
                        for (s, &v) in sums.iter_mut().zip(&across[x]) {
                            *s += v as f64;
                        }
                    },
                    |sums, x| {
                        for (s, &v) in sums.iter_mut().zip(&across[x]) {
                            *s -= v as f64;
                        }
                    },
                    |sums, x, count| {
                        for (m, &s) in means[x].iter_mut().zip(sums.iter()) {
                            *m = (s / count as f64) as f32;
                        }
                    },
                );
                for (k, line) in out.chunks_exact_mut(w).enumerate() {
                    for (o, column) in line.iter_mut().zip(means.iter()) {
                        *o = column[k];
                    }
                }
            },
        );
    // Columns: bands of rows, each with its own running column sums.
    const BAND: usize = 128;
    let rows = &*rows;
    values
        .par_chunks_mut(BAND * w)
        .enumerate()
        .for_each(|(band, block)| {
            let y0 = band * BAND;
            slide_window(
                &mut vec![0.0f64; w],
                h,
                r,
                y0..y0 + block.len() / w,
                |sums, y| {
                    sums.iter_mut()
                        .zip(&rows[y * w..(y + 1) * w])
                        .for_each(|(s, v)| *s += *v as f64);
                },
                |sums, y| {
                    sums.iter_mut()
                        .zip(&rows[y * w..(y + 1) * w])
                        .for_each(|(s, v)| *s -= *v as f64);
                },
                |sums, y, count| {
                    block[(y - y0) * w..(y - y0 + 1) * w]
                        .iter_mut()
                        .zip(&*sums)
                        .for_each(|(o, s)| *o = (s / count as f64) as f32);
                },
            );
        });
}

/// Slide the window of positions `p − r ..= p + r`, clipped to `0..n`,
/// over the positions `along` (in `0..n`): `enter(state, i)` as position i
/// comes into the window, `leave(state, i)` as it goes out, then
/// `at(state, p, size)` with the window at `p` and its size — running sums
/// in O(n), whatever `r`.
#[inline(always)]
fn slide_window<S: ?Sized>(
    state: &mut S,
    n: usize,
    r: usize,
    along: std::ops::Range<usize>,
    enter: impl Fn(&mut S, usize),
    leave: impl Fn(&mut S, usize),
    mut at: impl FnMut(&mut S, usize, usize),
) {
    let start = along.start.saturating_sub(r);
    let (mut lo, mut hi) = (start, start);
    for p in along {
        let (want_lo, want_hi) = (p.saturating_sub(r), (p + r + 1).min(n));
        while hi < want_hi {
            enter(state, hi);
            hi += 1;
        }
        while lo < want_lo {
            leave(state, lo);
            lo += 1;
        }
        at(state, p, hi - lo);
    }
}

/// Keep candidates (pixel index and radius, best first) at least `spacing` apart.
fn suppress(candidates: &[(usize, f32)], w: usize, spacing: f32) -> Vec<(usize, f32)> {
    let cell = spacing as f64;
    let key = |x: f64, y: f64| ((x / cell) as i64, (y / cell) as i64);
    let mut grid: std::collections::HashMap<(i64, i64), Vec<(f64, f64)>> =
        std::collections::HashMap::new();
    let mut kept = Vec::new();
    let limit = cell * cell;
    for &(i, radius) in candidates {
        let (x, y) = ((i % w) as f64, (i / w) as f64);
        let (cx, cy) = key(x, y);
        let close = (cx - 1..=cx + 1).any(|gx| {
            (cy - 1..=cy + 1).any(|gy| {
                grid.get(&(gx, gy)).is_some_and(|points| {
                    points
                        .iter()
                        .any(|&(px, py)| (px - x).powi(2) + (py - y).powi(2) < limit)
                })
            })
        });
        if !close {
            grid.entry((cx, cy)).or_default().push((x, y));
            kept.push((i, radius));
        }
    }
    kept
}

/// The cells not `outside` that hold the maximum of their 3×3 window
/// (clipped at the edges; ties allowed), in row order: [`is_window_max`]
/// with r = 1 at every cell, as the rows' running maxima of three-row
/// column maxima. `values` must be finite (NaN-free), so that a cell is its
/// window's maximum exactly when it is at least the window's largest value.
fn local_maxima(values: &[f32], outside: &[bool], w: usize, h: usize) -> Vec<usize> {
    const BAND: usize = 64;
    (0..h.div_ceil(BAND))
        .into_par_iter()
        .flat_map_iter(|band| {
            let mut column_max = vec![0.0f32; w];
            let mut window_max = vec![0.0f32; w];
            let mut found = Vec::new();
            for y in band * BAND..((band + 1) * BAND).min(h) {
                let rows = y.saturating_sub(1)..(y + 2).min(h);
                column_max.copy_from_slice(&values[rows.start * w..(rows.start + 1) * w]);
                for yy in rows.start + 1..rows.end {
                    let row = &values[yy * w..(yy + 1) * w];
                    for (m, &v) in column_max.iter_mut().zip(row) {
                        *m = m.max(v);
                    }
                }
                // Along the row: the column maxima at x − 1, x and x + 1.
                window_max.copy_from_slice(&column_max);
                for (m, &right) in window_max.iter_mut().zip(&column_max[1..]) {
                    *m = m.max(right);
                }
                for (m, &left) in window_max[1..].iter_mut().zip(&column_max) {
                    *m = m.max(left);
                }
                let row = &values[y * w..(y + 1) * w];
                let row_outside = &outside[y * w..(y + 1) * w];
                for (x, ((&v, &m), &out)) in
                    row.iter().zip(&window_max).zip(row_outside).enumerate()
                {
                    if !out && v >= m {
                        found.push(y * w + x);
                    }
                }
            }
            found
        })
        .collect()
}

/// Whether cell `(x, y)` holds the maximum of the `(2r+1)²` window around
/// it (clipped at the edges; ties allowed).
fn is_window_max(values: &[f32], w: usize, h: usize, x: usize, y: usize, r: usize) -> bool {
    let v = values[y * w + x];
    (y.saturating_sub(r)..(y + r + 1).min(h)).all(|yy| {
        values[yy * w + x.saturating_sub(r)..yy * w + (x + r + 1).min(w)]
            .iter()
            .all(|&u| u <= v)
    })
}

/// Distance from cell `i` to the nearest `outside` cell centre, searched in
/// growing square rings up to `limit` cells (returned when none is nearer):
/// the radius of the largest disc of vegetation around the cell.
fn vegetation_radius(outside: &[bool], w: usize, h: usize, i: usize, limit: usize) -> f32 {
    if outside[i] {
        return 0.0;
    }
    let (x, y) = ((i % w) as i64, (i / w) as i64);
    let mut best = (limit * limit) as i64;
    for d in 1..=limit as i64 {
        if d * d >= best {
            break;
        }
        for k in -d..=d {
            for (dx, dy) in [(k, -d), (k, d), (-d, k), (d, k)] {
                let (xx, yy) = (x + dx, y + dy);
                let inside = xx >= 0 && yy >= 0 && xx < w as i64 && yy < h as i64;
                if inside && outside[yy as usize * w + xx as usize] {
                    best = best.min(dx * dx + dy * dy);
                }
            }
        }
    }
    (best as f32).sqrt()
}

/// SplitMix64 (Steele, Lea & Flood 2014): a well-mixed hash of a grid cell
/// (or of any counter).
pub(crate) fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vegetation_radius_is_the_distance_transform() {
        use crate::raster::distance::distance_to_seeds;
        let (w, h) = (41, 29);
        let outside: Vec<bool> = (0..w * h)
            .map(|i| (i * 7919) % 23 == 0 || (i % w) * (i / w) % 37 == 5)
            .collect();
        let exact = distance_to_seeds(&outside, w, h);
        for (i, &want) in exact.iter().enumerate() {
            let r = vegetation_radius(&outside, w, h, i, 60);
            assert!((r - want).abs() < 1e-4, "cell {i}: {r} vs {want}");
        }
        // Beyond the limit the search stops at the limit.
        assert_eq!(vegetation_radius(&[false; 100], 10, 10, 55, 3), 3.0);
    }

    #[test]
    fn fill_is_deterministic_at_the_density_and_skips_pixels_without_data() {
        use super::super::segment::{Segment, Segmentation};
        use super::super::Image;
        let (w, h) = (40, 30);
        let image = Image::new(w, h, 1, vec![100; w * h]).unwrap();
        let segmentation = Segmentation {
            width: w,
            height: h,
            labels: vec![0; w * h],
            regions: vec![Segment {
                pixels: (w * h) as u32,
                bbox: [0, 0, w as u32, h as u32],
                centroid: [20.0, 15.0],
                mean: [100.0, 0.0, 0.0, 0.0],
                std: [0.0; 4],
            }],
            leaves: 1,
            steps: Default::default(),
        };
        let labels = [Label {
            class: 0,
            score: 0.9,
        }];
        let fill = Placement::Fill {
            spacing_px: 2.0,
            diameter_px: 2.0,
        };
        let mut buffers = DetectBuffers::default();
        let mut place = |vegetation: &[bool], valid: Option<&[bool]>| {
            let origin = [0, 0];
            detect(
                &image,
                &segmentation,
                &labels,
                vegetation,
                valid,
                &fill,
                origin,
                &mut buffers,
            )
        };
        let all = place(&[true], None);
        // One object per 2×2 pixels.
        assert_eq!(all.len(), w * h / 4);
        assert_eq!(all, place(&[true], None));
        // No data in the left half: objects only on the right.
        let valid: Vec<bool> = (0..w * h).map(|i| i % w >= 20).collect();
        let right = place(&[true], Some(&valid));
        assert!(right.iter().all(|o| o.x >= 20.0));
        assert_eq!(right.len(), all.iter().filter(|o| o.x >= 20.0).count());
        // A class that is not vegetation gets nothing.
        assert!(place(&[false], None).is_empty());
    }

    /// One crown on a disc of vegetation 10 px in radius, brightest at its
    /// centre: with no crown marked its size is the disc's diameter; with
    /// a marked size, the geometric mean of that size and the disc's
    /// diameter along the rays (no valley before the disc's edge).
    #[test]
    fn a_crown_has_the_disc_size_drawn_toward_the_marked_size() {
        use super::super::segment::{Segment, Segmentation};
        use super::super::Image;
        let (w, h, radius) = (61usize, 61usize, 10.0f64);
        let inside = |i: usize| {
            let (x, y) = ((i % w) as f64 - 30.0, (i / w) as f64 - 30.0);
            x.hypot(y) <= radius
        };
        // Brightest at the disc's centre.
        let pixels: Vec<u8> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64 - 30.0, (i / w) as f64 - 30.0);
                (200.0 - 4.0 * x.hypot(y)).max(0.0) as u8
            })
            .collect();
        let image = Image::new(w, h, 1, pixels).unwrap();
        // Placement reads only the labels: the regions' descriptions are
        // placeholders.
        let region = Segment {
            pixels: 0,
            bbox: [0, 0, w as u32, h as u32],
            centroid: [30.0, 30.0],
            mean: [0.0; 4],
            std: [0.0; 4],
        };
        let segmentation = Segmentation {
            width: w,
            height: h,
            labels: (0..w * h).map(|i| u32::from(!inside(i))).collect(),
            regions: vec![region; 2],
            leaves: 2,
            steps: Default::default(),
        };
        let labels = [0, 1].map(|class| Label { class, score: 0.9 });
        let size = |marked_size_px| {
            let placement = Placement::Crowns {
                spacing_px: 20.0,
                min_radius_px: 2.0,
                marked_size_px,
                template: None,
            };
            let found = detect(
                &image,
                &segmentation,
                &labels,
                &[true, false],
                None,
                &placement,
                [0, 0],
                &mut DetectBuffers::default(),
            );
            assert_eq!(found.len(), 1);
            assert_eq!((found[0].x, found[0].y), (30.5, 30.5));
            found[0].size_px
        };
        let measured = size(None);
        assert!((measured - 2.0 * radius as f32).abs() <= 2.0, "{measured}");
        // The rays leave the disc at 11 px along the axes and at 8
        // diagonal steps (11.3 px).
        let rays_px = 11.0 + 8.0 * std::f32::consts::SQRT_2;
        let drawn = size(Some(25.0));
        assert!((drawn - (25.0 * rays_px).sqrt()).abs() < 1e-3, "{drawn}");
    }

    /// Cones on a lattice 20 px apart: rays from a cone's top end in the
    /// valleys, 10 px away along the axes and 10√2 px along the diagonals,
    /// so the crown measures 10 + 10√2 px; its size is the geometric mean
    /// with the marked size, kept within [`SIZE_RANGE`] of it; a ray
    /// leaving vegetation ends at the first cell outside.
    #[test]
    fn a_crowns_size_follows_the_valleys_toward_the_marked_size() {
        let (w, h) = (101usize, 101usize);
        let mut value: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let (dx, dy) = ((x + 10.0) % 20.0 - 10.0, (y + 10.0) % 20.0 - 10.0);
                30.0 - dx.hypot(dy)
            })
            .collect();
        let top = 60 * w + 40;
        assert_eq!(value[top], 30.0);
        let measured = 10.0 + 10.0 * std::f32::consts::SQRT_2;
        let size = valley_size_px(&value, w, h, top, 20.0);
        assert!((size - (20.0 * measured).sqrt()).abs() < 1e-3, "{size}");
        // A marked size far above the measured one holds the size up.
        let held = valley_size_px(&value, w, h, top, 100.0);
        assert!((held - SIZE_RANGE[0] * 100.0).abs() < 1e-3, "{held}");
        // Vegetation ending 6 px from the top: the rays end at 7 px along
        // the axes and at 5 diagonal steps.
        for (i, v) in value.iter_mut().enumerate() {
            let (dx, dy) = ((i % w) as f32 - 40.0, (i / w) as f32 - 60.0);
            if dx.hypot(dy) > 6.0 {
                *v = f32::MIN;
            }
        }
        let edge = 7.0 + 5.0 * std::f32::consts::SQRT_2;
        let size = valley_size_px(&value, w, h, top, 20.0);
        assert!((size - (20.0 * edge).sqrt()).abs() < 1e-3, "{size}");
    }

    /// A placement read from a file is refused when its marked crown size
    /// is not a positive number of pixels (sizes are kept within a range of
    /// it) or its template does not hold together.
    #[test]
    fn placements_read_from_a_file_are_checked() {
        let crowns = |marked_size_px, template| Placement::Crowns {
            spacing_px: 10.0,
            min_radius_px: 2.0,
            marked_size_px,
            template,
        };
        assert_eq!(crowns(Some(20.0), None).problem(), None);
        assert_eq!(crowns(None, None).problem(), None);
        for bad in [0.0, -5.0, f32::NAN, f32::INFINITY] {
            let problem = crowns(Some(bad), None).problem().unwrap();
            assert!(problem.contains("not positive"), "{problem}");
        }
        let broken = CrownTemplate {
            tap_radius_px: 1,
            reach: 1,
            weights: vec![1.0],
            contrast: 1.0,
        };
        let problem = crowns(Some(20.0), Some(broken)).problem().unwrap();
        assert!(problem.contains("weights"), "{problem}");
    }

    #[test]
    fn window_maximum() {
        let values = [1.0, 2.0, 1.0, 0.0, 5.0, 0.0, 1.0, 2.0, 1.0];
        assert!(is_window_max(&values, 3, 3, 1, 1, 1));
        assert!(!is_window_max(&values, 3, 3, 1, 0, 1));
        assert!(is_window_max(&values, 3, 3, 1, 0, 0));
    }

    /// The 3×3 maxima found by rows are the cells [`is_window_max`] takes
    /// (r = 1) outside `outside`: many ties, `f32::MIN` cells, edges, and
    /// grids one cell wide or high, across more than one band of rows.
    #[test]
    fn local_maxima_are_the_three_by_three_window_maxima() {
        for (w, h) in [(37, 150), (1, 70), (70, 1), (2, 2), (65, 129)] {
            let values: Vec<f32> = (0..w * h)
                .map(|i| match (i * 7919) % 11 {
                    0 => f32::MIN,
                    k => (k % 4) as f32 * 0.5,
                })
                .collect();
            let outside: Vec<bool> = (0..w * h).map(|i| (i * 31) % 7 == 0).collect();
            let want: Vec<usize> = (0..w * h)
                .filter(|&i| !outside[i] && is_window_max(&values, w, h, i % w, i / w, 1))
                .collect();
            assert!(!want.is_empty());
            assert_eq!(local_maxima(&values, &outside, w, h), want, "{w}×{h}");
        }
    }

    #[test]
    fn box_blur_is_the_clipped_window_mean() {
        // 9 rows: one whole group of rows blurred together and one row alone.
        let (w, h) = (20, 9);
        let values: Vec<f32> = (0..w * h).map(|i| (i % 13) as f32).collect();
        let r = 2;
        let mut blurred = values.clone();
        box_blur(&mut blurred, &mut vec![0.0; w * h], w, h, r);
        // Windows are clipped at the edges (at x = 0 the row window holds 3
        // values); the mean of row means is the window's mean.
        let row_mean = |x: usize, y: usize| {
            let xs = x.saturating_sub(r)..(x + r + 1).min(w);
            let n = xs.len() as f32;
            xs.map(|xx| values[y * w + xx]).sum::<f32>() / n
        };
        for y in 0..h {
            for x in 0..w {
                let ys = y.saturating_sub(r)..(y + r + 1).min(h);
                let n = ys.len() as f32;
                let expected = ys.map(|yy| row_mean(x, yy)).sum::<f32>() / n;
                assert!((blurred[y * w + x] - expected).abs() < 1e-5, "({x}, {y})");
            }
        }
    }
}
