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
//! skipping, from each tile's highest height). The packet paints straight
//! into the frame, whose column tiles (see [`super::frame`]) give its lines
//! one contiguous block. The packet ends when every line has painted the
//! top row it is needed on (the horizon reached the top of the screen) or
//! the slices run out; the rows left above each line's horizon take the
//! sky.

use super::frame::{tiled_index, tiled_len, TILE_COLUMNS};
use super::sample::{LaneCells, Terrain};
use super::screen::Screen;

/// One slice: horizontal forward distance and its band.
#[derive(Debug)]
pub(super) struct Slice {
    pub(super) distance_m: f64,
    pub(super) subvoxel: bool,
    /// With prefiltering: a screen pixel's ground footprint across the ray
    /// (s/d) and the factor s²/d that, divided by the eye's height above the
    /// ground, gives its footprint along the ray; metres.
    pub(super) footprint: Option<(f64, f64)>,
}

impl Slice {
    /// Colour level for a sample at height `z` seen from `eye_z`: the
    /// larger of the pixel's two ground footprints picks it.
    #[inline]
    fn level(&self, terrain: &Terrain, eye_z: f64, z: f64) -> usize {
        match self.footprint {
            None => 0,
            Some((across, along)) => terrain.color_level(across.max(along / (eye_z - z).max(1e-3))),
        }
    }
}

/// Lines marched together.
pub(super) const PACKET: usize = 64;

// A packet's lines lie in one tile, and its lanes are the bits of a u64
// (which lanes a slice's samples cover).
const _: () = assert!(TILE_COLUMNS.is_multiple_of(PACKET) && PACKET <= 64);

/// Lanes a pitched camera paints together, a row at a time (two AVX2
/// registers of colours).
const GROUP: usize = 16;

// A packet is whole groups.
const _: () = assert!(PACKET.is_multiple_of(GROUP));

/// Slices tested together against the coarse heights before any is sampled.
const CHUNK: usize = 8;

/// A colour and depth image in column tiles, one column per line, that
/// tasks marching disjoint sets of lines write into at once.
pub(super) struct Target {
    colour: *mut u32,
    depth: *mut f32,
    width: usize,
    rows: usize,
}

// SAFETY: tasks write only the columns of their own lines (see
// `Target::lanes`), so no element is ever written by two threads, and
// nothing reads while they run.
unsafe impl Send for Target {}
// SAFETY: as for `Send`.
unsafe impl Sync for Target {}

impl Target {
    /// `colour` and `depth` hold a `width` × `rows` image in column tiles.
    pub fn new(colour: &mut [u32], depth: &mut [f32], width: usize, rows: usize) -> Self {
        let len = tiled_len(width, rows);
        assert!(colour.len() >= len && depth.len() >= len);
        Target {
            colour: colour.as_mut_ptr(),
            depth: depth.as_mut_ptr(),
            width,
            rows,
        }
    }

    /// The columns of the packet of lines `first..first + count` (`first`
    /// a multiple of [`PACKET`]): [`PACKET`] columns of one tile, those
    /// past `count` the last tile's padding.
    ///
    /// # Safety
    /// No other thread may be writing those columns while the result lives.
    unsafe fn lanes(&self, first: usize, count: usize) -> Lanes {
        assert!(count <= PACKET && first + count <= self.width);
        assert!(first.is_multiple_of(PACKET));
        let at = tiled_index(first, 0, self.rows);
        // SAFETY: `at` is within the image (the column is).
        unsafe {
            Lanes {
                colour: self.colour.add(at),
                depth: self.depth.add(at),
                rows: self.rows,
                count,
            }
        }
    }
}

/// One packet's columns of a [`Target`].
struct Lanes {
    /// Top row of the packet's first column.
    colour: *mut u32,
    depth: *mut f32,
    rows: usize,
    count: usize,
}

impl Lanes {
    /// Paint row `r` (from the bottom) of lane `k`.
    #[inline(always)]
    fn set(&mut self, r: usize, k: usize, colour: u32, depth: f32) {
        assert!(r < self.rows && k < self.count);
        let i = (self.rows - 1 - r) * TILE_COLUMNS + k;
        // SAFETY: in bounds (checked above; the column and its rows lie in
        // the target's tile), and the columns are this packet's alone
        // (`Target::lanes`' promise).
        unsafe {
            self.colour.add(i).write(colour);
            self.depth.add(i).write(depth);
        }
    }

    /// Paint lane `k` from row `from` (from the bottom) up while `covers`
    /// holds for the row's slope, at most up to the last of `slopes`;
    /// returns the first row left unpainted.
    #[inline(always)]
    fn paint_run(
        &mut self,
        k: usize,
        from: usize,
        slopes: &[f64],
        colour: u32,
        depth: f32,
        covers: impl Fn(f64) -> bool,
    ) -> usize {
        assert!(slopes.len() <= self.rows && k < self.count);
        let mut r = from;
        // Element of row r; wraps below zero only once r passes the top row,
        // where the loop ends before writing.
        let mut i = (self.rows.wrapping_sub(1 + from))
            .wrapping_mul(TILE_COLUMNS)
            .wrapping_add(k);
        while let Some(&slope) = slopes.get(r) {
            if !covers(slope) {
                break;
            }
            // SAFETY: r < rows (slopes.len() ≤ rows), so i is row r's element
            // of column k, in the packet's tile (as for `set`).
            unsafe {
                self.colour.add(i).write(colour);
                self.depth.add(i).write(depth);
            }
            i = i.wrapping_sub(TILE_COLUMNS);
            r += 1;
        }
        r
    }

    /// Row `r` (from the bottom) of lanes `first..first + GROUP`: their
    /// colours and depths.
    #[inline(always)]
    fn group_row(&mut self, r: usize, first: usize) -> (&mut [u32; GROUP], &mut [f32; GROUP]) {
        assert!(r < self.rows && first + GROUP <= PACKET);
        let i = (self.rows - 1 - r) * TILE_COLUMNS + first;
        // SAFETY: in bounds (checked above; a packet's PACKET columns lie in
        // the target's tile, padding columns past `count` included), the
        // columns are this packet's alone (`Target::lanes`' promise), and
        // the two arrays are distinct buffers.
        unsafe {
            (
                &mut *self.colour.add(i).cast::<[u32; GROUP]>(),
                &mut *self.depth.add(i).cast::<[f32; GROUP]>(),
            )
        }
    }

    /// Paint row `r` (from the bottom) of every lane.
    #[inline(always)]
    fn set_row(&mut self, r: usize, colour: u32, depth: f32) {
        assert!(r < self.rows);
        let i = (self.rows - 1 - r) * TILE_COLUMNS;
        // SAFETY: as for `set`, for the `count` lanes.
        unsafe {
            std::slice::from_raw_parts_mut(self.colour.add(i), self.count).fill(colour);
            std::slice::from_raw_parts_mut(self.depth.add(i), self.count).fill(depth);
        }
    }
}

/// One slice's samples in a group of [`GROUP`] lanes of a packet.
struct GroupSamples<'a> {
    /// The group's first lane.
    first: usize,
    /// Bit j: lane j's sample covers at least its next unpainted row.
    covering: u64,
    /// Per lane: its next unpainted row and the row its work ends at.
    row: [u32; GROUP],
    end: [u32; GROUP],
    /// Per lane: the sample's height above the eye, metres (−∞ for a lane
    /// whose sample covers nothing), and its colour.
    rise: &'a [f64; GROUP],
    colour: &'a [u32; GROUP],
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
    /// What a packet's lanes keep for [`Sampling::nearest_heights`],
    /// prepared once a packet.
    type Lanes;
    /// The lanes of ground directions `dirs` (x components, then y).
    fn lanes(&self, dirs: &[[f64; PACKET]; 2]) -> Self::Lanes;
    /// Nearest-vertex heights `s` metres along each lane's direction, all
    /// lanes at once where the sampling can; where it colours by vertex,
    /// also each lane's vertex for [`Sampling::vertex_colour`] (`vertices`
    /// untouched otherwise).
    fn nearest_heights(
        &self,
        lanes: &Self::Lanes,
        s: f64,
        out: &mut [f64; PACKET],
        vertices: &mut [u32; PACKET],
    );
    /// The colour of a vertex [`Sampling::nearest_heights`] gave, where
    /// the sampling colours by vertex (the same as [`Sampling::colour`] at
    /// that sample's position without sub-voxels); `None` otherwise.
    #[inline(always)]
    fn vertex_colour(&self, _vertex: u32) -> Option<u32> {
        None
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

    /// In grid units and f32, eight lanes to an AVX2 register.
    type Lanes = LaneCells<PACKET>;

    fn lanes(&self, dirs: &[[f64; PACKET]; 2]) -> LaneCells<PACKET> {
        self.terrain.lane_cells(self.eye, dirs)
    }

    #[inline(always)]
    fn nearest_heights(
        &self,
        lanes: &LaneCells<PACKET>,
        s: f64,
        out: &mut [f64; PACKET],
        vertices: &mut [u32; PACKET],
    ) {
        self.terrain.nearest_heights(lanes, s, out, vertices);
    }

    #[inline(always)]
    fn vertex_colour(&self, vertex: u32) -> Option<u32> {
        self.terrain.vertex_colour(vertex)
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
    /// The directions themselves: heights are taken one by one.
    type Lanes = [[f64; PACKET]; 2];

    fn lanes(&self, dirs: &[[f64; PACKET]; 2]) -> [[f64; PACKET]; 2] {
        *dirs
    }

    #[inline(always)]
    fn nearest_heights(
        &self,
        dirs: &[[f64; PACKET]; 2],
        s: f64,
        out: &mut [f64; PACKET],
        _vertices: &mut [u32; PACKET],
    ) {
        heights_one_by_one(self, dirs, s, false, out);
    }

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

/// The set bits of `mask`, lowest first.
#[inline(always)]
fn set_bits(mut mask: u64) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let k = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            k
        })
    })
}

/// A lane's horizon once its next unpainted row is `row`: the slope that
/// row needs among the lane's `slopes` (those of the rows below its end), or
/// ∞ when its work is done (past them; returns false).
#[inline(always)]
fn next_horizon(row: usize, slopes: &[f64], horizon: &mut f64) -> bool {
    let next = slopes.get(row);
    *horizon = next.copied().unwrap_or(f64::INFINITY);
    next.is_some()
}

/// The slices one terrain serves, and how it is sampled: the whole frame's
/// for a single grid; a band's for a pyramid, whose bands read coarser
/// levels farther away (seed 000 §6.3's bands, the pyramid's levels).
pub(super) struct Segment<'a, S> {
    pub sampling: S,
    pub terrain: &'a Terrain<'a>,
    /// The eye in this terrain's frame, metres.
    pub eye: [f64; 2],
    /// Indices of the frame's slices this terrain serves.
    pub slices: std::ops::Range<usize>,
}

/// What every packet of a frame shares.
pub(super) struct Pass<'a> {
    pub slices: &'a [Slice],
    pub screen: &'a Screen,
    /// Ground direction of each line, scaled so that `dir · s` advances the
    /// slice distance s.
    pub directions: &'a [[f64; 2]],
    pub eye_z: f64,
    /// Depth A − B/z of a view distance z (eq. 5.11): [A, B].
    pub depth_terms: [f64; 2],
    pub far_m: f64,
    pub sky: u32,
}

impl Pass<'_> {
    /// March lines `first..first + count` (count ≤ [`PACKET`], in one
    /// tile) into `target`.
    ///
    /// # Safety
    /// No other thread may be marching any of these lines into `target`.
    pub unsafe fn march<S: Sampling>(
        &self,
        segments: &[Segment<S>],
        first: usize,
        count: usize,
        target: &Target,
    ) {
        // SAFETY: these lines are ours (the caller's promise).
        let mut lanes = unsafe { target.lanes(first, count) };
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the machine has AVX2 (checked just above).
            unsafe { self.paint_avx2(segments, first, &mut lanes) };
            return;
        }
        self.paint(segments, first, &mut lanes);
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
        segments: &[Segment<S>],
        first: usize,
        lanes: &mut Lanes,
    ) {
        self.paint(segments, first, lanes);
    }

    /// March the lines of `lanes`, from line `first` on, into them, each
    /// segment's slices through its terrain.
    ///
    /// Every slice samples all [`PACKET`] lanes (nearest samples without
    /// branching; lanes past `count`, or done, sample too and cover
    /// nothing), compares each rise with the lane's horizon — the rise per
    /// metre its next unpainted row needs — and only the lanes whose sample
    /// covers a row paint.
    #[inline(always)]
    fn paint<S: Sampling>(&self, segments: &[Segment<S>], first: usize, lanes: &mut Lanes) {
        let count = lanes.count;
        let slope = &self.screen.slope[..];
        let [depth_a, depth_b] = self.depth_terms;
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
        // Each slice's heights, and the vertices they came from: every
        // lane of `ground` is written for each slice (and `vertices` where
        // the sampling colours by vertex), so they are set up once.
        let mut ground = [0.0; PACKET];
        let mut vertices = [0u32; PACKET];
        let (first_dir, last_dir) = (self.directions[first], self.directions[first + count - 1]);
        'segments: for segment in segments {
            let (sampling, terrain, eye) = (&segment.sampling, segment.terrain, segment.eye);
            let lane_sampling = sampling.lanes(&dirs);
            for chunk in self.slices[segment.slices.clone()].chunks(CHUNK) {
                // Empty-space skipping: the packet's samples over this chunk lie
                // between its outer lines and its nearest and farthest slices;
                // if no terrain there rises above any lane's horizon, none of
                // them paints (and the horizons stay as they are).
                let (near, far) = (chunk[0].distance_m, chunk[chunk.len() - 1].distance_m);
                let at = |dir: [f64; 2], s: f64| [eye[0] + dir[0] * s, eye[1] + dir[1] * s];
                let highest_rise = terrain.highest_near(&[
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
                    if slice.subvoxel {
                        heights_one_by_one(sampling, &dirs, s, true, &mut ground);
                    } else {
                        sampling.nearest_heights(&lane_sampling, s, &mut ground, &mut vertices);
                    }
                    let mut covering = 0u64;
                    for k in 0..PACKET {
                        covering |= u64::from(ground[k] - self.eye_z > s * horizon[k]) << k;
                    }
                    if covering == 0 {
                        continue;
                    }
                    // The covering lanes' colours, all looked up before any
                    // paints so that their loads are in flight together; by the
                    // vertex the height came from where that gives the colour.
                    let mut colour = [0u32; PACKET];
                    for k in set_bits(covering) {
                        let by_vertex = (!slice.subvoxel)
                            .then(|| sampling.vertex_colour(vertices[k]))
                            .flatten();
                        colour[k] = by_vertex.unwrap_or_else(|| {
                            let position = sampling.position([dirs[0][k], dirs[1][k]], s);
                            let level = slice.level(terrain, self.eye_z, ground[k]);
                            sampling.colour(position, slice.subvoxel, level)
                        });
                    }
                    // Rows each lane paints: from its next unpainted row up
                    // while its rise clears the row's slope, below its end (seed
                    // 000, Algorithm 1, line 11A).
                    if self.screen.pitched {
                        // Each row has its own depth and far-plane test: a
                        // group of lanes goes together, a row at a time.
                        let mut rise = [f64::NEG_INFINITY; PACKET];
                        for k in set_bits(covering) {
                            rise[k] = ground[k] - self.eye_z;
                        }
                        let groups = rise.as_chunks::<GROUP>().0.iter();
                        let groups = groups.zip(colour.as_chunks::<GROUP>().0);
                        for ((rise, colour), g) in groups.zip((0..PACKET).step_by(GROUP)) {
                            let group_covering = (covering >> g) & ((1 << GROUP) - 1);
                            if group_covering == 0 {
                                continue;
                            }
                            let samples = GroupSamples {
                                first: g,
                                covering: group_covering,
                                row: std::array::from_fn(|j| row[g + j] as u32),
                                end: std::array::from_fn(|j| end[g + j] as u32),
                                rise,
                                colour,
                            };
                            let painted = self.paint_pitched_rows(lanes, s, depth_over, &samples);
                            for j in set_bits(group_covering) {
                                let k = g + j;
                                row[k] += painted[j] as usize;
                                if !next_horizon(row[k], &slope[..end[k]], &mut horizon[k]) {
                                    busy -= 1;
                                }
                            }
                        }
                    } else {
                        // Level: one depth for the slice, and the slices end
                        // before the far plane; lane by lane.
                        let depth = (depth_a - depth_over) as f32;
                        for k in set_bits(covering) {
                            let rise = ground[k] - self.eye_z;
                            let slopes = &slope[..end[k]];
                            row[k] =
                                lanes.paint_run(k, row[k], slopes, colour[k], depth, |slope| {
                                    rise > s * slope
                                });
                            if !next_horizon(row[k], slopes, &mut horizon[k]) {
                                busy -= 1;
                            }
                        }
                    }
                }
                if busy == 0 {
                    break 'segments;
                }
            }
        }
        // Sky above each line's horizon: rows where every lane shows it
        // whole, the rest lane by lane.
        // (Each lane's sky runs from its next unpainted row to its end.)
        let (sky_from, sky_until) = (&row[..count], &end[..count]);
        let all_sky_from = sky_from.iter().copied().max().unwrap_or(0);
        let all_sky_until = sky_until.iter().copied().min().unwrap_or(0);
        let some_sky_from = sky_from.iter().copied().min().unwrap_or(0);
        let some_sky_until = sky_until.iter().copied().max().unwrap_or(0);
        for r in some_sky_from..some_sky_until {
            if (all_sky_from..all_sky_until).contains(&r) {
                lanes.set_row(r, self.sky, 1.0);
                continue;
            }
            for k in 0..count {
                if (row[k]..end[k]).contains(&r) {
                    lanes.set(r, k, self.sky, 1.0);
                }
            }
        }
    }

    /// Paint the rows one slice's samples cover in a group of a pitched
    /// camera's lanes, a row at a time for all of them: each row's depth
    /// and far-plane test (which a pitched camera's rows do not share)
    /// come once for the group instead of once a lane. A lane paints from
    /// its next unpainted row up while its rise clears the row's slope,
    /// below the row its work ends at; as the slopes increase with the
    /// row, its rows form one run. `depth_over` is the slice's B/s (eq.
    /// 5.11). Returns the rows each lane painted.
    #[inline(always)]
    fn paint_pitched_rows(
        &self,
        lanes: &mut Lanes,
        s: f64,
        depth_over: f64,
        samples: &GroupSamples,
    ) -> [u32; GROUP] {
        let GroupSamples {
            first,
            covering,
            row,
            end,
            rise,
            colour,
        } = samples;
        // The covering lanes' rows start between `lowest` and `last_start`
        // and end by `last_end`.
        let lowest = set_bits(*covering).map(|j| row[j]).min().unwrap_or(0);
        let last_start = set_bits(*covering).map(|j| row[j]).max().unwrap_or(0);
        let last_end = set_bits(*covering).map(|j| end[j]).max().unwrap_or(0);
        // Row r of lane j is open while row[j] ≤ r < end[j]. Every open row
        // is painted later (by a farther sample or the sky), so it may take
        // anything now: a row open in every lane is written whole, others
        // are blended. Masks are all ones or all zeros, so that the lanes
        // go side by side in registers.
        let rows_left: [u32; GROUP] = std::array::from_fn(|j| end[j] - row[j]);
        let all_open =
            row.iter().max().copied().unwrap_or(0)..end.iter().min().copied().unwrap_or(0);
        let depth_a = self.depth_terms[0];
        let mut painted = [0u32; GROUP];
        for r in lowest..last_end {
            let threshold = s * self.screen.slope[r as usize];
            let open: [u32; GROUP] = std::array::from_fn(|j| {
                u32::from(r.wrapping_sub(row[j]) < rows_left[j]).wrapping_neg()
            });
            let paints: [u32; GROUP] =
                std::array::from_fn(|j| open[j] & u32::from(rise[j] > threshold).wrapping_neg());
            if paints.iter().fold(0, |any, &p| any | p) == 0 {
                if r >= last_start {
                    break;
                }
                continue;
            }
            let forward_per_depth = self.screen.forward_per_depth[r as usize];
            let (row_colours, depth) = if s > self.far_m * forward_per_depth {
                // Beyond the far plane for this row's rays: sky.
                ([self.sky; GROUP], 1.0)
            } else {
                (**colour, (depth_a - depth_over * forward_per_depth) as f32)
            };
            let (colours, depths) = lanes.group_row(r as usize, *first);
            if all_open.contains(&r) {
                *colours = row_colours;
                *depths = [depth; GROUP];
            } else {
                // Blended through copies: the compiler keeps them in
                // registers (selecting in place, it stored lane by lane).
                let (old_colours, old_depths) = (*colours, *depths);
                let depth = depth.to_bits();
                *colours = std::array::from_fn(|j| {
                    (row_colours[j] & open[j]) | (old_colours[j] & !open[j])
                });
                *depths = std::array::from_fn(|j| {
                    f32::from_bits((depth & open[j]) | (old_depths[j].to_bits() & !open[j]))
                });
            }
            painted = std::array::from_fn(|j| painted[j].wrapping_sub(paints[j]));
        }
        painted
    }
}
