//! What to draw from a camera: a cut through the quadtree, or one of the
//! baselines — the plain list and the seed's blobs — behind the same
//! [`Selection`] interface (vegetation thesis, §4.2.4: blobs, quadtree with
//! clusters, the distance bands of fig. 4.13 and 4.15, the view switch of
//! §4.1.3 and fig. 4.4).
//!
//! Distance bands generalise the seed's three regions to n: band i reaches
//! `until_m` and draws clusters of at most `max_cluster` objects; nothing
//! beyond the last band is drawn. A cluster is further refused where the
//! screen would magnify its texture by more than `magnification` (texels
//! per metre against pixels per metre at its nearest point); the cut then
//! descends to its children.

use super::quadtree::{Node, NONE};
use super::views::ImpostorView;
use super::Clusters;
use crate::camera::Camera;
use glam::DVec3;
use rayon::prelude::*;

/// One distance band.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CutBand {
    /// Outer edge of the band, metres from the eye.
    pub until_m: f64,
    /// Most objects one drawn cluster may stand for inside this band.
    pub max_cluster: u32,
}

/// The parameters of a cut (fields left out take their defaults).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CutOptions {
    /// Bands by increasing distance.
    pub bands: Vec<CutBand>,
    /// Elevation of the line of sight above which an impostor shows its top
    /// view, degrees (the seed's θ, 45° after its 0–90° sweep).
    pub view_angle_deg: f64,
    /// Width of the cross-fade around the view-angle threshold and around
    /// each 45° boundary between side views, degrees (0: the view flips).
    pub crossfade_deg: f64,
    /// Choose the threshold per impostor instead: the elevation from which
    /// its top view shows more than its side view — a box of height h and
    /// width w seen from elevation e shows w² sin e from above and w h cos e
    /// from the side, equal at tan e = h / w. Flat clusters switch early,
    /// tall conifers late (the automatic choice the seed proposes, §4.1.3).
    pub automatic_view_angle: bool,
    /// Largest ratio of screen pixels to texture texels a cluster may be
    /// drawn at.
    pub magnification: f64,
    /// Width of the cross-fade between a cluster and its children, as a
    /// fraction of the margin left before the cluster is refused (by its
    /// band or its magnification): a cluster within that margin of being
    /// refused shares the pixels with its children by ordered dither, so
    /// the cut changes level without popping (0: it switches).
    pub level_fade: f64,
    /// Leave out what lies wholly outside the view frustum (the seed's
    /// object culling, §4.2.2); off, every object within the last band is
    /// drawn, as the seed's table 4.2 measured without it.
    pub cull: bool,
}

impl Default for CutOptions {
    /// Five bands from 300 m to 20 km, clusters of 1, 4, 16, 64 and 256.
    fn default() -> Self {
        CutOptions {
            bands: [
                (300.0, 1),
                (1_000.0, 4),
                (3_000.0, 16),
                (8_000.0, 64),
                (20_000.0, 256),
            ]
            .map(|(until_m, max_cluster)| CutBand {
                until_m,
                max_cluster,
            })
            .to_vec(),
            view_angle_deg: 45.0,
            crossfade_deg: 10.0,
            automatic_view_angle: false,
            magnification: 1.5,
            level_fade: 0.1,
            cull: true,
        }
    }
}

impl CutOptions {
    /// The seed's configurations 1–3 (fig. 4.15) for a terrain whose
    /// diagonal is `diagonal_m`: three bands, d₁ = diagonal/8, d₂ =
    /// diagonal/4 and d₃ = 2 × diagonal (beyond the terrain, as in the
    /// seed's test, so that nothing is culled by distance). The figure is not
    /// in the text; its prose fixes the middle band (at most 2 objects per
    /// cluster in configuration 1, 6 in configuration 3) and table 4.4 shows
    /// configuration 1 drawing the fewest billboards, so configuration 1
    /// groups the most in the far band. Maximum cluster sizes per band:
    /// 1: (1, 2, 64); 2: (1, 4, 16); 3: (1, 6, 8). Texture magnification is
    /// not limited, as the seed did not limit it.
    pub fn seed_configuration(number: u8, diagonal_m: f64) -> Option<CutOptions> {
        let sizes = match number {
            1 => [1, 2, 64],
            2 => [1, 4, 16],
            3 => [1, 6, 8],
            _ => return None,
        };
        let until = [diagonal_m / 8.0, diagonal_m / 4.0, 2.0 * diagonal_m];
        Some(CutOptions {
            bands: (0..3)
                .map(|i| CutBand {
                    until_m: until[i],
                    max_cluster: sizes[i],
                })
                .collect(),
            // The largest finite number: unlimited, and still a JSON number.
            magnification: f64::MAX,
            ..CutOptions::default()
        })
    }

    /// Bands from text `UNTIL_M:MAX_CLUSTER,…`, e.g. `300:1,1000:4,3000:16`
    /// (checked).
    pub fn parse_bands(text: &str) -> Result<Vec<CutBand>, String> {
        let bands = text
            .split(',')
            .map(|band| {
                let (until, size) = band
                    .split_once(':')
                    .ok_or_else(|| format!("{band:?}: expected UNTIL_M:MAX_CLUSTER"))?;
                Ok(CutBand {
                    until_m: until
                        .trim()
                        .parse()
                        .map_err(|_| format!("{until:?} is not a distance in metres"))?,
                    max_cluster: size
                        .trim()
                        .parse()
                        .map_err(|_| format!("{size:?} is not a cluster size"))?,
                })
            })
            .collect::<Result<Vec<CutBand>, String>>()?;
        CutOptions {
            bands: bands.clone(),
            ..CutOptions::default()
        }
        .check()?;
        Ok(bands)
    }

    /// Check the bands: increasing distances, sizes at least 1.
    pub fn check(&self) -> Result<(), String> {
        if self.bands.is_empty() {
            return Err("no distance bands".into());
        }
        for (i, b) in self.bands.iter().enumerate() {
            if !b.until_m.is_finite() || b.until_m <= 0.0 || b.max_cluster == 0 {
                return Err(format!(
                    "band {}: needs a positive distance and a cluster size of at least 1",
                    i + 1
                ));
            }
            if i > 0 && b.until_m <= self.bands[i - 1].until_m {
                return Err(format!("band {}: distances must increase", i + 1));
            }
        }
        if !(0.0..=90.0).contains(&self.view_angle_deg)
            || self.crossfade_deg.is_nan()
            || self.crossfade_deg < 0.0
        {
            return Err("the view angle must lie in 0–90° and the cross-fade be ≥ 0".into());
        }
        if !(self.magnification.is_finite() && self.magnification > 0.0) {
            return Err("the magnification must be a positive number".into());
        }
        if !(0.0..=1.0).contains(&self.level_fade) {
            return Err("the level fade must lie in 0–1".into());
        }
        Ok(())
    }

    /// Distance beyond which nothing is drawn, metres.
    pub fn last_distance(&self) -> f64 {
        self.bands.last().map_or(0.0, |b| b.until_m)
    }

    /// Largest cluster allowed at `distance_m`; `None` beyond the last band.
    pub fn max_cluster_at(&self, distance_m: f64) -> Option<u32> {
        self.bands
            .iter()
            .find(|b| distance_m <= b.until_m)
            .map(|b| b.max_cluster)
    }

    /// Nearest distance at which a cluster of `count` objects may be drawn:
    /// the inner edge of the first band that allows it.
    pub fn nearest_distance_for(&self, count: u32) -> Option<f64> {
        let i = self.bands.iter().position(|b| b.max_cluster >= count)?;
        Some(if i == 0 {
            0.0
        } else {
            self.bands[i - 1].until_m
        })
    }

    /// Largest cluster any band allows.
    pub fn largest_cluster(&self) -> u32 {
        self.bands.iter().map(|b| b.max_cluster).max().unwrap_or(1)
    }
}

/// What one instance stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Drawn {
    /// One object, by its index in tree order (`Clusters::tree.objects`).
    Object(u32),
    /// A quadtree node drawn from its baked views: all its members.
    Node(u32),
}

/// An atlas frame: page and texel rectangle (of page level 0).
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    bytemuck::Pod,
    bytemuck::Zeroable,
    serde::Serialize,
    serde::Deserialize,
)]
pub struct AtlasFrame {
    pub page: u16,
    pub x: u16,
    pub y: u16,
    pub width: u16,
    pub height: u16,
}

/// One view of an instance: which, how much of it (cross-fade weight),
/// where in the atlas, and its size in metres (width, height).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewDraw {
    pub view: ImpostorView,
    pub weight: f32,
    pub frame: AtlasFrame,
    pub size: [f32; 2],
}

/// One impostor to draw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Instance {
    pub drawn: Drawn,
    /// Foot of the billboard: centre of the footprint at the lowest ground,
    /// terrain frame, metres. A top view lies at `foot.z + top_m`.
    pub foot: [f32; 3],
    /// Height of the top view above the foot, metres.
    pub top_m: f32,
    /// Unit horizontal vector (east, north) from the instance towards the
    /// eye: a side view is turned about the vertical to face along it.
    pub facing: [f32; 2],
    /// Views with non-zero weight, `views[..view_count]`; weights sum to 1.
    pub views: [ViewDraw; 3],
    pub view_count: u8,
    /// The share of the pixels this instance draws, as an interval of
    /// ordered-dither thresholds `[from, to)`: `[0, 1)` except while a
    /// cluster fades into its children ([`CutOptions::level_fade`]), when
    /// the cluster and its children split the interval. The views split
    /// the instance's share by their weights.
    pub share: [f32; 2],
}

impl Instance {
    pub fn views(&self) -> &[ViewDraw] {
        &self.views[..self.view_count as usize]
    }
}

/// What a selection returns; cleared and refilled each frame so its
/// allocations are reused. The instances come in chunks (the parallel
/// quadtree walk leaves one per subtree; they are not copied together):
/// [`DrawList::chunks`] to upload them, [`DrawList::instances`] to visit.
#[derive(Debug, Clone, Default)]
pub struct DrawList {
    /// The first chunk (all of a plain list or blob selection).
    first: Vec<Instance>,
    /// Objects inside the frustum and the last band that the instances
    /// stand for (a cluster partly in view counts only its members in
    /// view; what a viewer reports as objects represented).
    pub represented: usize,
    /// Clusters drawn per quadtree depth (objects drawn one by one are not
    /// counted here).
    pub clusters_per_depth: Vec<u32>,
    /// The parallel walk's scratch: subtrees left for tasks, each task's
    /// part (`parts[..used]` are in use).
    frontier: Vec<(u32, Branch)>,
    parts: Vec<DrawList>,
    used: usize,
}

impl DrawList {
    pub fn clear(&mut self) {
        self.first.clear();
        self.represented = 0;
        self.clusters_per_depth.clear();
        self.used = 0;
    }

    /// Instances drawn.
    pub fn len(&self) -> usize {
        self.chunks().map(<[Instance]>::len).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The instances, chunk by chunk, in a fixed order.
    pub fn chunks(&self) -> impl Iterator<Item = &[Instance]> {
        std::iter::once(self.first.as_slice())
            .chain(self.parts[..self.used].iter().map(|p| p.first.as_slice()))
    }

    pub fn instances(&self) -> impl Iterator<Item = &Instance> {
        self.chunks().flatten()
    }

    /// Raise (or lower) every instance's foot by `lift(x, y)` metres, taken
    /// at the foot: the viewer's mesh mode moves impostors from the grid's
    /// surface, on which they were placed, onto the refined mesh it draws.
    /// Chunks in parallel.
    pub fn lift(&mut self, lift: &(dyn Fn(f64, f64) -> f64 + Sync)) {
        let used = self.used;
        std::iter::once(&mut self.first)
            .chain(self.parts[..used].iter_mut().map(|p| &mut p.first))
            .par_bridge()
            .for_each(|chunk| {
                for instance in chunk.iter_mut() {
                    let [x, y, z] = instance.foot;
                    instance.foot[2] = z + lift(x as f64, y as f64) as f32;
                }
            });
    }

    fn count_clusters(&mut self, depth: usize, n: u32) {
        if self.clusters_per_depth.len() <= depth {
            self.clusters_per_depth.resize(depth + 1, 0);
        }
        self.clusters_per_depth[depth] += n;
    }
}

/// A way to choose what to draw.
pub trait Selection: Sync {
    fn name(&self) -> &'static str;
    /// Fill `out` (cleared first) for `camera`.
    fn select(&self, camera: &Camera, options: &CutOptions, out: &mut DrawList);
}

/// The views to draw and their weights for a line of sight `elevation_deg`
/// above the horizon and seen from compass direction `azimuth_deg` (from the
/// object towards the eye): [`ViewChoice::choose`] for that direction.
pub fn choose_views(
    elevation_deg: f64,
    azimuth_deg: f64,
    options: &CutOptions,
) -> ([(ImpostorView, f32); 3], usize) {
    let (e, a) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
    let to_eye = DVec3::new(a.sin() * e.cos(), a.cos() * e.cos(), e.sin());
    ViewChoice::new(options).choose(to_eye)
}

/// The view switch of one selection (§4.1.3, fig. 4.4): above the
/// threshold θ the top view; below, the side view nearest the azimuth.
/// Within ±crossfade/2 of θ the top view fades in linearly with the angle;
/// within ±crossfade/2 of a 45° boundary the two sides share linearly.
/// Weights sum to 1. Thresholds are kept as tangents, so only lines of
/// sight inside a fade cost an arctangent.
#[derive(Debug, Clone, Copy)]
pub struct ViewChoice {
    view_angle_deg: f64,
    half_deg: f64,
    /// tan(θ − half) and tan(θ + half): below the first no top view, above
    /// the second only the top view.
    tan_no_top: f64,
    tan_all_top: f64,
    /// tan(45° − half): below it (as min/max of |dx|, |dy|) one side only.
    tan_one_side: f64,
}

impl ViewChoice {
    pub fn new(options: &CutOptions) -> Self {
        Self::with_angle(options.view_angle_deg, options.crossfade_deg)
    }

    /// The view switch at threshold `theta` (degrees) with a cross-fade of
    /// `crossfade_deg`.
    pub fn with_angle(theta: f64, crossfade_deg: f64) -> Self {
        let half = crossfade_deg / 2.0;
        let tan = |deg: f64| {
            if deg >= 90.0 {
                f64::INFINITY
            } else if deg <= -90.0 {
                f64::NEG_INFINITY
            } else {
                deg.to_radians().tan()
            }
        };
        ViewChoice {
            view_angle_deg: theta,
            half_deg: half,
            tan_no_top: tan(theta - half),
            tan_all_top: tan(theta + half),
            tan_one_side: tan((45.0 - half).max(0.0)),
        }
    }

    /// Linear fade from 0 at −half to 1 at +half (a step when half is 0).
    fn ramp(&self, x: f64) -> f64 {
        if self.half_deg == 0.0 {
            (x >= 0.0) as u8 as f64
        } else {
            ((x + self.half_deg) / (2.0 * self.half_deg)).clamp(0.0, 1.0)
        }
    }

    /// Views and weights for `to_eye`, the vector from the impostor to the eye.
    #[inline]
    pub fn choose(&self, to_eye: DVec3) -> ([(ImpostorView, f32); 3], usize) {
        let (dx, dy, dz) = (to_eye.x, to_eye.y, to_eye.z);
        let across = (dx * dx + dy * dy).sqrt();
        let top = if dz < self.tan_no_top * across {
            0.0
        } else if dz >= self.tan_all_top * across && self.half_deg > 0.0 {
            1.0
        } else {
            self.ramp(dz.atan2(across).to_degrees() - self.view_angle_deg)
        };
        let mut out = [(ImpostorView::Top, 0.0f32); 3];
        if top >= 1.0 {
            out[0] = (ImpostorView::Top, 1.0);
            return (out, 1);
        }
        // Nearest side by the dominant axis; the neighbour is the other axis.
        let (ax, ay) = (dx.abs(), dy.abs());
        let along_y = ay >= ax;
        let y_side = if dy >= 0.0 {
            ImpostorView::Back
        } else {
            ImpostorView::Front
        };
        let x_side = if dx >= 0.0 {
            ImpostorView::Right
        } else {
            ImpostorView::Left
        };
        let (nearest, neighbour) = if along_y {
            (y_side, x_side)
        } else {
            (x_side, y_side)
        };
        let ratio = ax.min(ay) / ax.max(ay).max(f64::MIN_POSITIVE);
        // Share of the neighbour: 0 until the blend starts, ½ at the boundary.
        let shared = if ratio <= self.tan_one_side {
            0.0
        } else {
            1.0 - self.ramp(45.0 - ratio.atan().to_degrees())
        };
        let mut n = 0;
        for (view, weight) in [
            (ImpostorView::Top, top),
            (nearest, (1.0 - top) * (1.0 - shared)),
            (neighbour, (1.0 - top) * shared),
        ] {
            if weight > 0.0 {
                out[n] = (view, weight as f32);
                n += 1;
            }
        }
        (out, n)
    }
}

/// Is the box `[min, max]` at least partly inside the frustum `planes`
/// (inward normals)? Conservative: a box near a corner may pass.
#[inline]
pub fn box_in_frustum(planes: &[[f64; 4]; 6], min: [f32; 3], max: [f32; 3]) -> bool {
    frustum_mask(planes, ALL_PLANES, min, max).is_some()
}

/// Every frustum plane, as a mask for [`frustum_mask`].
pub const ALL_PLANES: u8 = 0b11_1111;

/// Test the box against the planes in `mask` (bit i: plane i): `None` when
/// it lies wholly outside one of them, else the planes it straddles. A box
/// inside a plane has children inside it, so a walk down a tree passes
/// the mask on and tests fewer planes as it goes.
#[inline]
pub fn frustum_mask(planes: &[[f64; 4]; 6], mask: u8, min: [f32; 3], max: [f32; 3]) -> Option<u8> {
    let mut straddled = 0;
    for (i, p) in planes.iter().enumerate() {
        if mask & (1 << i) == 0 {
            continue;
        }
        // The box corners furthest along and against the plane normal.
        let (mut far, mut near) = (p[3], p[3]);
        for k in 0..3 {
            let (hi, lo) = if p[k] >= 0.0 {
                (max[k], min[k])
            } else {
                (min[k], max[k])
            };
            far += p[k] * hi as f64;
            near += p[k] * lo as f64;
        }
        if far < 0.0 {
            return None;
        }
        if near < 0.0 {
            straddled |= 1 << i;
        }
    }
    Some(straddled)
}

/// Distance from `eye` to the nearest point of the box, metres (0 inside).
#[inline]
pub fn box_distance(eye: DVec3, min: [f32; 3], max: [f32; 3]) -> f64 {
    box_distance_squared(eye, min, max).sqrt()
}

/// [`box_distance`] squared.
#[inline]
pub fn box_distance_squared(eye: DVec3, min: [f32; 3], max: [f32; 3]) -> f64 {
    let gap = |k: usize, e: f64| (min[k] as f64 - e).max(e - max[k] as f64).max(0.0);
    let (x, y, z) = (gap(0, eye.x), gap(1, eye.y), gap(2, eye.z));
    x * x + y * y + z * z
}

/// Distance from `eye` to the furthest point of the box, squared.
#[inline]
fn box_farthest_distance_squared(eye: DVec3, min: [f32; 3], max: [f32; 3]) -> f64 {
    let reach = |k: usize, e: f64| (e - min[k] as f64).abs().max((max[k] as f64 - e).abs());
    let (x, y, z) = (reach(0, eye.x), reach(1, eye.y), reach(2, eye.z));
    x * x + y * y + z * z
}

/// Frustum and distance of one camera, computed once per selection.
struct View<'c> {
    camera: &'c Camera,
    planes: [[f64; 4]; 6],
    /// The planes a box is tested against: all of them, or none when
    /// culling is off ([`CutOptions::cull`]).
    planes_tested: u8,
    last_squared: f64,
    /// Screen pixels per metre at 1 m from the eye.
    pixels_per_m_at_1m: f64,
    choice: ViewChoice,
    /// Per-impostor thresholds ([`CutOptions::automatic_view_angle`]).
    automatic: bool,
    crossfade_deg: f64,
}

impl<'c> View<'c> {
    fn new(camera: &'c Camera, options: &CutOptions) -> Self {
        View {
            camera,
            planes: camera.frustum_planes(),
            planes_tested: if options.cull { ALL_PLANES } else { 0 },
            last_squared: options.last_distance().powi(2),
            pixels_per_m_at_1m: camera.plane_distance_px(),
            choice: ViewChoice::new(options),
            automatic: options.automatic_view_angle,
            crossfade_deg: options.crossfade_deg,
        }
    }

    /// Inside the frustum and no further than the last band: the distance.
    fn sees(&self, min: [f32; 3], max: [f32; 3]) -> Option<f64> {
        self.sees_within(self.planes_tested, min, max)
            .map(|(d, _)| d)
    }

    /// Members of `node` (its box straddling the planes in `mask`) inside
    /// the frustum and the last band: all of them when the box lies wholly
    /// inside both, else counted one by one.
    fn members_in_view(&self, clusters: &Clusters, node: &Node, mask: u8) -> usize {
        let far = box_farthest_distance_squared(self.camera.position, node.min, node.max);
        if mask == 0 && far <= self.last_squared {
            return node.count as usize;
        }
        clusters.tree.objects[node.members()]
            .iter()
            .filter(|o| {
                let [min, max] = o.bounds();
                self.sees_within(mask, min, max).is_some()
            })
            .count()
    }

    /// [`View::sees`] testing only the planes in `mask`: the distance and
    /// the planes the box straddles.
    #[inline]
    fn sees_within(&self, mask: u8, min: [f32; 3], max: [f32; 3]) -> Option<(f64, u8)> {
        let straddled = frustum_mask(&self.planes, mask, min, max)?;
        let d2 = box_distance_squared(self.camera.position, min, max);
        (d2 <= self.last_squared).then(|| (d2.sqrt(), straddled))
    }
}

/// Builds instances with their view choice.
impl Clusters {
    /// View `view` of what `drawn` stands for, with weight 1: its atlas
    /// frame and size (metres). A viewer drawing sprites asks for views the
    /// cut did not choose.
    #[inline]
    pub fn view_of(&self, drawn: Drawn, view: ImpostorView) -> ViewDraw {
        let (frame, size) = match drawn {
            Drawn::Object(i) => {
                let o = &self.tree.objects[i as usize];
                let frame = self.classes[o.class as usize].frames[view as usize];
                let size = match view {
                    ImpostorView::Top => [o.diameter, o.diameter],
                    _ => [o.diameter, o.height],
                };
                (frame, size)
            }
            Drawn::Node(n) => {
                let node = &self.tree.nodes[n as usize];
                let frame = self.frames[node.frames as usize + view as usize];
                (
                    frame,
                    view.extent([0, 1, 2].map(|k| node.max[k] - node.min[k])),
                )
            }
        };
        ViewDraw {
            view,
            weight: 1.0,
            frame,
            size,
        }
    }

    /// Foot (centre of the footprint at the lowest ground) and height of
    /// what `drawn` stands for, metres.
    #[inline]
    fn foot_and_height(&self, drawn: Drawn) -> ([f32; 3], f32) {
        match drawn {
            Drawn::Object(i) => {
                let o = &self.tree.objects[i as usize];
                (o.foot, o.height)
            }
            Drawn::Node(n) => {
                let node = &self.tree.nodes[n as usize];
                let foot = [
                    (node.min[0] + node.max[0]) / 2.0,
                    (node.min[1] + node.max[1]) / 2.0,
                    node.min[2],
                ];
                (foot, node.max[2] - node.min[2])
            }
        }
    }

    /// The instance of `drawn` seen from the view's eye.
    #[inline]
    fn instance(&self, drawn: Drawn, view: &View) -> Instance {
        let (foot, height) = self.foot_and_height(drawn);
        let eye = view.camera.position;
        let to_eye = DVec3::new(
            eye.x - foot[0] as f64,
            eye.y - foot[1] as f64,
            eye.z - (foot[2] as f64 + height as f64 / 2.0),
        );
        let (chosen, n) = if view.automatic {
            let width = match drawn {
                Drawn::Object(i) => self.tree.objects[i as usize].diameter,
                Drawn::Node(n) => {
                    let node = &self.tree.nodes[n as usize];
                    (node.max[0] - node.min[0]).max(node.max[1] - node.min[1])
                }
            };
            let theta = (height as f64).atan2(width.max(1e-3) as f64).to_degrees();
            ViewChoice::with_angle(theta, view.crossfade_deg).choose(to_eye)
        } else {
            view.choice.choose(to_eye)
        };
        let across = (to_eye.x * to_eye.x + to_eye.y * to_eye.y).sqrt();
        let facing = if across > 0.0 {
            [(to_eye.x / across) as f32, (to_eye.y / across) as f32]
        } else {
            [0.0, -1.0]
        };
        let mut views = [ViewDraw {
            view: ImpostorView::Top,
            weight: 0.0,
            frame: AtlasFrame::default(),
            size: [0.0; 2],
        }; 3];
        for (slot, &(v, weight)) in views.iter_mut().zip(&chosen[..n]) {
            *slot = ViewDraw {
                weight,
                ..self.view_of(drawn, v)
            };
        }
        Instance {
            drawn,
            foot,
            top_m: height,
            facing,
            views,
            view_count: n as u8,
            share: [0.0, 1.0],
        }
    }
}

/// The plain list: every object inside the frustum and the last band, one
/// by one (the seed's starting point).
pub struct ObjectList<'a>(pub &'a Clusters);

impl Selection for ObjectList<'_> {
    fn name(&self) -> &'static str {
        "list"
    }

    fn select(&self, camera: &Camera, options: &CutOptions, out: &mut DrawList) {
        out.clear();
        let view = View::new(camera, options);
        for (i, o) in self.0.tree.objects.iter().enumerate() {
            let [min, max] = o.bounds();
            if view.sees(min, max).is_some() {
                out.first
                    .push(self.0.instance(Drawn::Object(i as u32), &view));
            }
        }
        out.represented = out.first.len();
    }
}

/// The seed's blobs (§4.2.4.2): greedy squares of side K metres. A blob
/// touching the frustum draws all its members; a blob beyond the last band
/// draws none.
pub struct Blobs<'a> {
    clusters: &'a Clusters,
    blobs: std::borrow::Cow<'a, [Blob]>,
}

/// Members (tree-order object indices) and the box they fill.
#[derive(Debug, Clone, PartialEq)]
pub struct Blob {
    pub members: Vec<u32>,
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl<'a> Blobs<'a> {
    /// Group the objects: take the first object left (database order), put
    /// every object left inside the K×K square centred on it in its blob,
    /// repeat until none is left.
    pub fn new(clusters: &'a Clusters, side_m: f32) -> Blobs<'a> {
        Blobs {
            clusters,
            blobs: group_blobs(clusters, side_m).into(),
        }
    }

    /// Blobs already grouped by [`group_blobs`] (a viewer keeps them for
    /// its session).
    pub fn from_groups(clusters: &'a Clusters, blobs: &'a [Blob]) -> Blobs<'a> {
        Blobs {
            clusters,
            blobs: blobs.into(),
        }
    }

    pub fn blobs(&self) -> &[Blob] {
        &self.blobs
    }
}

/// The seed's greedy grouping into blobs of side `side_m` (see [`Blobs`]).
pub fn group_blobs(clusters: &Clusters, side_m: f32) -> Vec<Blob> {
    let objects = &clusters.tree.objects;
    let mut order: Vec<u32> = (0..objects.len() as u32).collect();
    order.sort_by_key(|&i| objects[i as usize].row);
    // Spatial hash of cell K: the square around an object touches at
    // most the 3×3 cells around its own.
    let cell = |v: f32| (v / side_m).floor() as i64;
    let mut grid: std::collections::HashMap<(i64, i64), Vec<u32>> = Default::default();
    for &i in &order {
        let f = objects[i as usize].foot;
        grid.entry((cell(f[0]), cell(f[1]))).or_default().push(i);
    }
    let mut taken = vec![false; objects.len()];
    let mut blobs = Vec::new();
    let half = side_m / 2.0;
    for &seed in &order {
        if taken[seed as usize] {
            continue;
        }
        let centre = objects[seed as usize].foot;
        let mut members = Vec::new();
        let (cx, cy) = (cell(centre[0]), cell(centre[1]));
        for gy in cy - 1..=cy + 1 {
            for gx in cx - 1..=cx + 1 {
                for &i in grid.get(&(gx, gy)).map_or(&[][..], |v| v.as_slice()) {
                    let f = objects[i as usize].foot;
                    if !taken[i as usize]
                        && (f[0] - centre[0]).abs() <= half
                        && (f[1] - centre[1]).abs() <= half
                    {
                        taken[i as usize] = true;
                        members.push(i);
                    }
                }
            }
        }
        members.sort_unstable_by_key(|&i| objects[i as usize].row);
        let (mut min, mut max) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for &i in &members {
            let [lo, hi] = objects[i as usize].bounds();
            for k in 0..3 {
                min[k] = min[k].min(lo[k]);
                max[k] = max[k].max(hi[k]);
            }
        }
        blobs.push(Blob { members, min, max });
    }
    blobs
}

impl Selection for Blobs<'_> {
    fn name(&self) -> &'static str {
        "blobs"
    }

    fn select(&self, camera: &Camera, options: &CutOptions, out: &mut DrawList) {
        out.clear();
        let view = View::new(camera, options);
        for blob in self.blobs.iter() {
            if view.sees(blob.min, blob.max).is_some() {
                for &i in &blob.members {
                    out.first
                        .push(self.clusters.instance(Drawn::Object(i), &view));
                    let [min, max] = self.clusters.tree.objects[i as usize].bounds();
                    out.represented += usize::from(view.sees(min, max).is_some());
                }
            }
        }
    }
}

/// The cut through the quadtree (§4.2.4.3, with n bands): from the root,
/// a node outside the frustum or beyond the last band is skipped with all
/// its members; a node whose size its band allows, whose views were baked
/// and whose texture the screen would not magnify too much is drawn as one
/// impostor; otherwise its children are visited, and a leaf's objects are
/// drawn one by one.
pub struct QuadtreeCut<'a>(pub &'a Clusters);

/// Depth at which the walk splits into tasks run in parallel.
const SPLIT_DEPTH: u32 = 5;

/// What a walk carries down to a subtree.
#[derive(Debug, Clone, Copy)]
struct Branch {
    /// Frustum planes the subtree's parent straddles.
    mask: u8,
    /// Dither share left to the subtree (less than `[0, 1)` below a cluster
    /// fading into its children).
    share: [f32; 2],
    /// Are the subtree's objects counted as represented here? Not below a
    /// fading cluster, which counted them already.
    counted: bool,
}

impl Selection for QuadtreeCut<'_> {
    fn name(&self) -> &'static str {
        "quadtree"
    }

    /// The walk down to `SPLIT_DEPTH` runs here; the subtrees below it
    /// run in parallel, each into its own part of the list, and the parts
    /// are appended in tree order — the result does not depend on the
    /// thread count.
    fn select(&self, camera: &Camera, options: &CutOptions, out: &mut DrawList) {
        out.clear();
        if self.0.tree.nodes.is_empty() {
            return;
        }
        let view = View::new(camera, options);
        let mut frontier = std::mem::take(&mut out.frontier);
        frontier.clear();
        let root = Branch {
            mask: view.planes_tested,
            share: [0.0, 1.0],
            counted: true,
        };
        self.walk(0, root, &view, options, out, Some(&mut frontier));
        let mut parts = std::mem::take(&mut out.parts);
        if parts.len() < frontier.len() {
            parts.resize_with(frontier.len(), DrawList::default);
        }
        parts[..frontier.len()]
            .par_iter_mut()
            .zip(&frontier)
            .for_each(|(part, &(index, branch))| {
                part.clear();
                self.walk(index, branch, &view, options, part, None);
            });
        for part in &parts[..frontier.len()] {
            out.represented += part.represented;
            for (depth, &n) in part.clusters_per_depth.iter().enumerate() {
                out.count_clusters(depth, n);
            }
        }
        out.parts = parts;
        out.used = frontier.len();
        out.frontier = frontier;
    }
}

impl QuadtreeCut<'_> {
    /// Walk the subtree at `index` into `out`. With a `frontier`, nodes at
    /// [`SPLIT_DEPTH`] that need a walk of their own are left there instead.
    fn walk(
        &self,
        index: u32,
        branch: Branch,
        view: &View,
        options: &CutOptions,
        out: &mut DrawList,
        mut frontier: Option<&mut Vec<(u32, Branch)>>,
    ) {
        let clusters = self.0;
        let node = &clusters.tree.nodes[index as usize];
        let Some((distance, mask)) = view.sees_within(branch.mask, node.min, node.max) else {
            return;
        };
        let mut branch = Branch { mask, ..branch };
        let weight = if node.count > 1 {
            clusters.node_weight(node, distance, view, options)
        } else {
            0.0
        };
        if weight > 0.0 {
            let [from, to] = branch.share;
            let split = if weight >= 1.0 {
                to
            } else {
                from + (to - from) * weight as f32
            };
            let mut instance = clusters.instance(Drawn::Node(index), view);
            instance.share = [from, split];
            out.first.push(instance);
            if branch.counted {
                out.represented += view.members_in_view(clusters, node, mask);
                out.count_clusters(node.depth as usize, 1);
            }
            if split >= to {
                return;
            }
            // Fading: the children take the rest of the share.
            branch = Branch {
                share: [split, to],
                counted: false,
                ..branch
            };
        }
        if node.is_leaf() {
            for i in node.members() {
                let [min, max] = clusters.tree.objects[i].bounds();
                if node.count == 1 || view.sees_within(mask, min, max).is_some() {
                    let mut instance = clusters.instance(Drawn::Object(i as u32), view);
                    instance.share = branch.share;
                    out.first.push(instance);
                    out.represented += usize::from(branch.counted);
                }
            }
        } else if let Some(frontier) = frontier
            .as_deref_mut()
            .filter(|_| node.depth + 1 >= SPLIT_DEPTH)
        {
            frontier.extend(
                node.children
                    .iter()
                    .filter(|&&c| c != NONE)
                    .map(|&c| (c, branch)),
            );
        } else {
            for &child in node.children.iter().filter(|&&c| c != NONE) {
                self.walk(child, branch, view, options, out, frontier.as_deref_mut());
            }
        }
    }
}

impl Clusters {
    /// How much of its share `node`, `distance_m` from the eye at its
    /// nearest, takes as one impostor: 0 where it must be refined (not
    /// baked, too many objects for its band, or its texture magnified past
    /// [`CutOptions::magnification`]), 1 where it is clear of both limits
    /// by the [`CutOptions::level_fade`] margin, linear in between. The
    /// margins are relative: the distance past the band's inner edge over
    /// that edge, and the magnification left over the limit.
    fn node_weight(&self, node: &Node, distance_m: f64, view: &View, options: &CutOptions) -> f64 {
        if node.frames == NONE
            || options
                .max_cluster_at(distance_m)
                .is_none_or(|m| node.count > m)
        {
            return 0.0;
        }
        // Texels per metre of the front view against screen pixels per metre.
        let front = self.frames[node.frames as usize + ImpostorView::Front as usize];
        let width_m = (node.max[0] - node.min[0]).max(1e-3) as f64;
        let texels_per_m = front.width as f64 / width_m;
        let pixels_per_m = view.pixels_per_m_at_1m / distance_m.max(1e-9);
        let magnification_margin = texels_per_m * options.magnification / pixels_per_m - 1.0;
        if magnification_margin < 0.0 {
            return 0.0;
        }
        let band_margin = match options.nearest_distance_for(node.count) {
            Some(edge) if edge > 0.0 => distance_m / edge - 1.0,
            _ => f64::INFINITY,
        };
        let margin = magnification_margin.min(band_margin);
        if options.level_fade <= 0.0 {
            1.0
        } else {
            (margin / options.level_fade).min(1.0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(crossfade: f64) -> CutOptions {
        CutOptions {
            crossfade_deg: crossfade,
            ..CutOptions::default()
        }
    }

    fn weights(e: f64, a: f64, o: &CutOptions) -> Vec<(ImpostorView, f32)> {
        let (v, n) = choose_views(e, a, o);
        v[..n].to_vec()
    }

    #[test]
    fn views_flip_at_the_threshold_and_the_azimuth_boundaries() {
        let hard = options(0.0);
        assert_eq!(weights(44.9, 180.0, &hard), [(ImpostorView::Front, 1.0)]);
        assert_eq!(weights(45.0, 180.0, &hard), [(ImpostorView::Top, 1.0)]);
        assert_eq!(weights(10.0, 44.9, &hard), [(ImpostorView::Back, 1.0)]);
        assert_eq!(weights(10.0, 45.1, &hard), [(ImpostorView::Right, 1.0)]);
        assert_eq!(weights(10.0, 225.1, &hard), [(ImpostorView::Left, 1.0)]);
        assert_eq!(weights(10.0, 359.0, &hard), [(ImpostorView::Back, 1.0)]);

        let soft = options(10.0);
        // Outside the fades: one view.
        assert_eq!(weights(30.0, 100.0, &soft), [(ImpostorView::Right, 1.0)]);
        assert_eq!(weights(60.0, 100.0, &soft), [(ImpostorView::Top, 1.0)]);
        // At the threshold, half top; at a side boundary, half each.
        assert_eq!(
            weights(45.0, 90.0, &soft),
            [(ImpostorView::Top, 0.5), (ImpostorView::Right, 0.5)]
        );
        let mut boundary = weights(0.0, 135.0, &soft);
        boundary.sort_by_key(|v| v.0 as u8);
        assert_eq!(boundary.len(), 2);
        for (v, (view, w)) in boundary.iter().enumerate() {
            assert_eq!(*view, [ImpostorView::Front, ImpostorView::Right][v]);
            assert!((w - 0.5).abs() < 1e-6);
        }
        let three = weights(43.0, 137.0, &soft);
        assert_eq!(three.len(), 3);
        for e in (0..=90).map(|e| e as f64) {
            for a in (0..720).map(|a| a as f64 * 0.5) {
                let w = weights(e, a, &soft);
                let sum: f32 = w.iter().map(|v| v.1).sum();
                assert!((sum - 1.0).abs() < 1e-6, "{e} {a}: {w:?}");
                assert!(w.iter().all(|v| v.1 > 0.0));
            }
        }
        // Weights move continuously through a fade.
        let share = |a: f64| {
            weights(0.0, a, &soft)
                .iter()
                .find(|v| v.0 == ImpostorView::Right)
                .map_or(0.0, |v| v.1)
        };
        assert_eq!(share(39.0), 0.0);
        assert!((share(42.5) - 0.25).abs() < 1e-6);
        assert!((share(47.5) - 0.75).abs() < 1e-6);
        assert_eq!(share(51.0), 1.0);
    }

    #[test]
    fn the_automatic_threshold_is_where_the_top_shows_more_than_the_side() {
        // A box twice as wide as tall: tan θ = ½, θ = 26.6°.
        let choice = ViewChoice::with_angle(0.5f64.atan().to_degrees(), 0.0);
        let seen = |e: f64| {
            let e = e.to_radians();
            choice.choose(DVec3::new(0.0, -e.cos(), e.sin())).0[0].0
        };
        assert_eq!(seen(26.0), ImpostorView::Front);
        assert_eq!(seen(27.0), ImpostorView::Top);
    }

    #[test]
    fn bands_answer_sizes_and_distances() {
        let o = CutOptions::default();
        assert!(o.check().is_ok());
        assert_eq!(o.max_cluster_at(0.0), Some(1));
        assert_eq!(o.max_cluster_at(2_000.0), Some(16));
        assert_eq!(o.max_cluster_at(20_001.0), None);
        assert_eq!(o.nearest_distance_for(1), Some(0.0));
        assert_eq!(o.nearest_distance_for(5), Some(1_000.0));
        assert_eq!(o.nearest_distance_for(300), None);
        for n in 1..=3 {
            let c = CutOptions::seed_configuration(n, 10_000.0).unwrap();
            assert!(c.check().is_ok());
            // As a bundle's cluster index keeps them.
            let json = serde_json::to_string(&c).unwrap();
            assert_eq!(serde_json::from_str::<CutOptions>(&json).unwrap(), c);
            assert_eq!(c.last_distance(), 20_000.0);
        }
        assert_eq!(
            CutOptions::seed_configuration(2, 1.0).unwrap().bands[1].max_cluster,
            4
        );
        assert_eq!(CutOptions::parse_bands("300:1, 1000:4").unwrap().len(), 2);
        assert!(CutOptions::parse_bands("300:1,200:4")
            .unwrap_err()
            .contains("increase"));
        assert!(CutOptions::parse_bands("300")
            .unwrap_err()
            .contains("UNTIL_M"));
        let mut bad = CutOptions::default();
        bad.bands[2].until_m = 10.0;
        assert!(bad.check().unwrap_err().contains("band 3"));
    }
}

#[cfg(test)]
mod selection_tests {
    use super::*;
    use crate::cluster::bake::tests::baked_clusters;
    use crate::cluster::checks;
    use std::collections::HashSet;

    /// Cameras over and around the 2 km test square.
    fn cameras(count: usize) -> Vec<Camera> {
        checks::random_cameras(count, 7, [-500.0, -500.0, 120.0], [2500.0, 2500.0, 720.0])
    }

    /// The default cut with its bands scaled to the 2 km test square, so
    /// that every band is used.
    fn square_options() -> CutOptions {
        let mut options = CutOptions::default();
        for (b, until) in options
            .bands
            .iter_mut()
            .zip([100.0, 300.0, 700.0, 1500.0, 2500.0])
        {
            b.until_m = until;
        }
        options
    }

    #[test]
    fn the_cut_represents_every_visible_object_exactly_once() {
        let clusters = baked_clusters(600);
        let options = square_options();
        let mut list = DrawList::default();
        let (mut clusters_drawn, mut objects_drawn, mut fading) = (0, 0, 0);
        for camera in cameras(300) {
            QuadtreeCut(&clusters).select(&camera, &options, &mut list);
            assert_eq!(
                checks::cut_problems(&clusters, &list, &camera, &options),
                Vec::<String>::new()
            );
            for instance in list.instances() {
                match instance.drawn {
                    Drawn::Node(_) => clusters_drawn += 1,
                    Drawn::Object(_) => objects_drawn += 1,
                }
                fading += usize::from(instance.share != [0.0, 1.0]);
            }
            // Without the level fade every instance draws all its pixels.
            let switching = CutOptions {
                level_fade: 0.0,
                ..options.clone()
            };
            QuadtreeCut(&clusters).select(&camera, &switching, &mut list);
            assert!(list.instances().all(|i| i.share == [0.0, 1.0]));
            assert_eq!(
                checks::cut_problems(&clusters, &list, &camera, &switching),
                Vec::<String>::new()
            );
        }
        assert!(
            clusters_drawn > 100 && objects_drawn > 100 && fading > 50,
            "{clusters_drawn} {objects_drawn} {fading}"
        );
    }

    /// Per object inside the view, the dither share drawn as the object
    /// itself (not by a cluster).
    fn own_shares(clusters: &Clusters, list: &DrawList, camera: &Camera) -> Vec<Option<f32>> {
        let planes = camera.frustum_planes();
        let mut own: Vec<Option<f32>> = clusters
            .tree
            .objects
            .iter()
            .map(|o| {
                let [min, max] = o.bounds();
                box_in_frustum(&planes, min, max).then_some(0.0)
            })
            .collect();
        for instance in list.instances() {
            if let Drawn::Object(o) = instance.drawn {
                own[o as usize] = Some(instance.share[1] - instance.share[0]);
            }
        }
        own
    }

    #[test]
    fn the_level_fade_changes_the_cut_without_popping() {
        let clusters = baked_clusters(600);
        let options = square_options();
        // Fly from 2.4 km south-west of the square's centre towards it, in
        // steps of 0.4 % of the distance left.
        let largest_jump = |options: &CutOptions| {
            let (mut list, mut previous) = (DrawList::default(), None::<Vec<Option<f32>>>);
            let mut largest = 0.0f32;
            let mut back = 1700.0;
            while back > 50.0 {
                let camera = Camera {
                    position: DVec3::new(1000.0 - back, 1000.0 - back, 300.0),
                    heading_deg: 45.0,
                    pitch_deg: -10.0,
                    incl_px: 240.0,
                    fov_x_deg: 60.0,
                    width: 640,
                    height: 480,
                    near_m: 1.0,
                    far_m: 10_000.0,
                };
                QuadtreeCut(&clusters).select(&camera, options, &mut list);
                let own = own_shares(&clusters, &list, &camera);
                if let Some(previous) = &previous {
                    for (a, b) in previous.iter().zip(&own) {
                        if let (Some(a), Some(b)) = (a, b) {
                            largest = largest.max((a - b).abs());
                        }
                    }
                }
                previous = Some(own);
                back *= 0.996;
            }
            largest
        };
        let switching = largest_jump(&CutOptions {
            level_fade: 0.0,
            ..options.clone()
        });
        let fading = largest_jump(&options);
        let wide = largest_jump(&CutOptions {
            level_fade: 0.25,
            ..options.clone()
        });
        assert_eq!(switching, 1.0, "without the fade objects pop in");
        // A step of 0.4 % of the distance moves an object's share by a few
        // tenths at most with the default fade (10 % of the distance), less
        // with a wider one.
        assert!(
            fading < 0.3 && wide < fading,
            "the largest step of an object's share: {fading} (fade {}), {wide} (fade 0.25)",
            options.level_fade
        );
    }

    #[test]
    fn without_culling_everything_within_the_last_band_is_drawn() {
        let clusters = baked_clusters(600);
        let options = CutOptions {
            cull: false,
            ..CutOptions::default()
        };
        let mut list = DrawList::default();
        for camera in cameras(20) {
            let within = clusters
                .tree
                .objects
                .iter()
                .filter(|o| {
                    let [min, max] = o.bounds();
                    box_distance(camera.position, min, max) <= options.last_distance()
                })
                .count();
            ObjectList(&clusters).select(&camera, &options, &mut list);
            assert_eq!(list.len(), within);
            QuadtreeCut(&clusters).select(&camera, &options, &mut list);
            let drawn: HashSet<u32> = checks::represented_objects(&clusters, &list)
                .into_iter()
                .map(|(o, _)| o)
                .collect();
            assert_eq!(drawn.len(), within);
        }
    }

    #[test]
    fn blobs_draw_whole_blobs_that_touch_the_view_and_nothing_far() {
        let clusters = baked_clusters(600);
        let blobs = Blobs::new(&clusters, 150.0);
        // Every object in one blob, no blob wider than K.
        let mut all: Vec<u32> = blobs
            .blobs()
            .iter()
            .flat_map(|b| b.members.clone())
            .collect();
        all.sort_unstable();
        assert_eq!(all, (0..600).collect::<Vec<u32>>());
        assert!(blobs.blobs().len() > 20 && blobs.blobs().len() < 600);
        let options = CutOptions {
            bands: vec![CutBand {
                until_m: 1200.0,
                max_cluster: 1,
            }],
            ..CutOptions::default()
        };
        let mut list = DrawList::default();
        let mut lists = DrawList::default();
        for camera in cameras(100) {
            blobs.select(&camera, &options, &mut list);
            let drawn: HashSet<u32> = checks::represented_objects(&clusters, &list)
                .into_iter()
                .map(|(o, _)| o)
                .collect();
            assert_eq!(drawn.len(), list.len());
            let planes = camera.frustum_planes();
            for blob in blobs.blobs() {
                let visible = box_in_frustum(&planes, blob.min, blob.max)
                    && box_distance(camera.position, blob.min, blob.max) <= 1200.0;
                for m in &blob.members {
                    assert_eq!(drawn.contains(m), visible, "blob rule broken");
                }
            }
            // The list draws exactly what it sees; blobs draw a superset.
            ObjectList(&clusters).select(&camera, &options, &mut lists);
            let seen: HashSet<u32> = checks::represented_objects(&clusters, &lists)
                .into_iter()
                .map(|(o, _)| o)
                .collect();
            assert!(seen.is_subset(&drawn));
        }
    }
}
