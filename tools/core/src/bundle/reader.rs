use super::files::BundleFiles;
use super::manifest::{Artifact, ColorInfo, Manifest, FORMAT, FORMAT_VERSION};
use super::names::{self, ArtifactName, MANIFEST_FILE};
use crate::geo::TerrainFrame;
use crate::horizon::ColorSource;
use crate::lp::Hierarchy;
use crate::{files, Error, Result};
use memmap2::Mmap;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

/// An opened bundle: its directory and parsed manifest. Arrays are mapped
/// on request through the typed accessors ([`Bundle::heights`],
/// [`Bundle::lp`], …), each checking its shape against the grid.
#[derive(Debug, Clone)]
pub struct Bundle {
    pub dir: PathBuf,
    pub manifest: Manifest,
}

impl BundleFiles for Bundle {
    fn dir(&self) -> &Path {
        &self.dir
    }
    fn files(&self) -> &std::collections::BTreeMap<String, Artifact> {
        &self.manifest.artifacts
    }
    fn terrain_frame(&self) -> TerrainFrame {
        self.frame()
    }
}

/// An array artifact mapped into memory, read as `&[T]` without copying.
pub struct Array<T> {
    map: Option<Mmap>,
    pub shape: Vec<usize>,
    _element: PhantomData<T>,
}

impl<T: bytemuck::Pod> std::ops::Deref for Array<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        match &self.map {
            Some(map) => bytemuck::cast_slice(map),
            None => &[],
        }
    }
}

impl<'a, T: bytemuck::Pod> From<&'a Array<T>> for std::borrow::Cow<'a, [T]> {
    /// The mapped elements, borrowed.
    fn from(array: &'a Array<T>) -> Self {
        std::borrow::Cow::Borrowed(array)
    }
}

/// The mapped `lp` array; [`LpArray::hierarchy`] views it without a copy.
pub struct LpArray {
    pairs: Array<[f32; 2]>,
    frame: TerrainFrame,
}

impl LpArray {
    /// The hierarchy over the mapped `[error, radius]` pairs.
    pub fn hierarchy(&self) -> Hierarchy<'_> {
        Hierarchy::borrowed(self.frame.side, self.frame.cell_size_m, &self.pairs)
    }
}

/// The drape image: mapped RGBA8 texels and where they lie.
pub struct Drape {
    pub rgba: Array<u8>,
    pub info: ColorInfo,
}

impl Drape {
    /// The raycaster's colour source over the grid of `frame`; `None` when
    /// the image's geotransform cannot be inverted.
    pub fn color_source(&self, frame: &TerrainFrame) -> Option<ColorSource> {
        ColorSource::new(
            &self.rgba,
            self.info.width,
            self.info.height,
            &self.info.geotransform,
            frame,
        )
    }
}

/// Largest grid side a bundle may declare (2^16 + 1 vertices).
pub const MAX_SIDE: usize = (1 << 16) + 1;
/// Largest side of a drape image, pixels.
pub const MAX_IMAGE_SIDE: usize = 1 << 17;

/// A bundle is untrusted input: the manifest's grid and image must be
/// consistent before any array is mapped — a side of 2^n + 1 (at least 3,
/// at most [`MAX_SIDE`]), a positive finite cell size and z scale, finite
/// georeferencing with non-zero cell sizes, an image of sensible size, the
/// grid's and the image's arrays of the shapes those sizes give —
/// and every artifact or export must be a relative path of plain names
/// inside the bundle (no `..`, no root).
fn check_manifest(m: &Manifest) -> std::result::Result<(), String> {
    let g = &m.grid;
    if g.side < 3 || g.side > MAX_SIDE || !(g.side - 1).is_power_of_two() {
        return Err(format!(
            "grid side {} is not 2^n + 1 between 3 and {MAX_SIDE}",
            g.side
        ));
    }
    if !(g.cell_size_m.is_finite() && g.cell_size_m > 0.0) {
        return Err(format!(
            "grid cell size {} m is not a positive number",
            g.cell_size_m
        ));
    }
    if !(g.z_scale.is_finite() && g.z_scale > 0.0) {
        return Err(format!("z scale {} is not a positive number", g.z_scale));
    }
    let georeferencing = |what: &str, t: &crate::geo::GeoTransform| {
        let [_, w, _, _, _, h] = t.0;
        if t.0.iter().all(|v| v.is_finite()) && w != 0.0 && h != 0.0 {
            Ok(())
        } else {
            Err(format!("{what} georeferencing {:?} is not usable", t.0))
        }
    };
    georeferencing("grid", &g.geotransform)?;
    if let Some(c) = &m.color {
        georeferencing("image", &c.geotransform)?;
        if c.width == 0 || c.height == 0 || c.width > MAX_IMAGE_SIDE || c.height > MAX_IMAGE_SIDE {
            return Err(format!(
                "image size {}×{} is outside 1..={MAX_IMAGE_SIDE}",
                c.width, c.height
            ));
        }
    }
    let side = g.side;
    let mut shapes = vec![
        (names::HEIGHT.key, vec![side, side]),
        (names::MASK.key, vec![side, side]),
        (names::LP.key, vec![side, side, 2]),
    ];
    if let Some(c) = &m.color {
        shapes.push((names::COLOR.key, vec![c.height, c.width, 4]));
    }
    for (key, expected) in shapes {
        if let Some(a) = m.artifacts.get(key) {
            if a.shape != expected {
                return Err(format!(
                    "{key}: shape {:?} disagrees with the grid and image sizes (expected {expected:?})",
                    a.shape
                ));
            }
        }
    }
    for (key, a) in m.artifacts.iter().chain(&m.exports) {
        let path = Path::new(&a.file);
        let plain = !a.file.is_empty()
            && path
                .components()
                .all(|c| matches!(c, std::path::Component::Normal(_)));
        if !plain {
            return Err(format!(
                "{key}: file {:?} is not a relative path inside the bundle",
                a.file
            ));
        }
    }
    Ok(())
}

/// No artifact or export may be a link leading out of the bundle (its
/// canonical path must lie under the bundle's).
pub(crate) fn check_files_stay_inside<'a>(
    dir: &Path,
    files: impl IntoIterator<Item = &'a Artifact>,
) -> Result<()> {
    let root = dir.canonicalize().map_err(|e| Error::io(dir, e))?;
    for a in files {
        let path = dir.join(&a.file);
        // A missing file is reported by whoever reads it.
        if let Ok(real) = path.canonicalize() {
            if !real.starts_with(&root) {
                return Err(Error::invalid(
                    &path,
                    format!("leads out of the bundle (to {})", real.display()),
                ));
            }
        }
    }
    Ok(())
}

impl Bundle {
    /// Read `DIR/manifest.json`, check the format and version, and check
    /// that the manifest is consistent and names only files inside the
    /// bundle (`check_manifest`).
    pub fn open(dir: &Path) -> Result<Bundle> {
        let path = dir.join(MANIFEST_FILE);
        let text = files::read_to_string(&path)?;
        let format = serde_json::from_str::<serde_json::Value>(&text)
            .ok()
            .and_then(|m| m.get("format").and_then(|f| f.as_str()).map(str::to_string));
        if format.as_deref() == Some(super::PYRAMID_FORMAT) {
            return Err(Error::invalid(
                dir,
                "is a pyramid bundle (prep --tiled), which this command does not read yet; \
                 relevo info, validate, mesh, render, export, bake and relevo-view read pyramids",
            ));
        }
        let manifest: Manifest = serde_json::from_str(&text).map_err(|e| Error::Manifest {
            path: path.clone(),
            json: e,
        })?;
        if manifest.format != FORMAT {
            return Err(Error::invalid(
                &path,
                format!("format is {:?}, expected {FORMAT:?}", manifest.format),
            ));
        }
        if manifest.format_version != FORMAT_VERSION {
            return Err(Error::invalid(
                &path,
                format!(
                    "format version {} is not supported (this build reads {FORMAT_VERSION})",
                    manifest.format_version
                ),
            ));
        }
        if let Err(problem) = check_manifest(&manifest) {
            return Err(Error::invalid(&path, problem));
        }
        check_files_stay_inside(
            dir,
            manifest.artifacts.values().chain(manifest.exports.values()),
        )?;
        Ok(Bundle {
            dir: dir.to_path_buf(),
            manifest,
        })
    }

    /// The terrain frame of the height grid.
    pub fn frame(&self) -> TerrainFrame {
        let g = &self.manifest.grid;
        TerrainFrame {
            side: g.side,
            cell_size_m: g.cell_size_m,
            geotransform: g.geotransform,
        }
    }

    /// Heights in metres, row-major, `side`×`side`. Every one must be
    /// finite (a writer fills voids), so no reader meets a NaN.
    pub fn heights(&self) -> Result<Array<f32>> {
        let side = self.manifest.grid.side;
        let heights = self.grid_array(names::HEIGHT, &[side, side])?;
        if let Some(bad) = heights.iter().position(|h: &f32| !h.is_finite()) {
            return Err(Error::invalid(
                self.dir.join(names::HEIGHT.file),
                format!(
                    "height {} at row {}, column {} is not a finite number",
                    heights[bad],
                    bad / side,
                    bad % side
                ),
            ));
        }
        Ok(heights)
    }

    /// The data mask (1 data, 0 padding or void), row-major, `side`×`side`.
    pub fn mask(&self) -> Result<Array<u8>> {
        let side = self.manifest.grid.side;
        self.grid_array(names::MASK, &[side, side])
    }

    /// The Lindstrom–Pascucci errors and radii, mapped.
    pub fn lp(&self) -> Result<LpArray> {
        let side = self.manifest.grid.side;
        if !self.manifest.artifacts.contains_key(names::LP.key) {
            return Err(Error::invalid(
                self.dir.join(MANIFEST_FILE),
                "the bundle has no LP hierarchy (rebuild it with `relevo prep`)",
            ));
        }
        Ok(LpArray {
            pairs: self.grid_array(names::LP, &[side, side, 2])?,
            frame: self.frame(),
        })
    }

    /// The drape image, when the bundle has one.
    pub fn drape(&self) -> Result<Option<Drape>> {
        let Some(info) = &self.manifest.color else {
            return Ok(None);
        };
        let rgba = self.grid_array(names::COLOR, &[info.height, info.width, 4])?;
        Ok(Some(Drape {
            rgba,
            info: info.clone(),
        }))
    }

    /// Map `name` checking that its recorded shape is `shape`.
    fn grid_array<T: bytemuck::Pod>(
        &self,
        name: ArtifactName,
        shape: &[usize],
    ) -> Result<Array<T>> {
        let artifact = self.artifact(name.key)?;
        if artifact.shape != shape {
            return Err(Error::invalid(
                self.dir.join(&artifact.file),
                format!(
                    "{}: shape {:?}, expected {shape:?} for this grid",
                    name.key, artifact.shape
                ),
            ));
        }
        self.array(name.key)
    }

    /// Map artifact `name` as an array of `T` (one element, or a fixed group
    /// of elements such as `[f32; 2]`), checking dtype size and length.
    pub fn array<T: bytemuck::Pod>(&self, name: &str) -> Result<Array<T>> {
        let artifact = self.artifact(name)?;
        let path = self.dir.join(&artifact.file);
        let element = match artifact.dtype.size() {
            Some(e) if size_of::<T>().is_multiple_of(e) => e,
            _ => {
                return Err(Error::invalid(
                    &path,
                    format!("dtype {:?} cannot be read as this type", artifact.dtype),
                ))
            }
        };
        let file = files::open_regular(&path)?;
        let len = file.metadata().map_err(|e| Error::io(&path, e))?.len();
        let expected = artifact
            .shape
            .iter()
            .try_fold(element, |n, &d| n.checked_mul(d));
        if expected.map(|e| e as u64) != Some(len) {
            return Err(Error::invalid(
                &path,
                format!(
                    "{len} bytes, but shape {:?} of {:?} needs {}",
                    artifact.shape,
                    artifact.dtype,
                    expected.map_or("more than addressable".into(), |e| e.to_string())
                ),
            ));
        }
        if !(len as usize).is_multiple_of(size_of::<T>()) {
            return Err(Error::invalid(
                &path,
                format!("{len} bytes do not divide into elements of this type"),
            ));
        }
        let map = if len == 0 {
            None
        } else {
            // SAFETY: the map is read-only; a bundle is not modified while read.
            let map = unsafe { Mmap::map(&file) };
            Some(map.map_err(|e| Error::io(&path, e))?)
        };
        Ok(Array {
            map,
            shape: artifact.shape.clone(),
            _element: PhantomData,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bundle::{validate_artifacts, write_terrain_bundle, Crs, GridInfo};
    use crate::geo::GeoTransform;
    use crate::grid::HeightGrid;
    use crate::lp::ErrorMetric;
    use crate::testdata;

    /// The Fuji crop (30 m cells) written by [`write_terrain_bundle`] into
    /// a temporary folder: the folder, the bundle's path and the grid.
    fn fuji_bundle() -> (tempfile::TempDir, PathBuf, HeightGrid) {
        let dem = testdata::dem("fuji_257.f32");
        let grid = HeightGrid {
            side: dem.side,
            heights: dem.heights,
            mask: vec![1u8; dem.side * dem.side],
            geotransform: GeoTransform::north_up(0.0, dem.side as f64 * 30.0, 30.0, 30.0),
        };
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("fuji.relevo");
        let crs = Crs {
            wkt: String::new(),
            epsg: None,
        };
        write_terrain_bundle(&target, "fuji", &grid, 30.0, crs, false).unwrap();
        (dir, target, grid)
    }

    /// A bundle of the Fuji crop written by [`write_terrain_bundle`] and
    /// read back through the typed accessors: same arrays, no copy of the
    /// hierarchy, valid, and refused when an array's shape disagrees.
    #[test]
    fn bundles_round_trip_through_writer_and_reader() {
        let (dir, target, grid) = fuji_bundle();
        let dem = testdata::dem("fuji_257.f32");
        let side = dem.side;
        let hierarchy =
            Hierarchy::compute(&dem.heights, side, dem.cell_size_m, ErrorMetric::default());
        let mask = grid.mask.clone();
        assert!(!dir.path().join("fuji.relevo.tmp").exists());

        let bundle = Bundle::open(&target).unwrap();
        assert_eq!(
            bundle.manifest.grid,
            GridInfo::of(&grid, 30.0, 1.0).unwrap()
        );
        assert_eq!(&bundle.heights().unwrap()[..], &dem.heights[..]);
        assert_eq!(&bundle.mask().unwrap()[..], &mask[..]);
        let lp = bundle.lp().unwrap();
        let view = lp.hierarchy();
        assert!(matches!(view.error_radius, std::borrow::Cow::Borrowed(_)));
        assert_eq!(view, hierarchy);
        assert!(bundle.drape().unwrap().is_none());
        assert!(bundle.vegetation().unwrap().is_none());
        assert_eq!(bundle.frame().world_origin(), (15.0, 15.0));
        assert_eq!(validate_artifacts(&bundle), Vec::<String>::new());

        // A manifest whose side disagrees with the arrays is refused by name.
        let mut wrong = bundle.clone();
        wrong.manifest.grid.side = 129;
        let message = wrong
            .heights()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            message.contains("height.f32") && message.contains("[257, 257]"),
            "{message}"
        );
    }

    /// Hostile manifests are refused when the bundle is opened, before
    /// any array is mapped, with the manifest named and the problem stated.
    #[test]
    fn inconsistent_or_escaping_manifests_are_refused_on_opening() {
        let (dir, target, _) = fuji_bundle();
        let manifest_path = target.join(MANIFEST_FILE);
        let good = std::fs::read_to_string(&manifest_path).unwrap();
        let refused = |edit: &dyn Fn(&mut serde_json::Value), needle: &str| {
            let mut m: serde_json::Value = serde_json::from_str(&good).unwrap();
            edit(&mut m);
            std::fs::write(&manifest_path, serde_json::to_string(&m).unwrap()).unwrap();
            let message = Bundle::open(&target).err().map(|e| e.to_string());
            let message = message.unwrap_or_else(|| panic!("accepted: {needle}"));
            assert!(
                message.contains("manifest.json") && message.contains(needle),
                "{message}"
            );
        };
        refused(&|m| m["grid"]["side"] = 256.into(), "grid side 256");
        refused(
            &|m| m["grid"]["side"] = 129.into(),
            "height: shape [257, 257] disagrees",
        );
        refused(&|m| m["grid"]["side"] = 0.into(), "grid side 0");
        refused(
            &|m| m["grid"]["side"] = (1u64 << 40).into(),
            "is not 2^n + 1",
        );
        refused(&|m| m["grid"]["cell_size_m"] = 0.0.into(), "cell size 0");
        refused(
            &|m| m["grid"]["cell_size_m"] = (-30.0).into(),
            "cell size -30",
        );
        refused(&|m| m["grid"]["z_scale"] = 0.0.into(), "z scale 0");
        refused(
            &|m| m["grid"]["geotransform"][1] = 0.0.into(),
            "grid georeferencing",
        );
        for hostile in ["../../etc/passwd", "/etc/passwd", "a/../../b", ""] {
            refused(
                &|m| m["artifacts"]["height"]["file"] = hostile.into(),
                "not a relative path inside the bundle",
            );
        }
        // A link leading out of the bundle.
        std::fs::write(&manifest_path, &good).unwrap();
        let outside = dir.path().join("outside.f32");
        std::fs::copy(target.join("height.f32"), &outside).unwrap();
        std::fs::remove_file(target.join("height.f32")).unwrap();
        std::os::unix::fs::symlink(&outside, target.join("height.f32")).unwrap();
        let message = Bundle::open(&target)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            message.contains("height.f32") && message.contains("leads out of the bundle"),
            "{message}"
        );
        // A link inside the bundle is fine.
        std::fs::remove_file(target.join("height.f32")).unwrap();
        std::fs::rename(&outside, target.join("heights.bin")).unwrap();
        std::os::unix::fs::symlink("heights.bin", target.join("height.f32")).unwrap();
        assert!(Bundle::open(&target).unwrap().heights().is_ok());
    }
}
