use super::names::{self, ArtifactName};
use super::{Artifact, ColorInfo, Manifest, FORMAT, FORMAT_VERSION, MANIFEST_FILE};
use crate::geo::TerrainFrame;
use crate::horizon::ColorSource;
use crate::lp::Hierarchy;
use crate::veg::db::{self, VegObject};
use crate::{Error, Result};
use memmap2::Mmap;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

/// An opened bundle: its directory and parsed manifest. Arrays are mapped
/// on request through the typed accessors ([`Bundle::heights`],
/// [`Bundle::hierarchy`], …), each checking its shape against the grid.
#[derive(Debug, Clone)]
pub struct Bundle {
    pub dir: PathBuf,
    pub manifest: Manifest,
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

impl Bundle {
    /// Read `DIR/manifest.json` and check the format and version.
    pub fn open(dir: &Path) -> Result<Bundle> {
        let path = dir.join(MANIFEST_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let manifest: Manifest = serde_json::from_str(&text).map_err(|e| Error::Manifest {
            path: path.clone(),
            source: e,
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

    /// Heights in metres, row-major, `side`×`side`.
    pub fn heights(&self) -> Result<Array<f32>> {
        let side = self.manifest.grid.side;
        self.grid_array(names::HEIGHT, &[side, side])
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

    /// The vegetation database, when the bundle has one.
    pub fn vegetation(&self) -> Result<Option<Vec<VegObject>>> {
        let Some(artifact) = self.manifest.artifacts.get(names::VEGETATION.key) else {
            return Ok(None);
        };
        let path = self.dir.join(&artifact.file);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        db::from_csv(&text)
            .map(Some)
            .map_err(|e| Error::invalid(&path, e.to_string()))
    }

    /// The manifest entry of artifact `name`.
    pub fn artifact(&self, name: &str) -> Result<&Artifact> {
        self.manifest.artifacts.get(name).ok_or_else(|| {
            Error::invalid(
                self.dir.join(MANIFEST_FILE),
                format!("no artifact {name:?}"),
            )
        })
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
        let file = std::fs::File::open(&path).map_err(|e| Error::io(&path, e))?;
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
    use crate::bundle::{validate, write_terrain_bundle, Crs, GridInfo};
    use crate::geo::GeoTransform;
    use crate::grid::HeightGrid;
    use crate::testdata;

    /// A bundle of the Fuji crop written by [`write_terrain_bundle`] and
    /// read back through the typed accessors: same arrays, no copy of the
    /// hierarchy, valid, and refused when an array's shape disagrees.
    #[test]
    fn bundles_round_trip_through_writer_and_reader() {
        let dem = testdata::dem("fuji_257.f32");
        let side = dem.side;
        let hierarchy = Hierarchy::compute(&dem.heights, side, dem.cell_size_m);
        let mask = vec![1u8; side * side];
        let grid = HeightGrid {
            side,
            heights: dem.heights.clone(),
            mask: mask.clone(),
            geotransform: GeoTransform::north_up(0.0, side as f64 * 30.0, 30.0, 30.0),
        };
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("fuji.relevo");
        let crs = Crs {
            wkt: String::new(),
            epsg: None,
        };
        write_terrain_bundle(&target, "fuji", &grid, 30.0, crs, false).unwrap();
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
        assert_eq!(validate(&bundle), Vec::<String>::new());

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
}
