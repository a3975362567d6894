//! A pyramid build split into jobs that separate processes — array tasks
//! of a cluster's scheduler — run side by side on a shared file system.
//!
//! Each [`Step`] of the build becomes at most `per_step` jobs, each a run
//! of consecutive tiles of the step (row by row), numbered across the
//! steps in order. The jobs of one step write disjoint slots of the tile
//! files and read only what earlier steps wrote, so they run in any order
//! and in parallel; a job runs only once every step before its own is
//! complete. A job skips its tiles already marked done, so running it
//! again — after a kill, on another node — finishes the same bytes.
//!
//! ```
//! use relevo_core::pyramid::{jobs, TileLayout};
//! let layout = TileLayout::new(1025, 128).unwrap();
//! let all = jobs::jobs(&layout, true, 4);
//! // heights, own errors, errors and radii, drape: 4 jobs each; the
//! // lattice: one; levels 1–3 and their drapes: at most 4 each.
//! assert_eq!(all[0].tiles.len(), 16);
//! assert_eq!(all.iter().filter(|j| j.step.name() == "lattice").count(), 1);
//! ```

use super::build::{run_step, steps, BuildOptions, HeightSource, Progress, Step};
use super::layout::{TileKey, TileLayout};
use super::store::TileStore;
use crate::{Error, Result};

/// One job: some tiles of one step.
#[derive(Debug, Clone, PartialEq)]
pub struct Job {
    /// Its number, counted across the steps in order.
    pub index: usize,
    pub step: Step,
    pub tiles: Vec<TileKey>,
}

/// The jobs of a build of `layout`: each step's tiles cut into at most
/// `per_step` runs of consecutive tiles, as even as they divide.
pub fn jobs(layout: &TileLayout, drape: bool, per_step: usize) -> Vec<Job> {
    let mut out = Vec::new();
    for step in steps(layout, drape) {
        let tiles = step.tiles(layout);
        let n = per_step.clamp(1, tiles.len());
        for k in 0..n {
            let (from, to) = (k * tiles.len() / n, (k + 1) * tiles.len() / n);
            out.push(Job {
                index: out.len(),
                step,
                tiles: tiles[from..to].to_vec(),
            });
        }
    }
    out
}

/// The jobs of `jobs` with tiles not done, and those tiles.
pub fn unfinished(store: &TileStore, jobs: &[Job]) -> Result<Vec<(usize, Vec<TileKey>)>> {
    let mut out = Vec::new();
    for job in jobs {
        let left = job.step.missing(store, &job.tiles)?;
        if !left.is_empty() {
            out.push((job.index, left));
        }
    }
    Ok(out)
}

/// Run job `index` of `jobs` in `store`: its tiles not yet done, in
/// parallel, each marked when written. Refused, naming the jobs to run
/// first, while a step before its own is incomplete. Returns the wall
/// time, ms.
pub fn run_job(
    source: Option<&dyn HeightSource>,
    store: &TileStore,
    options: &BuildOptions,
    jobs: &[Job],
    index: usize,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<f64> {
    let Some(job) = jobs.get(index) else {
        return Err(Error::Input(format!(
            "no job {index}: the plan has jobs 0–{}",
            jobs.len().saturating_sub(1)
        )));
    };
    let earlier: Vec<Job> = jobs
        .iter()
        .take_while(|j| j.step != job.step)
        .cloned()
        .collect();
    let waiting = unfinished(store, &earlier)?;
    if !waiting.is_empty() {
        let tiles: usize = waiting.iter().map(|(_, t)| t.len()).sum();
        let names: Vec<String> = waiting.iter().map(|(j, _)| j.to_string()).collect();
        return Err(Error::Input(format!(
            "job {index} ({}) needs the steps before it complete, but {tiles} tiles of jobs {} \
             are not done; run those jobs first",
            job.step.name(),
            names.join(", ")
        )));
    }
    run_step(source, None, store, options, job.step, &job.tiles, progress)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::HeightGrid;
    use crate::lp::ErrorMetric;
    use crate::pyramid::build::{build, partials_capacity};
    use crate::testdata;

    #[test]
    fn every_tile_of_every_step_is_in_exactly_one_job() {
        let layout = TileLayout::new(1025, 64).unwrap();
        for per_step in [1, 3, 4, 16, 1000] {
            let all = jobs(&layout, true, per_step);
            for step in steps(&layout, true) {
                let mut tiles: Vec<TileKey> = all
                    .iter()
                    .filter(|j| j.step == step)
                    .flat_map(|j| j.tiles.clone())
                    .collect();
                let count = all.iter().filter(|j| j.step == step).count();
                assert!(count <= per_step && count >= 1, "{per_step} {step:?}");
                tiles.sort();
                let mut expected = step.tiles(&layout);
                expected.sort();
                assert_eq!(tiles, expected, "{per_step} {step:?}");
            }
            assert!(all.iter().enumerate().all(|(i, j)| j.index == i));
        }
    }

    /// The Fuji crop built as jobs — 1, 4 and 16 a step, each job's
    /// tiles in the order given — holds the bytes one build writes;
    /// a job whose earlier steps are incomplete is refused by number.
    #[test]
    fn a_build_run_as_jobs_writes_the_bytes_of_one_build() {
        let dem = testdata::dem("fuji_257.f32");
        let g = HeightGrid {
            side: dem.side,
            heights: dem.heights.clone(),
            mask: vec![1; dem.side * dem.side],
            geotransform: crate::geo::GeoTransform::north_up(
                0.0,
                0.0,
                dem.cell_size_m,
                dem.cell_size_m,
            ),
        };
        let options = BuildOptions {
            metric: ErrorMetric::Bound,
            cell_size_m: dem.cell_size_m,
            drape: true,
        };
        let layout = TileLayout::new(g.side, 32).unwrap();
        let files = TileStore::file_bytes;
        let whole = tempfile::tempdir().unwrap();
        let store = TileStore::open(whole.path(), layout, partials_capacity(&layout)).unwrap();
        build(&g, None, &store, &options, &|_| {}).unwrap();
        for per_step in [1, 4, 16] {
            let dir = tempfile::tempdir().unwrap();
            let store = TileStore::open(dir.path(), layout, partials_capacity(&layout))
                .unwrap()
                .durable();
            let all = jobs(&layout, true, per_step);
            if per_step > 1 {
                let e = run_job(Some(&g), &store, &options, &all, per_step, &|_| {})
                    .unwrap_err()
                    .to_string();
                assert!(e.contains(&format!("job {per_step} (own errors)")), "{e}");
                assert!(e.contains("jobs 0, 1"), "{e}");
            }
            // Within each step, the jobs from last to first.
            let mut order: Vec<usize> = (0..all.len()).collect();
            order.sort_by_key(|&i| {
                (
                    steps(&layout, true).iter().position(|s| *s == all[i].step),
                    std::cmp::Reverse(i),
                )
            });
            for i in order {
                run_job(Some(&g), &store, &options, &all, i, &|_| {}).unwrap();
            }
            assert!(unfinished(&store, &all).unwrap().is_empty());
            assert!(
                files(dir.path()) == files(whole.path()),
                "{per_step} jobs a step differ from one build"
            );
        }
    }
}
