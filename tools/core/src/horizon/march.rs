//! The floating-horizon loop: lines marched in packets, slice by slice, each
//! painting its rows bottom-up (seed 000, Algorithm 1 with depth, line 11A).
//!
//! A packet is [`PACKET`] neighbouring lines marched in lockstep: at each
//! slice all their ground positions and vertex indices are computed side by
//! side (SIMD lanes) and their heights loaded before any is compared, so the
//! loads — neighbours on the ground, often in one cache line — are in
//! flight together instead of one after another. Slices are taken
//! [`CHUNK`] at a time, and a chunk where no terrain under the packet can
//! rise above any line's horizon is skipped unsampled (empty-space
//! skipping, from each tile's highest height). The packet paints into a
//! small image of its own, [`PACKET`] pixels a row (it stays in cache), and
//! copies each row to the frame whole, so the frame is written once, in
//! runs of 128 bytes. The packet ends when every line has painted the top
//! row it is needed on (the horizon reached the top of the screen) or the
//! slices run out.

use super::sample::Terrain;
use super::screen::Screen;
use super::Slice;
use std::cell::RefCell;

/// Lines marched together.
pub(super) const PACKET: usize = 32;

/// Slices tested together against the coarse heights before any is sampled.
const CHUNK: usize = 8;

/// A row-major colour and depth image, top row first, that tasks marching
/// disjoint sets of lines write into at once: column j belongs to line j.
pub(super) struct Target {
    colour: *mut u32,
    depth: *mut f32,
    stride: usize,
    rows: usize,
}

// SAFETY: tasks write only the columns of their own lines (see `set_run`),
// so no element is ever written by two threads, and nothing reads while
// they run.
unsafe impl Send for Target {}
// SAFETY: as for `Send`.
unsafe impl Sync for Target {}

impl Target {
    /// `colour` and `depth` hold `rows` rows of `stride` elements.
    pub fn new(colour: &mut [u32], depth: &mut [f32], stride: usize, rows: usize) -> Self {
        assert!(colour.len() >= stride * rows && depth.len() >= stride * rows);
        Target {
            colour: colour.as_mut_ptr(),
            depth: depth.as_mut_ptr(),
            stride,
            rows,
        }
    }

    /// Write `colour` and `depth` into row `r` (from the bottom), from
    /// column `first` on.
    ///
    /// # Safety
    /// No other thread may be writing those columns.
    #[inline]
    unsafe fn set_run(&self, r: usize, first: usize, colour: &[u32], depth: &[f32]) {
        let n = colour.len();
        assert!(r < self.rows && first + n <= self.stride && depth.len() == n);
        let i = (self.rows - 1 - r) * self.stride + first;
        // SAFETY: `i..i + n` is in bounds (checked above) and, by the
        // caller's promise, no other thread writes these columns; the
        // sources are the caller's own buffers, so nothing overlaps.
        unsafe {
            let (c, d) = (self.colour.add(i), self.depth.add(i));
            match (
                <&[u32; PACKET]>::try_from(colour),
                <&[f32; PACKET]>::try_from(depth),
            ) {
                // A whole packet's row: one fixed-size copy each.
                (Ok(colour), Ok(depth)) => {
                    c.cast::<[u32; PACKET]>().write_unaligned(*colour);
                    d.cast::<[f32; PACKET]>().write_unaligned(*depth);
                }
                _ => {
                    std::ptr::copy_nonoverlapping(colour.as_ptr(), c, n);
                    std::ptr::copy_nonoverlapping(depth.as_ptr(), d, n);
                }
            }
        }
    }
}

/// How positions and heights are computed (seed 000, chapter 7).
pub(super) trait Sampling: Sync {
    type Position: Copy + Default;
    /// The ground position `distance_m` along ground direction `dir`.
    fn position(&self, dir: [f64; 2], distance_m: f64) -> Self::Position;
    /// Height at `p`, metres; NaN off the grid or where the mask is 0.
    fn height(&self, p: Self::Position, subvoxel: bool) -> f64;
    /// Colour at `p` from colour level `level`.
    fn colour(&self, p: Self::Position, subvoxel: bool, level: usize) -> u32;
    /// Nearest-vertex heights `s` metres along each lane's direction
    /// (`dirs`: x components, then y), all lanes at once where the sampling
    /// can.
    #[inline(always)]
    fn nearest_heights(&self, dirs: &[[f64; PACKET]; 2], s: f64, out: &mut [f64; PACKET]) {
        heights_one_by_one(self, dirs, s, false, out);
    }
}

/// [`Sampling::height`] `s` metres along each lane's direction, lane by lane.
#[inline(always)]
fn heights_one_by_one<S: Sampling + ?Sized>(
    sampling: &S,
    dirs: &[[f64; PACKET]; 2],
    s: f64,
    subvoxel: bool,
    out: &mut [f64; PACKET],
) {
    for k in 0..PACKET {
        out[k] = sampling.height(sampling.position([dirs[0][k], dirs[1][k]], s), subvoxel);
    }
}

/// Floating point throughout.
pub(super) struct FloatSampling<'a> {
    pub terrain: &'a Terrain<'a>,
    pub eye: [f64; 2],
}

impl Sampling for FloatSampling<'_> {
    type Position = [f64; 2];

    #[inline]
    fn position(&self, dir: [f64; 2], distance_m: f64) -> [f64; 2] {
        [
            self.eye[0] + dir[0] * distance_m,
            self.eye[1] + dir[1] * distance_m,
        ]
    }

    #[inline]
    fn height(&self, [x, y]: [f64; 2], subvoxel: bool) -> f64 {
        if subvoxel {
            self.terrain.height(x, y, true).unwrap_or(f64::NAN)
        } else {
            self.terrain.nearest_height(x, y) as f64
        }
    }

    #[inline]
    fn colour(&self, [x, y]: [f64; 2], subvoxel: bool, level: usize) -> u32 {
        self.terrain.color(x, y, subvoxel, level)
    }

    #[inline(always)]
    fn nearest_heights(&self, dirs: &[[f64; PACKET]; 2], s: f64, out: &mut [f64; PACKET]) {
        self.terrain.nearest_heights(self.eye, dirs, s, out);
    }
}

/// 16.16 fixed point for ground positions (in cells) and heights (in
/// metres).
pub(super) struct FixedSampling<'a> {
    pub terrain: &'a Terrain<'a>,
    /// The eye in 1/65536 cell.
    pub eye: [i64; 2],
}

/// One in 16.16 fixed point.
const ONE: f64 = 65536.0;

impl<'a> FixedSampling<'a> {
    pub fn new(terrain: &'a Terrain<'a>, eye: [f64; 2]) -> Self {
        let to_cell = ONE / terrain.cell_m;
        FixedSampling {
            terrain,
            eye: [(eye[0] * to_cell) as i64, (eye[1] * to_cell) as i64],
        }
    }
}

impl Sampling for FixedSampling<'_> {
    type Position = [i64; 2];

    #[inline]
    fn position(&self, dir: [f64; 2], distance_m: f64) -> [i64; 2] {
        let to_cell = ONE / self.terrain.cell_m;
        let (dx, dy) = ((dir[0] * to_cell) as i64, (dir[1] * to_cell) as i64);
        let dist = (distance_m * ONE) as i64;
        [
            self.eye[0] + ((dx * dist) >> 16),
            self.eye[1] + ((dy * dist) >> 16),
        ]
    }

    #[inline]
    fn height(&self, [x, y]: [i64; 2], subvoxel: bool) -> f64 {
        self.terrain
            .height_fixed(x, y, subvoxel)
            .map_or(f64::NAN, |z| z as f64 / ONE)
    }

    #[inline]
    fn colour(&self, [x, y]: [i64; 2], subvoxel: bool, level: usize) -> u32 {
        self.terrain.color_fixed(x, y, subvoxel, level)
    }
}

/// A packet's own image, [`PACKET`] pixels a row, bottom row first; one
/// per thread, kept from frame to frame.
#[derive(Default)]
struct PacketImage {
    colour: Vec<u32>,
    depth: Vec<f32>,
}

thread_local! {
    static PACKET_IMAGE: RefCell<PacketImage> = RefCell::default();
}

/// What every packet of a frame shares.
pub(super) struct Pass<'a> {
    pub terrain: &'a Terrain<'a>,
    pub slices: &'a [Slice],
    pub screen: &'a Screen,
    /// Ground direction of each line, scaled so that `dir · s` advances the
    /// slice distance s.
    pub directions: &'a [[f64; 2]],
    /// The eye, terrain-frame metres.
    pub eye: [f64; 2],
    pub eye_z: f64,
    /// Depth A − B/z of a view distance z (eq. 5.11): [A, B].
    pub depth_terms: [f64; 2],
    pub far_m: f64,
    pub sky: u32,
}

impl Pass<'_> {
    /// March lines `first..first + count` (count ≤ [`PACKET`]) into `target`.
    ///
    /// # Safety
    /// No other thread may be marching any of these lines into `target`.
    pub unsafe fn march<S: Sampling>(
        &self,
        sampling: &S,
        first: usize,
        count: usize,
        target: &Target,
    ) {
        PACKET_IMAGE.with_borrow_mut(|image| {
            #[cfg(target_arch = "x86_64")]
            let sky_from = if std::is_x86_feature_detected!("avx2") {
                // SAFETY: the machine has AVX2 (checked just above).
                unsafe { self.paint_avx2(sampling, first, count, image) }
            } else {
                self.paint(sampling, first, count, image)
            };
            #[cfg(not(target_arch = "x86_64"))]
            let sky_from = self.paint(sampling, first, count, image);
            let needed = &self.screen.rows_needed[first..first + count];
            let sky = ([self.sky; PACKET], [1.0f32; PACKET]);
            for r in 0..self.screen.height {
                let (colour, depth) = if r < sky_from {
                    let at = r * PACKET;
                    (&image.colour[at..at + count], &image.depth[at..at + count])
                } else {
                    (&sky.0[..count], &sky.1[..count])
                };
                let inside = |k: usize| (needed[k][0]..needed[k][1]).contains(&r);
                if (0..count).all(inside) {
                    // SAFETY: these lines are ours (the caller's promise).
                    unsafe { target.set_run(r, first, colour, depth) };
                } else {
                    // A pitched screen's outer lines need only some rows.
                    for k in (0..count).filter(|&k| inside(k)) {
                        // SAFETY: as above.
                        unsafe {
                            target.set_run(r, first + k, &colour[k..k + 1], &depth[k..k + 1]);
                        }
                    }
                }
            }
        });
    }

    /// [`Pass::paint`] compiled for AVX2, where the lanes' positions and
    /// indices take four at a time.
    ///
    /// # Safety
    /// The machine must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn paint_avx2<S: Sampling>(
        &self,
        sampling: &S,
        first: usize,
        count: usize,
        image: &mut PacketImage,
    ) -> usize {
        self.paint(sampling, first, count, image)
    }

    /// March lines `first..first + count` into the packet's own image.
    ///
    /// Every slice samples all [`PACKET`] lanes (nearest samples without
    /// branching; lanes past `count`, or done, sample too and cover
    /// nothing), compares each rise with the lane's horizon — the rise per
    /// metre its next unpainted row needs — and only the lanes whose sample
    /// covers a row paint.
    #[inline(always)]
    fn paint<S: Sampling>(
        &self,
        sampling: &S,
        first: usize,
        count: usize,
        image: &mut PacketImage,
    ) -> usize {
        let slope = &self.screen.slope[..];
        let forward_per_depth = &self.screen.forward_per_depth[..];
        let [depth_a, depth_b] = self.depth_terms;
        image.colour.resize(self.screen.height * PACKET, 0);
        image.depth.resize(self.screen.height * PACKET, 0.0);
        // Per lane: its ground direction, next unpainted row, the row its
        // work ends at, and the slope a sample must rise above to cover the
        // next row (∞ for a lane with nothing left to paint).
        let mut dirs = [[0.0; PACKET]; 2];
        let mut row = [0usize; PACKET];
        let mut end = [0usize; PACKET];
        let mut horizon = [f64::INFINITY; PACKET];
        for k in 0..count {
            [dirs[0][k], dirs[1][k]] = self.directions[first + k];
            end[k] = self.screen.rows_needed[first + k][1];
            if end[k] > 0 {
                horizon[k] = slope[0];
            }
        }
        let mut busy = horizon.iter().filter(|h| h.is_finite()).count();
        let (first_dir, last_dir) = (self.directions[first], self.directions[first + count - 1]);
        for chunk in self.slices.chunks(CHUNK) {
            // Empty-space skipping: the packet's samples over this chunk lie
            // between its outer lines and its nearest and farthest slices;
            // if no terrain there rises above any lane's horizon, none of
            // them paints (and the horizons stay as they are).
            let (near, far) = (chunk[0].distance_m, chunk[chunk.len() - 1].distance_m);
            let at = |dir: [f64; 2], s: f64| [self.eye[0] + dir[0] * s, self.eye[1] + dir[1] * s];
            let highest_rise = self.terrain.highest_near(&[
                at(first_dir, near),
                at(last_dir, near),
                at(first_dir, far),
                at(last_dir, far),
            ]) - self.eye_z;
            if !(0..count).any(|k| highest_rise > (near * horizon[k]).min(far * horizon[k])) {
                continue;
            }
            for slice in chunk {
                let s = slice.distance_m;
                let depth_over = depth_b / s;
                // A NaN rise (no data) covers nothing.
                let mut ground = [0.0; PACKET];
                if slice.subvoxel {
                    heights_one_by_one(sampling, &dirs, s, true, &mut ground);
                } else {
                    sampling.nearest_heights(&dirs, s, &mut ground);
                }
                let mut covering = 0u32;
                for k in 0..PACKET {
                    covering |= u32::from(ground[k] - self.eye_z > s * horizon[k]) << k;
                }
                while covering != 0 {
                    let k = covering.trailing_zeros() as usize;
                    covering &= covering - 1;
                    let position = sampling.position([dirs[0][k], dirs[1][k]], s);
                    let rise = ground[k] - self.eye_z;
                    let level = slice.level(self.terrain, self.eye_z, rise + self.eye_z);
                    let colour = sampling.colour(position, slice.subvoxel, level);
                    let (r, end) = (&mut row[k], end[k]);
                    if !self.screen.pitched {
                        // Level: one depth for the slice, and the slices end
                        // before the far plane.
                        let depth = (depth_a - depth_over) as f32;
                        while *r < end && rise > s * slope[*r] {
                            image.colour[*r * PACKET + k] = colour;
                            image.depth[*r * PACKET + k] = depth;
                            *r += 1;
                        }
                    }
                    while *r < end && rise > s * slope[*r] {
                        // Beyond the far plane for this row's rays: sky (only a
                        // pitched camera's rows differ).
                        let (c, depth) = if s > self.far_m * forward_per_depth[*r] {
                            (self.sky, 1.0)
                        } else {
                            (
                                colour,
                                (depth_a - depth_over * forward_per_depth[*r]) as f32,
                            )
                        };
                        image.colour[*r * PACKET + k] = c;
                        image.depth[*r * PACKET + k] = depth;
                        *r += 1;
                    }
                    if *r < end {
                        horizon[k] = slope[*r];
                    } else {
                        horizon[k] = f64::INFINITY;
                        busy -= 1;
                    }
                }
            }
            if busy == 0 {
                break;
            }
        }
        // Sky above each line's horizon, up to the row from which every
        // line shows sky (the copy writes those rows from constants).
        let sky_from = row[..count].iter().copied().max().unwrap_or(0);
        for k in 0..count {
            for r in row[k]..end[k].min(sky_from) {
                image.colour[r * PACKET + k] = self.sky;
                image.depth[r * PACKET + k] = 1.0;
            }
        }
        sky_from
    }
}
