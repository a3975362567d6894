//! What a check finds: per artifact an outcome, the figure and tolerance
//! it was judged by, and the places of the change. Shared by the check and
//! the reference grids' comparison.

use serde::Serialize;

/// How one artifact (or render) compares with its record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// Byte for byte the recorded file.
    Unchanged,
    /// Changed, every recorded figure within its tolerance.
    WithinTolerance,
    /// Changed beyond a tolerance, or an artifact the record lacks.
    Changed,
    /// Not compared: the user asked to skip it.
    Skipped,
}

/// Where a change is: a block of the grid (or the drape) and its extent in
/// the bundle's CRS.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Place {
    /// Block column and row.
    pub block: [usize; 2],
    /// Grid (or drape) columns `c0..c1`, rows `r0..r1`.
    pub cells: [usize; 4],
    /// West, south, east, north in the bundle's CRS.
    pub bounds: [f64; 4],
    /// The change there (metres, levels or cells; infinite where data
    /// appeared or vanished), by which places are ranked.
    pub change: f64,
    /// What changed there, in words.
    pub what: String,
}

/// One artifact's result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// Manifest key, or `render:NAME`.
    pub artifact: String,
    pub outcome: Outcome,
    /// The figure judged, in words (e.g. "largest block change 5.004 m").
    pub figure: String,
    /// The tolerance it was judged against, in words.
    pub tolerance: String,
    /// The places beyond tolerance (at most [`MOST_PLACES`]), or where the
    /// change within tolerance lies.
    pub places: Vec<Place>,
}

/// Places listed per finding.
pub const MOST_PLACES: usize = 8;
