//! A whole bundle checked as its readers rely on it: the terrain, drape and
//! vegetation artifacts ([`bundle::validate_artifacts`]) and the vegetation
//! clusters ([`cluster::store::validate`]). It sits above both so that the
//! bundle format knows nothing of the clusters stored in it.

use crate::bundle::{self, Bundle};
use crate::cluster;

/// Every problem `relevo validate` reports, one line each; empty means valid.
pub fn validate(bundle: &Bundle) -> Vec<String> {
    let mut problems = bundle::validate_artifacts(bundle);
    problems.extend(cluster::store::validate(bundle));
    problems
}
