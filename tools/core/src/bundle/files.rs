//! What both bundle formats share: a folder whose manifest lists files by
//! key. The vegetation database and its clusters are such files in a
//! single-grid bundle and in a pyramid alike; [`BundleFiles`] reads them
//! from either, [`StagedFiles`] writes them into either's staging folder.

use super::hash::sha256_file;
use super::manifest::{Artifact, Dtype};
use super::names::{self, ArtifactName, MANIFEST_FILE};
use crate::geo::TerrainFrame;
use crate::veg::db::{self, VegObject};
use crate::{files, Error, Result};
use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

/// A bundle of either format as the files its manifest lists.
pub trait BundleFiles {
    /// The bundle's folder.
    fn dir(&self) -> &Path;
    /// The files its manifest lists, by key.
    fn files(&self) -> &BTreeMap<String, Artifact>;
    /// The terrain frame of its (level-0) grid.
    fn terrain_frame(&self) -> TerrainFrame;

    /// The manifest entry of `key`.
    fn artifact(&self, key: &str) -> Result<&Artifact> {
        self.files().get(key).ok_or_else(|| {
            Error::invalid(
                self.dir().join(MANIFEST_FILE),
                format!("no artifact {key:?}"),
            )
        })
    }

    /// The vegetation database, when the bundle has one.
    fn vegetation(&self) -> Result<Option<Vec<VegObject>>> {
        let Some(artifact) = self.files().get(names::VEGETATION.key) else {
            return Ok(None);
        };
        let path = self.dir().join(&artifact.file);
        let text = files::read_to_string(&path)?;
        db::from_csv(&text)
            .map(Some)
            .map_err(|e| Error::invalid(&path, e.to_string()))
    }
}

/// Files written into a bundle's staging folder and recorded by key as its
/// manifest will list them.
#[derive(Debug)]
pub struct StagedFiles {
    dir: PathBuf,
    pub(crate) artifacts: BTreeMap<String, Artifact>,
}

impl StagedFiles {
    /// None yet, in staging folder `dir`.
    pub fn new(dir: &Path) -> StagedFiles {
        StagedFiles {
            dir: dir.to_path_buf(),
            artifacts: BTreeMap::new(),
        }
    }

    /// The files recorded so far, by key.
    pub fn into_artifacts(self) -> BTreeMap<String, Artifact> {
        self.artifacts
    }

    /// The vegetation database (`vegetation.csv`).
    pub fn write_vegetation(&mut self, objects: &[VegObject]) -> Result<()> {
        self.put_file(names::VEGETATION, db::to_csv(objects).as_bytes())
    }

    /// The samples the vegetation came from, as `veg::samples::to_csv` writes
    /// them (drape pixels).
    pub fn write_vegetation_samples(&mut self, csv: &str) -> Result<()> {
        self.put_file(names::VEGETATION_SAMPLES, csv.as_bytes())
    }

    /// Write a whole-file artifact under `key` (the clusters' pages have
    /// keys made at run time, so this takes the key and file apart).
    pub(crate) fn put_keyed_file(&mut self, key: &str, file: &str, bytes: &[u8]) -> Result<()> {
        self.write_bytes(file, bytes)?;
        let artifact = self.record(file)?;
        self.artifacts.insert(key.into(), artifact);
        Ok(())
    }

    /// Write a whole-file artifact under `name`.
    pub(crate) fn put_file(&mut self, name: ArtifactName, bytes: &[u8]) -> Result<()> {
        self.put_keyed_file(name.key, name.file, bytes)
    }

    /// Write `bytes` to `file` of the staging folder, its folders made.
    pub(crate) fn write_bytes(&self, file: &str, bytes: &[u8]) -> Result<()> {
        let path = self.dir.join(file);
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        fs::write(&path, bytes).map_err(|e| Error::io(&path, e))
    }

    /// The artifact record (size, SHA-256) of a file in the staging folder.
    pub(crate) fn record(&self, file: &str) -> Result<Artifact> {
        let (bytes, sha256) = sha256_file(&self.dir.join(file))?;
        Ok(Artifact {
            file: file.to_string(),
            dtype: Dtype::File,
            shape: Vec::new(),
            bytes,
            sha256,
        })
    }
}
