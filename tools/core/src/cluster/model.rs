//! 3D models of vegetation classes, the source of every impostor view
//! (vegetation thesis, §4.1.2: textures rendered from OBJ models instead of
//! photographs with a hand-made alpha channel).
//!
//! A model is a triangle soup in its own frame: x east, y north, z up,
//! origin at the foot of the trunk. It comes from an OBJ file (with its MTL
//! diffuse colours and PNG textures, read with `tobj`) or from the
//! procedural generator here, which makes the default models of the default
//! classes deterministically from a seed.

use crate::{Error, Result};
use std::path::Path;

/// One triangle: corners in the model frame, texture coordinates, a colour
/// per corner (linear 0–1 RGB, multiplied with the texture when there is one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triangle {
    pub corners: [[f32; 3]; 3],
    pub uv: [[f32; 2]; 3],
    pub colour: [[f32; 3]; 3],
    /// Index into [`Model::textures`].
    pub texture: Option<u32>,
}

/// A straight-alpha RGBA8 texture, row 0 at the top (v = 1).
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    pub width: usize,
    pub height: usize,
    pub rgba: Vec<u8>,
}

impl Texture {
    /// Nearest texel at (u, v), repeating outside [0, 1].
    #[inline]
    pub fn sample(&self, u: f32, v: f32) -> [u8; 4] {
        let x = ((u.rem_euclid(1.0) * self.width as f32) as usize).min(self.width - 1);
        let y = (((1.0 - v.rem_euclid(1.0)) * self.height as f32) as usize).min(self.height - 1);
        let i = (y * self.width + x) * 4;
        [
            self.rgba[i],
            self.rgba[i + 1],
            self.rgba[i + 2],
            self.rgba[i + 3],
        ]
    }
}

/// A vegetation model.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    pub triangles: Vec<Triangle>,
    pub textures: Vec<Texture>,
}

/// The model's bounding box, model units: `[min, max]` per axis.
pub type Bounds = [[f32; 2]; 3];

impl Model {
    /// Bounding box of all corners.
    pub fn bounds(&self) -> Bounds {
        let mut b = [[f32::INFINITY, f32::NEG_INFINITY]; 3];
        for t in &self.triangles {
            for p in &t.corners {
                for k in 0..3 {
                    b[k][0] = b[k][0].min(p[k]);
                    b[k][1] = b[k][1].max(p[k]);
                }
            }
        }
        b
    }

    /// Footprint diameter (the larger horizontal extent about the origin,
    /// doubled) and height above the origin, model units.
    pub fn size(&self) -> (f32, f32) {
        let b = self.bounds();
        let radius = [b[0][0], b[0][1], b[1][0], b[1][1]]
            .iter()
            .fold(0f32, |r, v| r.max(v.abs()));
        (2.0 * radius, b[2][1].max(0.0))
    }

    /// Height over footprint diameter: how tall an object of a given
    /// diameter stands.
    pub fn aspect(&self) -> f32 {
        let (diameter, height) = self.size();
        height / diameter
    }

    /// Read an OBJ model with its materials. OBJ is y up with z towards the
    /// viewer; here y is north, so (x, y, z)_OBJ → (x, −z, y). Textures must be
    /// PNG; a missing texture, a model without faces or without extent is an
    /// error naming the file.
    pub fn load_obj(path: &Path) -> Result<Model> {
        let options = tobj::LoadOptions {
            triangulate: true,
            single_index: true,
            ..Default::default()
        };
        if !path.exists() {
            return Err(Error::invalid(path, "no such model file"));
        }
        let folder = path.parent().unwrap_or(Path::new("."));
        let mut obj = std::io::BufReader::new(crate::files::open_regular(path)?);
        // The material library is opened the same way; why it could not be
        // is kept for the message, as tobj reports only that it failed.
        let refused = std::cell::RefCell::new(None);
        let (meshes, materials) = tobj::load_obj_buf(&mut obj, &options, |mtl| {
            let mtl_path = folder.join(mtl);
            let file = crate::files::open_regular(&mtl_path).map_err(|e| {
                *refused.borrow_mut() = Some(e.to_string());
                tobj::LoadError::OpenFileFailed
            })?;
            tobj::load_mtl_buf(&mut std::io::BufReader::new(file))
        })
        .map_err(|e| Error::invalid(path, format!("not a readable OBJ model ({e})")))?;
        let materials = materials.map_err(|e| {
            let why = refused.borrow_mut().take().unwrap_or_else(|| e.to_string());
            Error::invalid(path, format!("its materials cannot be read ({why})"))
        })?;
        let mut model = Model {
            triangles: Vec::new(),
            textures: Vec::new(),
        };
        // Per material: its diffuse colour and texture index.
        let mut looks = Vec::with_capacity(materials.len());
        for material in &materials {
            let texture = match &material.diffuse_texture {
                Some(file) if !file.is_empty() => {
                    let texture_path = folder.join(file);
                    let bytes = crate::files::read(&texture_path)
                        .map_err(|e| Error::invalid(path, format!("texture {e}")))?;
                    let (rgba, width, height) =
                        crate::raster::png::decode_rgba(&bytes).map_err(|e| {
                            Error::invalid(path, format!("texture {}: {e}", texture_path.display()))
                        })?;
                    model.textures.push(Texture {
                        width,
                        height,
                        rgba,
                    });
                    Some(model.textures.len() as u32 - 1)
                }
                _ => None,
            };
            looks.push((material.diffuse.unwrap_or([0.8; 3]), texture));
        }
        for mesh in meshes.iter().map(|m| &m.mesh) {
            let (colour, texture) = mesh
                .material_id
                .and_then(|id| looks.get(id).copied())
                .unwrap_or(([0.8; 3], None));
            let corner = |i: u32| -> Option<([f32; 3], [f32; 2], [f32; 3])> {
                let i = i as usize;
                let p = mesh.positions.get(3 * i..3 * i + 3)?;
                let uv = mesh
                    .texcoords
                    .get(2 * i..2 * i + 2)
                    .map_or([0.0; 2], |t| [t[0], t[1]]);
                let c = mesh.vertex_color.get(3 * i..3 * i + 3).map_or(colour, |c| {
                    [c[0] * colour[0], c[1] * colour[1], c[2] * colour[2]]
                });
                Some(([p[0], -p[2], p[1]], uv, c))
            };
            for t in mesh.indices.chunks_exact(3) {
                let (Some(a), Some(b), Some(c)) = (corner(t[0]), corner(t[1]), corner(t[2])) else {
                    return Err(Error::invalid(path, "a face refers to a missing vertex"));
                };
                model.triangles.push(Triangle {
                    corners: [a.0, b.0, c.0],
                    uv: [a.1, b.1, c.1],
                    colour: [a.2, b.2, c.2],
                    texture,
                });
            }
        }
        if model.triangles.is_empty() {
            return Err(Error::invalid(path, "the model has no faces"));
        }
        let (diameter, height) = model.size();
        if !(diameter > 0.0 && height > 0.0 && diameter.is_finite() && height.is_finite()) {
            return Err(Error::invalid(
                path,
                "the model has no extent above its origin (z ≤ 0 everywhere, or no width)",
            ));
        }
        Ok(model)
    }
}

/// Where the model of a vegetation class comes from: a built-in kind, or an
/// OBJ file. Stored (in the cluster index, the manifest's parameters) as
/// `procedural:KIND` or the file's path.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(from = "String", into = "String")]
pub enum ModelSource {
    Procedural(TreeKind),
    Obj(std::path::PathBuf),
}

impl ModelSource {
    /// A person's or a file's choice: a kind's name (`conifer`, or as
    /// stored, `procedural:conifer`), anything else an OBJ file.
    ///
    /// ```
    /// use relevo_core::cluster::model::{ModelSource, TreeKind};
    /// assert_eq!(ModelSource::parse("conifer"), ModelSource::Procedural(TreeKind::Conifer));
    /// assert_eq!(ModelSource::parse("procedural:stand").to_string(), "procedural:stand");
    /// assert_eq!(ModelSource::parse("oak.obj"), ModelSource::Obj("oak.obj".into()));
    /// ```
    pub fn parse(text: &str) -> ModelSource {
        let kind = TreeKind::from_name(text.strip_prefix("procedural:").unwrap_or(text));
        match kind {
            Some(kind) => ModelSource::Procedural(kind),
            None => ModelSource::Obj(text.into()),
        }
    }

    /// The model itself: built, or read from its file.
    pub fn load(&self) -> Result<Model> {
        match self {
            ModelSource::Procedural(kind) => Ok(kind.model(1)),
            ModelSource::Obj(path) => Model::load_obj(path),
        }
    }
}

impl std::fmt::Display for ModelSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ModelSource::Procedural(kind) => write!(f, "procedural:{}", kind.name()),
            ModelSource::Obj(path) => write!(f, "{}", path.display()),
        }
    }
}

impl From<String> for ModelSource {
    fn from(text: String) -> Self {
        ModelSource::parse(&text)
    }
}

impl From<ModelSource> for String {
    fn from(source: ModelSource) -> Self {
        source.to_string()
    }
}

/// The procedural models, one per kind of vegetation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TreeKind {
    /// A round crown of leaf clumps on a short trunk.
    Broadleaf,
    /// Tiers of drooping branch clumps narrowing to a tip.
    Conifer,
    /// A bare trunk with a few grey limbs.
    Dead,
    /// Several broadleaf crowns of different heights sharing one footprint:
    /// the patch of forest an object of a "forest" class stands for.
    Stand,
}

impl TreeKind {
    pub const ALL: [TreeKind; 4] = [
        TreeKind::Broadleaf,
        TreeKind::Conifer,
        TreeKind::Dead,
        TreeKind::Stand,
    ];

    pub fn name(self) -> &'static str {
        match self {
            TreeKind::Broadleaf => "broadleaf",
            TreeKind::Conifer => "conifer",
            TreeKind::Dead => "dead",
            TreeKind::Stand => "stand",
        }
    }

    pub fn from_name(name: &str) -> Option<TreeKind> {
        TreeKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// The default kind for a vegetation class name: conifers, dead trees and
    /// forest patches by name, broadleaf trees otherwise.
    pub fn for_class(class: &str) -> TreeKind {
        let c = class.to_ascii_lowercase();
        let any = |words: &[&str]| words.iter().any(|w| c.contains(w));
        if any(&["conifer", "pine", "spruce", "fir", "cedar"]) {
            TreeKind::Conifer
        } else if any(&["dead", "snag"]) {
            TreeKind::Dead
        } else if any(&["forest", "stand", "wood", "grove"]) {
            TreeKind::Stand
        } else {
            TreeKind::Broadleaf
        }
    }

    /// The model of this kind, about 1 unit across, built from `seed`.
    pub fn model(self, seed: u64) -> Model {
        let mut b = Builder {
            model: Model {
                triangles: Vec::new(),
                textures: Vec::new(),
            },
            random: SplitMix(seed ^ (self as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)),
        };
        match self {
            TreeKind::Broadleaf => b.broadleaf([0.0, 0.0], 0.5, 1.3),
            TreeKind::Conifer => b.conifer(),
            TreeKind::Dead => b.dead(),
            TreeKind::Stand => {
                // Crowns of 0.25–0.35 radius around the patch, tallest in the middle.
                b.broadleaf([0.0, 0.0], 0.3, 0.55);
                for k in 0..6 {
                    let angle = k as f32 * std::f32::consts::TAU / 6.0 + b.random.range(-0.3, 0.3);
                    let reach = b.random.range(0.2, 0.3);
                    let radius = b.random.range(0.17, 0.22);
                    let height = b.random.range(0.38, 0.5);
                    b.broadleaf([reach * angle.sin(), reach * angle.cos()], radius, height);
                }
            }
        }
        b.model
    }
}

/// Deterministic pseudo-random numbers (SplitMix64; Steele, Lea and Flood,
/// "Fast splittable pseudorandom number generators", OOPSLA 2014): the same
/// seed gives the same models on every machine and version.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [lo, hi).
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * ((self.next() >> 40) as f32 / (1u64 << 24) as f32)
    }
}

/// Bark and leaf colours (linear 0–1 RGB).
const BARK: [f32; 3] = [0.32, 0.22, 0.14];
const GREY_BARK: [f32; 3] = [0.55, 0.52, 0.48];
const LEAF: [f32; 3] = [0.20, 0.42, 0.14];
const NEEDLE: [f32; 3] = [0.11, 0.30, 0.16];

struct Builder {
    model: Model,
    random: SplitMix,
}

impl Builder {
    fn triangle(&mut self, corners: [[f32; 3]; 3], colour: [f32; 3]) {
        self.model.triangles.push(Triangle {
            corners,
            uv: [[0.0; 2]; 3],
            colour: [colour; 3],
            texture: None,
        });
    }

    /// A tapered cylinder from `base` to `top` with radii `r0`, `r1`.
    fn limb(&mut self, base: [f32; 3], top: [f32; 3], r0: f32, r1: f32, colour: [f32; 3]) {
        const SIDES: usize = 6;
        let axis = sub(top, base);
        // Two unit vectors across the axis.
        let helper = if axis[2].abs() > 0.9 * norm(axis) {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 0.0, 1.0]
        };
        let u = unit(cross(axis, helper));
        let v = unit(cross(axis, u));
        let ring = |centre: [f32; 3], r: f32, k: usize| {
            let a = k as f32 * std::f32::consts::TAU / SIDES as f32;
            let (s, c) = a.sin_cos();
            [
                centre[0] + r * (c * u[0] + s * v[0]),
                centre[1] + r * (c * u[1] + s * v[1]),
                centre[2] + r * (c * u[2] + s * v[2]),
            ]
        };
        for k in 0..SIDES {
            let (a, b) = (ring(base, r0, k), ring(base, r0, k + 1));
            let (c, d) = (ring(top, r1, k), ring(top, r1, k + 1));
            self.triangle([a, b, d], colour);
            self.triangle([a, d, c], colour);
        }
    }

    /// An irregular clump of leaves: an octahedron subdivided once, its
    /// vertices pushed in and out, coloured with a little variation.
    fn clump(&mut self, centre: [f32; 3], radii: [f32; 3], colour: [f32; 3]) {
        let axes = [
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ];
        let faces = [
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ];
        let shade = self.random.range(0.8, 1.2);
        let colour = colour.map(|c| (c * shade).min(1.0));
        let jitter = |d: [f32; 3], random: &mut SplitMix| {
            let d = unit(d);
            let bump = random.range(0.75, 1.15);
            [
                centre[0] + d[0] * radii[0] * bump,
                centre[1] + d[1] * radii[1] * bump,
                centre[2] + d[2] * radii[2] * bump,
            ]
        };
        for f in faces {
            let (a, b, c) = (axes[f[0]], axes[f[1]], axes[f[2]]);
            let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
            let p = [a, b, c, ab, bc, ca].map(|d| jitter(d, &mut self.random));
            for t in [[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]] {
                self.triangle([p[t[0]], p[t[1]], p[t[2]]], colour);
            }
        }
    }

    /// A broadleaf tree at `foot` with crown radius `radius` and total height
    /// `height` (model units).
    fn broadleaf(&mut self, foot: [f32; 2], radius: f32, height: f32) {
        let crown_centre = height - radius * 0.9;
        let trunk_top = [foot[0], foot[1], crown_centre];
        self.limb(
            [foot[0], foot[1], 0.0],
            trunk_top,
            radius * 0.12,
            radius * 0.07,
            BARK,
        );
        for _ in 0..28 {
            // A point in the crown ellipsoid, flattened a little below.
            let (a, z) = (
                self.random.range(0.0, std::f32::consts::TAU),
                self.random.range(-0.75, 0.9),
            );
            let r = radius * 0.62 * (1.0 - z * z).sqrt() * self.random.range(0.5, 1.0);
            let centre = [
                foot[0] + r * a.sin(),
                foot[1] + r * a.cos(),
                crown_centre + z * radius * 0.6,
            ];
            let size = radius * self.random.range(0.3, 0.45);
            self.clump(centre, [size, size, size * 0.8], LEAF);
        }
    }

    /// A conifer 0.5 wide at the base and 2.4 tall.
    fn conifer(&mut self) {
        let height = 2.4;
        self.limb([0.0; 3], [0.0, 0.0, height], 0.05, 0.01, BARK);
        const TIERS: usize = 7;
        for tier in 0..TIERS {
            let t = tier as f32 / TIERS as f32;
            let z = 0.35 + t * (height - 0.55);
            let reach = 0.5 * (1.0 - t) + 0.06;
            let count = 7 - tier / 2;
            for k in 0..count {
                let a =
                    k as f32 * std::f32::consts::TAU / count as f32 + self.random.range(0.0, 0.6);
                let r = reach * self.random.range(0.55, 0.8);
                let centre = [r * a.sin(), r * a.cos(), z];
                let size = reach * 0.45;
                self.clump(centre, [size, size, size * 0.45], NEEDLE);
            }
        }
        self.clump([0.0, 0.0, height - 0.1], [0.06, 0.06, 0.14], NEEDLE);
    }

    /// A dead tree: a grey trunk 1.6 tall with a few bare limbs.
    fn dead(&mut self) {
        let top = [0.0, 0.0, 1.6];
        self.limb([0.0; 3], top, 0.07, 0.03, GREY_BARK);
        for k in 0..6 {
            let a = k as f32 * 1.1 + self.random.range(0.0, 0.5);
            let z = self.random.range(0.6, 1.35);
            let reach = self.random.range(0.25, 0.45);
            let end = [
                reach * a.sin(),
                reach * a.cos(),
                z + self.random.range(0.15, 0.35),
            ];
            self.limb([0.0, 0.0, z], end, 0.025, 0.01, GREY_BARK);
        }
    }
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: [f32; 3]) -> f32 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn unit(a: [f32; 3]) -> [f32; 3] {
    let n = norm(a);
    a.map(|v| v / n)
}

fn mid(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        (a[0] + b[0]) / 2.0,
        (a[1] + b[1]) / 2.0,
        (a[2] + b[2]) / 2.0,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn procedural_models_are_deterministic_and_shaped_by_kind() {
        for kind in TreeKind::ALL {
            let a = kind.model(7);
            assert_eq!(a, kind.model(7), "{kind:?}");
            assert_ne!(a, kind.model(8), "{kind:?}: the seed matters");
            let (diameter, height) = a.size();
            assert!(diameter > 0.3 && diameter < 1.5, "{kind:?} {diameter}");
            assert!(height > 0.3, "{kind:?} {height}");
        }
        assert!(TreeKind::Conifer.model(1).aspect() > TreeKind::Broadleaf.model(1).aspect());
        assert!(TreeKind::Stand.model(1).aspect() < 1.0);
        assert_eq!(TreeKind::for_class("forest"), TreeKind::Stand);
        assert_eq!(TreeKind::for_class("Pine"), TreeKind::Conifer);
        assert_eq!(TreeKind::for_class("dead"), TreeKind::Dead);
        assert_eq!(TreeKind::for_class("tree"), TreeKind::Broadleaf);
    }

    #[test]
    fn obj_models_read_with_materials_or_fail_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, text: &[u8]| {
            let p = dir.path().join(name);
            std::fs::write(&p, text).unwrap();
            p
        };
        // A textured vertical leaf card, 2 wide and 3 tall.
        let leaf = crate::raster::png::encode_rgba(&[30, 120, 20, 255, 0, 0, 0, 0], 2, 1).unwrap();
        write("leaf.png", &leaf);
        write("card.mtl", b"newmtl leaf\nKd 1 1 1\nmap_Kd leaf.png\n");
        let card = write(
            "card.obj",
            b"mtllib card.mtl\nv -1 0 0\nv 1 0 0\nv 1 3 0\nv -1 3 0\n\
              vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl leaf\nf 1/1 2/2 3/3 4/4\n",
        );
        let model = Model::load_obj(&card).unwrap();
        assert_eq!(model.triangles.len(), 2);
        assert_eq!(model.textures.len(), 1);
        assert_eq!(model.size(), (2.0, 3.0));
        assert_eq!(model.triangles[0].texture, Some(0));

        let message = |p: &Path| Model::load_obj(p).unwrap_err().to_string();
        assert!(message(&dir.path().join("none.obj")).contains("no such model file"));
        let garbage = write("garbage.obj", &[0xff, 0xfe, 0x00, 0x12, 0x80]);
        assert!(
            message(&garbage).contains("garbage.obj"),
            "{}",
            message(&garbage)
        );
        let points = write("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n");
        assert!(message(&points).contains("no faces"));
        write("lost.mtl", b"newmtl bark\nmap_Kd nowhere.png\n");
        let lost = write(
            "lost.obj",
            b"mtllib lost.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl bark\nf 1 2 3\n",
        );
        let text = message(&lost);
        assert!(
            text.contains("lost.obj") && text.contains("nowhere.png"),
            "{text}"
        );
    }
}
