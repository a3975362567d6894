//! Regression-testing a region's outputs: a bundle against a golden record
//! a user commits (`relevo check`), and two bundles against each other
//! (`relevo diff`).
//!
//! - [`record`]: the golden record — per artifact its hash and summaries,
//!   the tolerances, reference renders — and reading and writing it.
//! - [`reference`](mod@reference): grids kept beside the record as PNGs, compared vertex
//!   by vertex.
//! - [`blocks`]: grids summarised by blocks (hash and statistics), one text
//!   line per row of blocks.
//! - [`vegetation`]: the database summarised by class and block, and two
//!   databases matched object to object.
//! - [`finding`]: what a check finds per artifact: outcome, figure,
//!   tolerance, places.
//! - [`check`](mod@check): a bundle judged against a record, with places.
//! - [`diff`]: two bundles compared cell by cell and object by object, and
//!   pictures of what changed.

pub mod blocks;
pub mod check;
pub mod diff;
pub mod finding;
pub mod record;
pub mod reference;
pub mod vegetation;

pub use check::{check, CheckOptions, CheckReport};
pub use finding::{Finding, Outcome, Place};
pub use record::{GoldenRecord, RenderRecord, Tolerances};
