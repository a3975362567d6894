use super::{Artifact, Manifest, FORMAT, FORMAT_VERSION, MANIFEST_FILE};
use crate::{Error, Result};
use memmap2::Mmap;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

/// An opened bundle: its directory and parsed manifest.
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

    /// The manifest entry of artifact `name`.
    pub fn artifact(&self, name: &str) -> Result<&Artifact> {
        self.manifest.artifacts.get(name).ok_or_else(|| {
            Error::invalid(
                self.dir.join(MANIFEST_FILE),
                format!("no artifact {name:?}"),
            )
        })
    }

    /// Map artifact `name` as an array of `T`, checking dtype size and length.
    pub fn array<T: bytemuck::Pod>(&self, name: &str) -> Result<Array<T>> {
        let artifact = self.artifact(name)?;
        let path = self.dir.join(&artifact.file);
        if artifact.dtype.size() != Some(std::mem::size_of::<T>()) {
            return Err(Error::invalid(
                &path,
                format!("dtype {:?} cannot be read as this type", artifact.dtype),
            ));
        }
        let file = std::fs::File::open(&path).map_err(|e| Error::io(&path, e))?;
        let len = file.metadata().map_err(|e| Error::io(&path, e))?.len();
        let expected = artifact.shape.iter().product::<usize>() * std::mem::size_of::<T>();
        if len != expected as u64 {
            return Err(Error::invalid(
                &path,
                format!(
                    "{len} bytes, but shape {:?} needs {expected}",
                    artifact.shape
                ),
            ));
        }
        // SAFETY: the map is read-only; a bundle is not modified while read.
        let map = if len == 0 {
            None
        } else {
            Some(unsafe { Mmap::map(&file) }.map_err(|e| Error::io(&path, e))?)
        };
        Ok(Array {
            map,
            shape: artifact.shape.clone(),
            _element: PhantomData,
        })
    }
}
