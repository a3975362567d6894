//! A whole bundle checked as its readers rely on it: the terrain, drape and
//! vegetation artifacts ([`bundle::validate_artifacts`]) or a pyramid's
//! tiles ([`pyramid::reader::validate`]), and the vegetation clusters
//! ([`cluster::store::validate`]). It sits above them so that neither
//! bundle format knows anything of the clusters stored in it.

use crate::bundle::{self, Bundle};
use crate::cluster;
use crate::pyramid::{self, Pyramid};

/// Every problem `relevo validate` reports, one line each; empty means valid.
pub fn validate(bundle: &Bundle) -> Vec<String> {
    let mut problems = bundle::validate_artifacts(bundle);
    problems.extend(cluster::store::validate(bundle));
    problems
}

/// Every problem `relevo validate` reports in a pyramid, one line each:
/// its tiles (their hashes too when `hashes`), then its clusters.
pub fn validate_pyramid(p: &Pyramid, hashes: bool) -> Vec<String> {
    let mut problems = pyramid::reader::validate(p, hashes);
    problems.extend(cluster::store::validate(p));
    problems
}
