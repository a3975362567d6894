//! The five orthographic views of models — top, front, back, left, right —
//! rendered on the CPU (vegetation thesis, §4.1.2–4.1.3: the views an
//! impostor shows, captured there with a frame buffer object).
//!
//! Rasterisation is deterministic: one thread per view, a fixed order of
//! triangles, 4×4 samples per texel with a depth test per sample. A texel's
//! alpha is the share of its samples covered and its colour the sum of the
//! covered samples' colours over all 16 — premultiplied by construction, so
//! the edges of leaves fade to transparent, never to a background colour.

use super::image::PremulImage;
use super::model::Model;

/// The five views of an impostor. A side view is named by where it is seen
/// from: `Front` from the south (looking north), `Back` from the north,
/// `Left` from the west, `Right` from the east.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ImpostorView {
    Top = 0,
    Front = 1,
    Back = 2,
    Left = 3,
    Right = 4,
}

impl ImpostorView {
    pub const ALL: [ImpostorView; 5] = [
        ImpostorView::Top,
        ImpostorView::Front,
        ImpostorView::Back,
        ImpostorView::Left,
        ImpostorView::Right,
    ];

    /// The side views by the compass direction they are seen from, degrees
    /// clockwise from north: back 0°, right 90°, front 180°, left 270°.
    pub const SIDES: [(ImpostorView, f64); 4] = [
        (ImpostorView::Back, 0.0),
        (ImpostorView::Right, 90.0),
        (ImpostorView::Front, 180.0),
        (ImpostorView::Left, 270.0),
    ];

    pub fn name(self) -> &'static str {
        match self {
            ImpostorView::Top => "top",
            ImpostorView::Front => "front",
            ImpostorView::Back => "back",
            ImpostorView::Left => "left",
            ImpostorView::Right => "right",
        }
    }

    /// Terrain-frame point (x east, y north, z up; relative to the view box
    /// centre) → (right, up, depth towards the viewer) of this view's image.
    /// Larger depth is nearer the viewer.
    #[inline]
    pub fn project(self, p: [f32; 3]) -> [f32; 3] {
        let [x, y, z] = p;
        match self {
            ImpostorView::Top => [x, y, z],
            ImpostorView::Front => [x, z, -y],
            ImpostorView::Back => [-x, z, y],
            ImpostorView::Left => [-y, z, -x],
            ImpostorView::Right => [y, z, x],
        }
    }

    /// Width and height, metres, of this view of a box with extents
    /// `[x, y, z]`.
    pub fn extent(self, size: [f32; 3]) -> [f32; 2] {
        match self {
            ImpostorView::Top => [size[0], size[1]],
            ImpostorView::Front | ImpostorView::Back => [size[0], size[2]],
            ImpostorView::Left | ImpostorView::Right => [size[1], size[2]],
        }
    }
}

/// A model placed in a scene: its foot at `foot` (metres), scaled to
/// `diameter` across and `height` tall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placed<'a> {
    pub model: &'a Model,
    pub foot: [f32; 3],
    pub diameter: f32,
    pub height: f32,
}

/// Samples per texel along each axis.
const SUBSAMPLES: usize = 4;

/// The fixed light: from the south-east, 50° up (unit vector).
const SUN: [f32; 3] = [0.454_519_3, -0.454_519_3, 0.766_044_4];

/// Render `scene` as seen from `view`, orthographically, over the box
/// `[min, max]` (metres), into an image of `width`×`height` texels.
pub fn render_view(
    scene: &[Placed],
    view: ImpostorView,
    min: [f32; 3],
    max: [f32; 3],
    width: usize,
    height: usize,
) -> PremulImage {
    let centre = [0, 1, 2].map(|k| (min[k] + max[k]) / 2.0);
    let [span_w, span_h] = view.extent([0, 1, 2].map(|k| max[k] - min[k]));
    let (sw, sh) = (width * SUBSAMPLES, height * SUBSAMPLES);
    // Image space: x right, y down, in samples.
    let scale = [sw as f32 / span_w, sh as f32 / span_h];
    let mut depth = vec![f32::NEG_INFINITY; sw * sh];
    let mut colour = vec![[0u8; 3]; sw * sh];
    for placed in scene {
        let (model_diameter, model_height) = placed.model.size();
        let sx = placed.diameter / model_diameter;
        let sz = placed.height / model_height;
        for t in &placed.model.triangles {
            let world = t.corners.map(|c| {
                [
                    placed.foot[0] + c[0] * sx,
                    placed.foot[1] + c[1] * sx,
                    placed.foot[2] + c[2] * sz,
                ]
            });
            let light = lambert(world);
            let screen = world.map(|p| {
                let [r, u, d] =
                    view.project([p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]]);
                [
                    r * scale[0] + sw as f32 / 2.0,
                    sh as f32 / 2.0 - u * scale[1],
                    d,
                ]
            });
            raster_triangle(
                t,
                placed.model,
                &screen,
                light,
                sw,
                sh,
                &mut depth,
                &mut colour,
            );
        }
    }
    resolve(&depth, &colour, width, height)
}

/// Two-sided Lambert shading of a triangle under [`SUN`], with sky light.
fn lambert(p: [[f32; 3]; 3]) -> f32 {
    let (u, v) = (
        [0, 1, 2].map(|k| p[1][k] - p[0][k]),
        [0, 1, 2].map(|k| p[2][k] - p[0][k]),
    );
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len.is_nan() || len <= 0.0 {
        return 0.5;
    }
    let facing = ((n[0] * SUN[0] + n[1] * SUN[1] + n[2] * SUN[2]) / len).abs();
    0.45 + 0.55 * facing
}

/// Fill the samples of one triangle whose corners are in sample space
/// (x right, y down, depth larger nearer).
#[allow(clippy::too_many_arguments)]
fn raster_triangle(
    t: &super::model::Triangle,
    model: &Model,
    s: &[[f32; 3]; 3],
    light: f32,
    sw: usize,
    sh: usize,
    depth: &mut [f32],
    colour: &mut [[u8; 3]],
) {
    let edge = |a: [f32; 3], b: [f32; 3], x: f32, y: f32| {
        (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0])
    };
    let area = edge(s[0], s[1], s[2][0], s[2][1]);
    if area == 0.0 || !area.is_finite() {
        return;
    }
    let inverse_area = 1.0 / area;
    let lo = |k: usize| s.iter().map(|p| p[k]).fold(f32::INFINITY, f32::min);
    let hi = |k: usize| s.iter().map(|p| p[k]).fold(f32::NEG_INFINITY, f32::max);
    let x0 = (lo(0).floor().max(0.0)) as usize;
    let y0 = (lo(1).floor().max(0.0)) as usize;
    let x1 = (hi(0).ceil().min(sw as f32)) as usize;
    let y1 = (hi(1).ceil().min(sh as f32)) as usize;
    let texture = t.texture.and_then(|i| model.textures.get(i as usize));
    for y in y0..y1 {
        let py = y as f32 + 0.5;
        for x in x0..x1 {
            let px = x as f32 + 0.5;
            // Barycentric weights; the same sign as the area means inside.
            let w0 = edge(s[1], s[2], px, py) * inverse_area;
            let w1 = edge(s[2], s[0], px, py) * inverse_area;
            let w2 = 1.0 - w0 - w1;
            if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                continue;
            }
            let z = w0 * s[0][2] + w1 * s[1][2] + w2 * s[2][2];
            let i = y * sw + x;
            if z <= depth[i] {
                continue;
            }
            let mut rgb =
                [0, 1, 2].map(|k| w0 * t.colour[0][k] + w1 * t.colour[1][k] + w2 * t.colour[2][k]);
            if let Some(texture) = texture {
                let u = w0 * t.uv[0][0] + w1 * t.uv[1][0] + w2 * t.uv[2][0];
                let v = w0 * t.uv[0][1] + w1 * t.uv[1][1] + w2 * t.uv[2][1];
                let texel = texture.sample(u, v);
                // Alpha-tested: leaves are in or out at each sample; the
                // coverage of a texel comes from its 16 samples.
                if texel[3] < 128 {
                    continue;
                }
                for k in 0..3 {
                    rgb[k] *= texel[k] as f32 / 255.0;
                }
            }
            depth[i] = z;
            colour[i] = rgb.map(|c| (c * light * 255.0).round().clamp(0.0, 255.0) as u8);
        }
    }
}

/// Average each texel's 4×4 samples into premultiplied RGBA8.
fn resolve(depth: &[f32], colour: &[[u8; 3]], width: usize, height: usize) -> PremulImage {
    let sw = width * SUBSAMPLES;
    let n = (SUBSAMPLES * SUBSAMPLES) as u32;
    let mut image = PremulImage::transparent(width, height);
    for y in 0..height {
        for x in 0..width {
            let (mut sum, mut covered) = ([0u32; 3], 0u32);
            for sy in 0..SUBSAMPLES {
                for sx in 0..SUBSAMPLES {
                    let i = (y * SUBSAMPLES + sy) * sw + x * SUBSAMPLES + sx;
                    if depth[i] > f32::NEG_INFINITY {
                        covered += 1;
                        for k in 0..3 {
                            sum[k] += colour[i][k] as u32;
                        }
                    }
                }
            }
            let c = sum.map(|s| ((s + n / 2) / n) as u8);
            let a = ((covered * 255 + n / 2) / n) as u8;
            image.texels[y * width + x] = [c[0], c[1], c[2], a];
        }
    }
    image
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::model::TreeKind;

    #[test]
    fn views_are_deterministic_premultiplied_and_see_the_right_side() {
        let model = TreeKind::Broadleaf.model(3);
        let (d, h) = model.size();
        let scene = [Placed {
            model: &model,
            foot: [0.0; 3],
            diameter: d,
            height: h,
        }];
        let (min, max) = ([-d / 2.0, -d / 2.0, 0.0], [d / 2.0, d / 2.0, h]);
        for view in ImpostorView::ALL {
            let a = render_view(&scene, view, min, max, 64, 64);
            assert_eq!(a, render_view(&scene, view, min, max, 64, 64));
            assert!(a.texels.iter().all(|t| t[..3].iter().all(|&c| c <= t[3])));
            let covered = a.texels.iter().filter(|t| t[3] > 0).count();
            assert!(covered > 64 * 64 / 5, "{view:?}: {covered}");
            // Edges fade: some texels are partly covered.
            assert!(a.texels.iter().any(|t| t[3] > 0 && t[3] < 255));
        }
        // A trunk seen from the side reaches the bottom row; from the top
        // the crown hides it.
        let front = render_view(&scene, ImpostorView::Front, min, max, 64, 64);
        assert!((0..64).any(|x| front.texel(x, 63)[3] > 0));
        // A marker east of the origin shows on the right of the front view
        // and on the left of the back view.
        let marker = TreeKind::Dead.model(1);
        let east = [Placed {
            model: &marker,
            foot: [0.8, 0.0, 0.0],
            diameter: 0.3,
            height: 1.0,
        }];
        let (min, max) = ([-1.0, -1.0, 0.0], [1.0, 1.0, 1.0]);
        let column = |image: &PremulImage| {
            let (mut sum, mut n) = (0.0, 0.0);
            for y in 0..image.height {
                for x in 0..image.width {
                    sum += x as f64 * image.texel(x, y)[3] as f64;
                    n += image.texel(x, y)[3] as f64;
                }
            }
            sum / n / image.width as f64
        };
        assert!(column(&render_view(&east, ImpostorView::Front, min, max, 32, 16)) > 0.8);
        assert!(column(&render_view(&east, ImpostorView::Back, min, max, 32, 16)) < 0.2);
        assert!(column(&render_view(&east, ImpostorView::Top, min, max, 32, 32)) > 0.8);
    }
}
