//! The screen as the raycaster marches it: rows and lines of a camera that
//! may pitch.
//!
//! Level (pitch 0), each screen column sees one vertical half-plane through
//! the eye, and the floating horizon marches columns (seed 000, chapter 4).
//! Pitched by θ, vertical lines of the world no longer stay vertical on the
//! screen: they converge on the vertical vanishing point, the nadir below the
//! screen when looking down or the zenith above it when looking up, at
//! d·cot θ pixels from the principal point (d the plane distance in pixels).
//! A vertical half-plane through the eye then projects to a screen *line*
//! through that point, and the pixels of one line are exactly those whose
//! rays lie in that half-plane — so the floating horizon marches lines
//! instead of columns, with unchanged occlusion: along a line, a higher row
//! is a higher elevation angle within the half-plane.
//!
//! Rows and lines separate. With the camera's right axis horizontal (no
//! roll), the ray of row r at ρ = r + ½ − incl pixels above the principal
//! point advances α(r) = d·cos θ − ρ·sin θ horizontally forward and rises
//! β(r) = d·sin θ + ρ·cos θ per unit of the ray, whatever the column. So a
//! sample at horizontal forward distance s and height Δz above the eye covers
//! row r exactly when Δz > s·β(r)/α(r), and the pixel it paints there has view
//! depth s·d/α(r): a table per row, a comparison per sample, and depths equal
//! to the GPU's for the pitched projection. At θ = 0, α = d and β = ρ: the
//! level renderer's projection incl + d·Δz/s and its per-slice depth.
//!
//! A line is the half-plane whose ground direction is forward + a·right; its
//! pixel on row r is at x = a·α(r) from the centre column. Lines are spaced
//! evenly in a, through the pixel centres of the row nearest the horizon
//! line, where far terrain and its silhouettes lie; each pixel takes the line
//! nearest it (a rule the painter and the gather share). Rows nearer the
//! vanishing point get more lines than pixels, which is the price of a tilt:
//! the work grows with max α / min α, and pitches where it
//! would exceed [`MAX_LINE_DENSITY`] (or where a row would look backwards)
//! are refused — see [`pitch_range`].

use crate::camera::Camera;
use crate::{Error, Result};

/// The most lines marched per screen column (at the rows nearest the
/// vanishing point): bounds the cost of a tilt to this many times the level
/// renderer's.
pub const MAX_LINE_DENSITY: f64 = 4.0;

/// Rows and lines of one camera; buffers reused from frame to frame.
#[derive(Debug, Default)]
pub(super) struct Screen {
    pub width: usize,
    pub height: usize,
    /// Per row from the bottom: rise of the row's ray per metre of
    /// horizontal forward distance, β(r)/α(r).
    pub slope: Vec<f64>,
    /// Per row: α(r)/d, so that a pixel's view depth is s / this.
    pub forward_per_depth: Vec<f64>,
    /// Line j's ground direction is forward + (first_offset + j·offset_step)·right.
    pub first_offset: f64,
    pub offset_step: f64,
    pub lines: usize,
    /// Per line: the rows [lo, hi) on which some pixel takes it.
    pub rows_needed: Vec<[usize; 2]>,
    /// Per row: pixel column p takes line ⌊p·scale + shift + ½⌋ (see
    /// [`Screen::line_at`]).
    pub row_map: Vec<[f64; 2]>,
    /// Whether lines differ from columns (pitch ≠ 0).
    pub pitched: bool,
}

/// α and β in pixels of the rays `rho` pixels above the principal point:
/// how far they advance horizontally forward and rise per unit
/// (forward = cos θ·level + sin θ·up, the camera's up = −sin θ·level + cos θ·up).
pub(super) fn ray_at(camera: &Camera, rho: f64) -> (f64, f64) {
    let d = camera.plane_distance_px();
    let (sin, cos) = camera.pitch_deg.to_radians().sin_cos();
    (d * cos - rho * sin, d * sin + rho * cos)
}

/// α(r) and β(r) in pixels for row `r` from the bottom.
fn row_ray(camera: &Camera, r: usize) -> (f64, f64) {
    ray_at(camera, r as f64 + 0.5 - camera.incl_px)
}

/// Lines per column the camera's pitch asks for (max α / min α), or `None`
/// when some row looks straight down, straight up or backwards.
fn line_density(camera: &Camera) -> Option<f64> {
    let bottom = row_ray(camera, 0).0;
    let top = row_ray(camera, camera.height.max(1) as usize - 1).0;
    let (low, high) = (bottom.min(top), bottom.max(top));
    (low > 0.0).then(|| high / low)
}

/// The pitches, degrees, the raycaster draws for this camera's size, field
/// of view and projection-plane shift: those whose rows all look forward
/// and need at most [`MAX_LINE_DENSITY`] lines per column. About ±60° at a
/// 60° field of view and 16:9.
pub fn pitch_range(camera: &Camera) -> [f64; 2] {
    let supported = |pitch: f64| {
        let tilted = Camera {
            pitch_deg: pitch,
            ..*camera
        };
        line_density(&tilted).is_some_and(|density| density <= MAX_LINE_DENSITY)
    };
    let limit = |sign: f64| {
        let (mut ok, mut bad) = (0.0, 90.0);
        for _ in 0..40 {
            let mid = (ok + bad) / 2.0;
            if supported(sign * mid) {
                ok = mid;
            } else {
                bad = mid;
            }
        }
        sign * ok
    };
    [limit(-1.0), limit(1.0)]
}

impl Screen {
    /// The rows and lines of `camera`; refuses a pitch outside
    /// [`pitch_range`].
    pub fn fill(&mut self, camera: &Camera) -> Result<()> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let d = camera.plane_distance_px();
        let density = line_density(camera);
        if !camera.pitch_deg.is_finite() || !density.is_some_and(|v| v <= MAX_LINE_DENSITY) {
            let [low, high] = pitch_range(camera);
            return Err(Error::Input(format!(
                "pitch {}° is outside the raycast's range {low:.1}° to {high:.1}° \
                 for a {w}×{h} view with a {}° field of view",
                camera.pitch_deg, camera.fov_x_deg
            )));
        }
        self.width = w;
        self.height = h;
        self.pitched = camera.pitch_deg != 0.0;
        self.slope.clear();
        self.forward_per_depth.clear();
        let (mut alpha_min, mut alpha_max) = (f64::INFINITY, 0.0f64);
        for r in 0..h {
            let (alpha, beta) = row_ray(camera, r);
            self.slope.push(beta / alpha);
            self.forward_per_depth.push(alpha / d);
            alpha_min = alpha_min.min(alpha);
            alpha_max = alpha_max.max(alpha);
        }
        self.rows_needed.clear();
        self.row_map.clear();
        if !self.pitched {
            // Lines are the columns, through pixel centres.
            self.offset_step = 1.0 / d;
            self.first_offset = (0.5 - w as f64 / 2.0) / d;
            self.lines = w;
            self.rows_needed.resize(w, [0, h]);
            self.row_map.resize(h, [1.0, 0.0]);
            return Ok(());
        }
        // Lines pass through the pixel centres of the row nearest the
        // horizon line (ρ = −d·tan θ), where the far terrain and its
        // silhouettes are: there a pixel takes exactly its own ray. Rows
        // between it and the vanishing point have lines closer than a pixel;
        // the few beyond it (above the horizon looking down, below it looking
        // up) slightly farther apart than a pixel.
        let horizon_row = (camera.incl_px - d * camera.pitch_deg.to_radians().tan() - 0.5)
            .round()
            .clamp(0.0, (h - 1) as f64) as usize;
        let alpha_ref = self.forward_per_depth[horizon_row] * d;
        self.offset_step = 1.0 / alpha_ref;
        let x0 = 0.5 - w as f64 / 2.0;
        let before = (x0 * (1.0 - alpha_ref / alpha_min)).ceil().max(0.0);
        self.first_offset = (x0 - before) / alpha_ref;
        for r in 0..h {
            // Pixel p sits at x = p + ½ − w/2, on the line whose offset is x/α(r).
            let alpha = self.forward_per_depth[r] * d;
            let scale = 1.0 / (alpha * self.offset_step);
            let shift = ((0.5 - w as f64 / 2.0) / alpha - self.first_offset) / self.offset_step;
            self.row_map.push([scale, shift]);
        }
        self.lines = (0..h).map(|r| self.line_at(r, w - 1)).max().unwrap_or(0) + 1;
        if self.lines > i32::MAX as usize
            || super::frame::tiled_len(self.lines, h) > u32::MAX as usize
        {
            return Err(Error::Input(format!(
                "a {w}×{h} view pitched {}° needs {} lines, more than the raycast indexes",
                camera.pitch_deg, self.lines
            )));
        }
        // The lines a row needs widen towards the vanishing point and nest:
        // walk the rows from the narrowest; a line first met on row r is
        // needed from r to the widest end (the running hull keeps this true
        // should rounding ever break the nesting by a line).
        let looking_down = camera.pitch_deg < 0.0;
        self.rows_needed.resize(self.lines, [0, 0]);
        let (mut lo, mut hi) = (usize::MAX, 0usize); // lines met so far, [lo, hi)
        for i in 0..h {
            let r = if looking_down { h - 1 - i } else { i };
            let (first, last) = (self.line_at(r, 0), self.line_at(r, w - 1));
            let rows = if looking_down { [0, r + 1] } else { [r, h] };
            for j in (first..=last).filter(|&j| j < lo || j >= hi) {
                self.rows_needed[j] = rows;
            }
            lo = lo.min(first);
            hi = hi.max(last + 1);
        }
        Ok(())
    }

    /// The line nearest the centre of pixel column `px` on row `r` (from the
    /// bottom): the one rule the painter's row ranges and the gather share.
    #[inline]
    pub fn line_at(&self, r: usize, px: usize) -> usize {
        let [scale, shift] = self.row_map[r];
        nearest_line(px, scale, shift)
    }

    /// [`Screen::line_at`] of the pixels `first..first + out.len()` of row
    /// `r`.
    #[inline(always)]
    pub fn lines_on_row(&self, r: usize, first: usize, out: &mut [u32]) {
        let [scale, shift] = self.row_map[r];
        let last = self.lines.saturating_sub(1) as f64;
        for (i, line) in out.iter_mut().enumerate() {
            // Every pixel's line is one of the screen's (`lines` is the
            // largest + 1), so the clamp changes nothing but lets the
            // conversion skip saturation (and go through i32, which SIMD
            // converts in one instruction).
            let v = line_position((first + i) as f64, scale, shift)
                .max(0.0)
                .min(last);
            // SAFETY: finite (`max` takes 0 over NaN) and in
            // [0, lines − 1], which fits an i32 (`fill` refuses more lines).
            *line = unsafe { v.to_int_unchecked::<i32>() } as u32;
        }
    }
}

/// The line nearest pixel column `px` on a row mapped by `scale` and
/// `shift` (see [`Screen::row_map`]).
#[inline(always)]
fn nearest_line(px: usize, scale: f64, shift: f64) -> usize {
    line_position(px as f64, scale, shift).max(0.0) as usize
}

/// Where pixel column `px` falls among the lines, plus ½: its integer
/// part is the nearest line.
#[inline(always)]
fn line_position(px: f64, scale: f64, shift: f64) -> f64 {
    px * scale + shift + 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn camera(pitch: f64) -> Camera {
        Camera {
            position: DVec3::new(0.0, 0.0, 100.0),
            heading_deg: 0.0,
            pitch_deg: pitch,
            incl_px: 540.0,
            fov_x_deg: 60.0,
            width: 1920,
            height: 1080,
            near_m: 1.0,
            far_m: 1000.0,
        }
    }

    #[test]
    fn level_lines_are_the_columns() {
        let mut screen = Screen::default();
        screen.fill(&camera(0.0)).unwrap();
        assert_eq!(screen.lines, 1920);
        for r in [0, 539, 1079] {
            for p in [0usize, 1, 960, 1919] {
                assert_eq!(screen.line_at(r, p), p);
            }
        }
    }

    /// Every pixel's line paints the pixel's row, lines never step back
    /// along a row, and the gather's lines, a row piece at a time, are the
    /// same rule's.
    #[test]
    fn every_pixel_of_a_pitched_screen_takes_a_line_that_paints_its_row() {
        for pitch in [-45.0, -20.0, 15.0, 40.0] {
            let cam = camera(pitch);
            let mut screen = Screen::default();
            screen.fill(&cam).unwrap();
            assert!(screen.lines > 1920 && (screen.lines as f64) < 1920.0 * MAX_LINE_DENSITY);
            let mut on_row = [0u32; 1920];
            for r in 0..1080 {
                // In pieces of a tile's width, from uneven starts too.
                for (first, piece) in [(0, 64), (64, 1856), (1900, 20)] {
                    screen.lines_on_row(r, first, &mut on_row[first..first + piece]);
                }
                let mut previous = None;
                for (p, &gathered) in on_row.iter().enumerate() {
                    let j = screen.line_at(r, p);
                    assert_eq!(gathered as usize, j, "pitch {pitch}: row {r} pixel {p}");
                    let [lo, hi] = screen.rows_needed[j];
                    assert!(
                        lo <= r && r < hi,
                        "pitch {pitch}: row {r} pixel {p} line {j}"
                    );
                    // Lines are at most a pixel apart: the next pixel's line
                    // is never before this one's.
                    if let Some(q) = previous {
                        assert!(j >= q);
                    }
                    previous = Some(j);
                }
            }
        }
    }

    /// The painters take a lane's covered rows as one run from its next
    /// row up, which holds while the rows' slopes rise strictly: at every
    /// pitch of the range, the ends included, and every size.
    #[test]
    fn slopes_rise_with_the_row_at_every_pitch() {
        for (width, height) in [(1920, 1080), (150, 97), (1000, 1000)] {
            let sized = Camera {
                width,
                height,
                incl_px: height as f64 / 2.0,
                ..camera(0.0)
            };
            let [low, high] = pitch_range(&sized);
            for pitch in [low, -30.0, -1e-9, 0.0, 1e-9, 12.5, high] {
                let mut screen = Screen::default();
                screen
                    .fill(&Camera {
                        pitch_deg: pitch,
                        ..sized
                    })
                    .unwrap();
                assert!(
                    screen.slope.windows(2).all(|pair| pair[0] < pair[1]),
                    "{width}×{height} pitch {pitch}"
                );
            }
        }
    }

    /// A pitched screen whose lines' buffers would outgrow 32-bit indices
    /// is refused with its size, before any buffer is sized.
    #[test]
    fn screens_beyond_32_bit_line_buffers_are_refused() {
        let huge = Camera {
            width: 40_000,
            height: 40_000,
            incl_px: 20_000.0,
            ..camera(0.0)
        };
        let [low, _] = pitch_range(&huge);
        let mut screen = Screen::default();
        let err = screen
            .fill(&Camera {
                pitch_deg: low + 0.5,
                ..huge
            })
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("40000×40000") && err.contains("lines"),
            "{err}"
        );
        assert!(screen.rows_needed.is_empty());
    }

    #[test]
    fn the_pitch_range_is_where_lines_stay_bounded() {
        let [low, high] = pitch_range(&camera(0.0));
        assert!(
            (-65.0..-55.0).contains(&low) && (55.0..65.0).contains(&high),
            "{low} {high}"
        );
        let mut screen = Screen::default();
        assert!(screen.fill(&camera(low + 0.5)).is_ok());
        let err = screen.fill(&camera(low - 0.5)).unwrap_err().to_string();
        assert!(err.contains("outside the raycast's range"), "{err}");
        assert!(screen.fill(&camera(f64::NAN)).is_err());
    }
}
