//! A bundle checked against its golden record: per artifact, unchanged
//! (same SHA-256), changed within the tolerances, or changed beyond them —
//! with the figure, the tolerance and the place, block by block.

use super::blocks::{Block, BlockDigest, BlockLayout, BlockStatistics};
use super::finding::{Finding, Outcome, Place, MOST_PLACES};
use super::record::{self, GoldenRecord, RenderRecord, Tolerances};
use super::vegetation::{ClassBlock, ClassDigest, VegetationDigest};
use crate::bundle::{names, Bundle};
use crate::geo::GeoTransform;
use crate::raster::compare::{difference, ImageDifference};
use crate::scene::{self, CameraPose, View};
use crate::{Error, Result};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

/// The whole check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CheckReport {
    pub region: String,
    pub findings: Vec<Finding>,
}

impl CheckReport {
    /// Whether every artifact is within its tolerance.
    pub fn passed(&self) -> bool {
        self.findings.iter().all(|f| f.outcome != Outcome::Changed)
    }
}

/// What a check compares, and how strictly.
#[derive(Debug, Clone, Default)]
pub struct CheckOptions {
    pub tolerances: Tolerances,
    /// Artifacts not compared: manifest keys, or prefixes of them ending in
    /// `*` (`clusters*`), and `render:NAME`.
    pub skip: Vec<String>,
}

impl CheckOptions {
    fn skips(&self, key: &str) -> bool {
        self.skip.iter().any(|s| match s.strip_suffix('*') {
            Some(prefix) => key.starts_with(prefix),
            None => key == s,
        })
    }
}

/// Check `bundle` against `record` (read from the folder `record_dir`,
/// where its renders lie). An error means the inputs cannot be compared: a
/// bundle that fails validation, a record of another region, an artifact
/// the record lists that the bundle lacks, a missing reference file.
pub fn check(
    bundle: &Bundle,
    record: &GoldenRecord,
    record_dir: &Path,
    options: &CheckOptions,
) -> Result<CheckReport> {
    let tolerances = &options.tolerances;
    let m = &bundle.manifest;
    if record.region != m.region {
        return Err(Error::Input(format!(
            "the golden record is of region {:?}, the bundle {} of {:?}",
            record.region,
            bundle.dir.display(),
            m.region
        )));
    }
    // The bundle's files must be the ones its manifest describes, since the
    // comparison starts from the manifest's hashes.
    let problems = crate::validation::validate(bundle);
    if !problems.is_empty() {
        return Err(Error::invalid(
            &bundle.dir,
            format!("fails validation: {}", problems.join("; ")),
        ));
    }
    let mut findings = Vec::new();
    let in_bundle: BTreeMap<&String, &crate::bundle::Artifact> =
        m.artifacts.iter().chain(&m.exports).collect();
    // An atlas page can go when the clusters are baked into fewer pages:
    // a change. Any other artifact the record lists must be there.
    let has_clusters = in_bundle.contains_key(&names::CLUSTER_INDEX.key.to_string());
    for (key, recorded) in &record.artifacts {
        if in_bundle.contains_key(key) {
            continue;
        }
        if has_clusters && key.starts_with(names::CLUSTER_PAGE_PREFIX) {
            findings.push(changed(
                key,
                format!(
                    "{} is gone: the clusters were baked into fewer pages",
                    recorded.file
                ),
                "the record's artifacts",
            ));
        } else {
            return Err(Error::invalid(
                &bundle.dir,
                format!("has no artifact {key:?}, which the golden record lists"),
            ));
        }
    }
    let same_grid =
        record.grid.side == m.grid.side && record.grid.geotransform == m.grid.geotransform;
    for (key, artifact) in &in_bundle {
        if options.skips(key) {
            findings.push(skipped(key));
            continue;
        }
        let Some(recorded) = record.artifacts.get(*key) else {
            findings.push(Finding {
                artifact: (*key).clone(),
                outcome: Outcome::Changed,
                figure: format!("new artifact {} the record does not list", artifact.file),
                tolerance: "the record's artifacts".into(),
                places: Vec::new(),
            });
            continue;
        };
        if recorded.sha256 == artifact.sha256 {
            findings.push(Finding {
                artifact: (*key).clone(),
                outcome: Outcome::Unchanged,
                figure: "same SHA-256".into(),
                tolerance: "exact".into(),
                places: Vec::new(),
            });
            continue;
        }
        if let (Some(r), true) = (&recorded.reference, same_grid) {
            let statistics = recorded
                .blocks
                .as_ref()
                .map_or(BlockStatistics::Max, |b| b.statistics);
            let tolerance = move |v: f64| allowed(statistics, tolerances, v);
            let judge = super::reference::Judge {
                tolerance: &tolerance,
                words: tolerance_words(statistics, tolerances),
                unit: unit(statistics),
                exact: is_exact(statistics, tolerances),
            };
            findings.push(super::reference::compare(
                bundle, key, r, record_dir, &judge,
            )?);
            continue;
        }
        let (blocks, classes) = record::current_summary(bundle, key)?;
        let finding = match (&recorded.blocks, blocks, &recorded.classes, classes) {
            (Some(before), Some(after), _, _) if same_grid || before.statistics == BlockStatistics::MeanColour => {
                compare_blocks(key, before, &after, &block_geo(bundle, before), tolerances)
            }
            (_, _, Some(before), Some(after)) if same_grid => {
                compare_vegetation(key, before, &after, bundle, tolerances)
            }
            _ if !same_grid => changed(
                key,
                format!(
                    "the grid changed from {}² to {}² cells (or moved): not comparable block by block",
                    record.grid.side, m.grid.side
                ),
                "the recorded grid",
            ),
            _ => changed(key, format!("{} differs (SHA-256)", artifact.file), "exact (hash only)"),
        };
        findings.push(finding);
    }
    for render in &record.renders {
        let key = format!("render:{}", render.name);
        findings.push(match options.skips(&key) {
            true => skipped(&key),
            false => check_render(bundle, render, record_dir, tolerances)?,
        });
    }
    Ok(CheckReport {
        region: record.region.clone(),
        findings,
    })
}

/// The georeferencing of the raster a digest was made of: the drape's own
/// for colour, the grid's otherwise.
fn block_geo(bundle: &Bundle, digest: &BlockDigest) -> GeoTransform {
    match (&bundle.manifest.color, digest.statistics) {
        (Some(c), BlockStatistics::MeanColour) => c.geotransform,
        _ => bundle.manifest.grid.geotransform,
    }
}

fn skipped(key: &str) -> Finding {
    Finding {
        artifact: key.to_string(),
        outcome: Outcome::Skipped,
        figure: "not compared (--skip)".into(),
        tolerance: "skipped".into(),
        places: Vec::new(),
    }
}

fn changed(key: &str, figure: String, tolerance: &str) -> Finding {
    Finding {
        artifact: key.to_string(),
        outcome: Outcome::Changed,
        figure,
        tolerance: tolerance.to_string(),
        places: Vec::new(),
    }
}

/// A block's extent, in cells and in the CRS.
fn place_of(
    layout: &BlockLayout,
    geo: &GeoTransform,
    [bx, by]: [usize; 2],
    change: f64,
    what: String,
) -> Place {
    let cells = layout.cells_of(bx, by);
    let (x0, y0) = geo.apply(cells[0] as f64, cells[3] as f64);
    let (x1, y1) = geo.apply(cells[2] as f64, cells[1] as f64);
    Place {
        block: [bx, by],
        cells,
        bounds: [x0.min(x1), y0.min(y1), x0.max(x1), y0.max(y1)],
        change,
        what,
    }
}

/// The tolerance of one recorded value, and its words.
fn allowed(statistics: BlockStatistics, t: &Tolerances, recorded: f64) -> f64 {
    match statistics {
        BlockStatistics::MinMeanMax => t.height_m + t.height_relative * recorded.abs(),
        BlockStatistics::Max => t.lp_error_m,
        BlockStatistics::Count => 0.0,
        BlockStatistics::MeanColour => t.drape_levels,
    }
}

/// Whether the tolerance of values of this kind is zero (any change fails).
fn is_exact(statistics: BlockStatistics, t: &Tolerances) -> bool {
    match statistics {
        BlockStatistics::MinMeanMax => t.height_m == 0.0 && t.height_relative == 0.0,
        BlockStatistics::Max => t.lp_error_m == 0.0,
        BlockStatistics::Count => true,
        BlockStatistics::MeanColour => t.drape_levels == 0.0,
    }
}

fn tolerance_words(statistics: BlockStatistics, t: &Tolerances) -> String {
    let exact = |v: f64| v == 0.0;
    match statistics {
        BlockStatistics::MinMeanMax if exact(t.height_m) && exact(t.height_relative) => {
            "exact heights".into()
        }
        BlockStatistics::MinMeanMax => format!(
            "heights within {} m + {} × height",
            t.height_m, t.height_relative
        ),
        BlockStatistics::Max if exact(t.lp_error_m) => "exact LP errors".into(),
        BlockStatistics::Max => format!("LP errors within {} m", t.lp_error_m),
        BlockStatistics::Count => "exact data cells per block".into(),
        BlockStatistics::MeanColour if exact(t.drape_levels) => "exact drape colour".into(),
        BlockStatistics::MeanColour => format!("drape colour within {} levels", t.drape_levels),
    }
}

fn unit(statistics: BlockStatistics) -> &'static str {
    match statistics {
        BlockStatistics::MinMeanMax | BlockStatistics::Max => " m",
        BlockStatistics::Count => " cells",
        BlockStatistics::MeanColour => " levels",
    }
}

/// Compare a grid's blocks: a block whose hash is unchanged is unchanged;
/// another is within tolerance when each of its statistics moved by no
/// more than the tolerance allows (a tolerance of zero allows no change).
fn compare_blocks(
    key: &str,
    before: &BlockDigest,
    after: &BlockDigest,
    geo: &GeoTransform,
    t: &Tolerances,
) -> Finding {
    let tolerance = format!(
        "{}, judged by each block's {} (no reference grid beside the record)",
        tolerance_words(before.statistics, t),
        match before.statistics {
            BlockStatistics::MinMeanMax => "lowest, mean and highest value",
            BlockStatistics::Max => "largest value",
            BlockStatistics::Count => "count",
            BlockStatistics::MeanColour => "mean red, green and blue",
        }
    );
    if before.width != after.width || before.height != after.height {
        return changed(
            key,
            format!(
                "size changed from {}×{} to {}×{}",
                before.width, before.height, after.width, after.height
            ),
            &tolerance,
        );
    }
    let (old, new) = (before.blocks(), after.blocks());
    let layout = before.layout();
    let exact = is_exact(before.statistics, t);
    let (mut beyond, mut within, mut largest) = (Vec::new(), Vec::new(), 0.0f64);
    for (by, (old_row, new_row)) in old.iter().zip(&new).enumerate() {
        for (bx, (o, n)) in old_row.iter().zip(new_row).enumerate() {
            if o.hash == n.hash {
                continue;
            }
            let (moved, fits) = block_change(o, n, before.statistics, t);
            largest = largest.max(moved);
            let what = describe_block_change(o, n, before.statistics, moved);
            let place = place_of(&layout, geo, [bx, by], moved, what);
            if fits && !exact {
                within.push(place);
            } else {
                beyond.push(place);
            }
        }
    }
    let changed_blocks = beyond.len() + within.len();
    let figure = format!(
        "{changed_blocks} of {} blocks changed, largest block change {largest:.3}{}",
        old.iter().map(Vec::len).sum::<usize>(),
        unit(before.statistics)
    );
    let (outcome, mut places) = if beyond.is_empty() {
        (Outcome::WithinTolerance, within)
    } else {
        (Outcome::Changed, beyond)
    };
    // The largest changes first.
    places.sort_by(|a, b| b.change.total_cmp(&a.change));
    places.truncate(MOST_PLACES);
    Finding {
        artifact: key.to_string(),
        outcome,
        figure,
        tolerance,
        places,
    }
}

/// How far a block's statistics moved (the largest), and whether each is
/// within its tolerance.
fn block_change(o: &Block, n: &Block, statistics: BlockStatistics, t: &Tolerances) -> (f64, bool) {
    match (&o.values, &n.values) {
        (Some(a), Some(b)) => {
            let mut largest = 0.0f64;
            let mut fits = true;
            for (x, y) in a.iter().zip(b) {
                let d = (y - x).abs();
                largest = largest.max(d);
                fits &= d <= allowed(statistics, t, *x);
            }
            (largest, fits)
        }
        (None, None) => (0.0, true),
        // Data appeared or vanished.
        _ => (f64::INFINITY, false),
    }
}

fn describe_block_change(o: &Block, n: &Block, statistics: BlockStatistics, moved: f64) -> String {
    // `moved` is the place's `change`; the words say what moved.
    let u = unit(statistics);
    match (&o.values, &n.values) {
        (Some(a), Some(b)) if statistics == BlockStatistics::MinMeanMax => format!(
            "lowest {:.3} → {:.3}, mean {:.3} → {:.3}, highest {:.3} → {:.3}",
            a[0], b[0], a[1], b[1], a[2], b[2]
        ),
        (Some(_), Some(_)) if moved == 0.0 => {
            "values changed by less than the record's resolution".into()
        }
        (Some(a), Some(b)) => format!("{} → {}{u}", join(a), join(b)),
        (None, Some(_)) => "data appeared where there was none".into(),
        (Some(_), None) => "the data here vanished".into(),
        (None, None) => "values without data changed".into(),
    }
}

fn join(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:.3}"))
        .collect::<Vec<_>>()
        .join("/")
}

/// Compare the vegetation by class: counts within the count tolerance, and
/// per block the count and the mean position within theirs.
fn compare_vegetation(
    key: &str,
    before: &VegetationDigest,
    after: &VegetationDigest,
    bundle: &Bundle,
    t: &Tolerances,
) -> Finding {
    let side = bundle.manifest.grid.side;
    let layout = BlockLayout::of(side, side);
    let geo = bundle.manifest.grid.geotransform;
    let tolerance = format!(
        "{} object(s) per class and block, mean positions within {} m",
        t.vegetation_count, t.vegetation_position_m
    );
    let empty = ClassDigest {
        count: 0,
        blocks: Vec::new(),
    };
    let (mut beyond, mut summary, mut class_beyond) = (Vec::new(), Vec::new(), false);
    let classes: std::collections::BTreeSet<&String> = before.keys().chain(after.keys()).collect();
    for class in classes {
        let (b, a) = (
            before.get(class).unwrap_or(&empty),
            after.get(class).unwrap_or(&empty),
        );
        if b.count != a.count {
            summary.push(format!("{class}: {} → {} objects", b.count, a.count));
        }
        let index = |d: &ClassDigest| -> BTreeMap<[usize; 2], ClassBlock> {
            d.parse()
                .unwrap_or_default()
                .into_iter()
                .map(|c| (c.block, c))
                .collect()
        };
        let (old, new) = (index(b), index(a));
        let blocks: std::collections::BTreeSet<&[usize; 2]> =
            old.keys().chain(new.keys()).collect();
        for block in blocks {
            let (o, n) = (old.get(block), new.get(block));
            let (count_o, count_n) = (o.map_or(0, |c| c.count), n.map_or(0, |c| c.count));
            let shift = match (o, n) {
                (Some(o), Some(n)) => (o.mean[0] - n.mean[0]).hypot(o.mean[1] - n.mean[1]),
                _ => 0.0,
            };
            let count_off = count_o.abs_diff(count_n);
            if count_off > t.vegetation_count || shift > t.vegetation_position_m {
                let what = format!(
                    "{class}: {count_o} → {count_n} objects, mean position moved {shift:.3} m"
                );
                let change = shift.max(count_off as f64);
                beyond.push(place_of(&layout, &geo, *block, change, what));
            }
        }
        class_beyond |= b.count.abs_diff(a.count) > t.vegetation_count;
    }
    let changed_blocks = beyond.len();
    beyond.sort_by(|p, q| q.change.total_cmp(&p.change));
    beyond.truncate(MOST_PLACES);
    Finding {
        artifact: key.to_string(),
        outcome: if changed_blocks == 0 && !class_beyond {
            Outcome::WithinTolerance
        } else {
            Outcome::Changed
        },
        figure: if summary.is_empty() {
            format!("class counts unchanged; {changed_blocks} block(s) beyond tolerance")
        } else {
            format!(
                "{}; {changed_blocks} block(s) beyond tolerance",
                summary.join(", ")
            )
        },
        tolerance,
        places: beyond,
    }
}

/// Render `render` of `bundle` as the record's renders are made: the CPU
/// raycaster with its default options, RGBA8 rows.
pub fn render_reference(bundle: &Bundle, render: &RenderRecord) -> Result<Vec<u8>> {
    let pose = CameraPose::parse(&render.camera)
        .map_err(|e| Error::Input(format!("render {}: camera {e}", render.name)))?;
    let view = View {
        eye: pose.eye,
        heading_deg: pose.heading_deg,
        pitch_deg: pose.pitch_deg,
        incl_px: pose.incl_px,
        fov_x_deg: 60.0,
        size: render.size,
        far_cells: 1024.0,
    };
    crate::memory::check(
        &format!(
            "render {} ({}×{})",
            render.name, render.size[0], render.size[1]
        ),
        u64::from(render.size[0]) * u64::from(render.size[1]),
        crate::horizon::RaycastFrame::BYTES_PER_PIXEL,
        "choose a smaller size",
    )?;
    let frame = scene::render_bundle(bundle, &view, &Default::default(), None)?;
    Ok(frame.to_rows().rgba_bytes().to_vec())
}

/// Render again and compare with the reference PNG beside the record.
fn check_render(
    bundle: &Bundle,
    render: &RenderRecord,
    record_dir: &Path,
    t: &Tolerances,
) -> Result<Finding> {
    let path = record_dir.join(&render.file);
    let bytes = crate::files::read(&path)?;
    let (expected, w, h) = crate::raster::png::decode_rgba(&bytes)
        .map_err(|e| Error::invalid(&path, e.to_string()))?;
    if [w as u32, h as u32] != render.size {
        return Err(Error::invalid(
            &path,
            format!(
                "is {w}×{h}, the record says {}×{}",
                render.size[0], render.size[1]
            ),
        ));
    }
    let actual = render_reference(bundle, render)?;
    let d = difference(&actual, &expected, t.render_threshold)
        .ok_or_else(|| Error::invalid(&path, "size differs from the render"))?;
    Ok(render_finding(&render.name, &d, t))
}

/// A render's finding from its difference.
pub fn render_finding(name: &str, d: &ImageDifference, t: &Tolerances) -> Finding {
    let outcome = if d.pixels_off == 0 && d.mean == 0.0 {
        Outcome::Unchanged
    } else if d.share_off() <= t.render_pixels_off && d.mean <= t.render_mean {
        Outcome::WithinTolerance
    } else {
        Outcome::Changed
    };
    Finding {
        artifact: format!("render:{name}"),
        outcome,
        figure: format!(
            "{:.2} % of pixels more than {} levels off, mean difference {:.3} levels, PSNR {:.1} dB",
            100.0 * d.share_off(),
            d.threshold,
            d.mean,
            d.psnr_db
        ),
        tolerance: format!(
            "at most {:.2} % of pixels off, mean at most {} levels",
            100.0 * t.render_pixels_off,
            t.render_mean
        ),
        places: Vec::new(),
    }
}
