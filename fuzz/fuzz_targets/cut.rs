//! A quadtree that is the fuzzer's input — a node count (4 bytes), that
//! many node records, then object records — with the index's counts made
//! to match, so that every input reaches the structure checks and, where
//! they pass, the cut's walk over the tree from several cameras.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "common/clustered_bundle.rs"]
mod clustered_bundle;
use clustered_bundle::{clustered_bundle, open_and_walk};

/// Bytes of one node record.
const NODE_BYTES: usize = 68;

fuzz_target!(|data: &[u8]| {
    let Some((count, records)) = data.split_first_chunk::<4>() else {
        return;
    };
    let nodes = (u32::from_le_bytes(*count) as usize).min(records.len() / NODE_BYTES);
    let (nodes, objects) = records.split_at(nodes * NODE_BYTES);
    let objects = &objects[..objects.len() / 28 * 28];
    let bundle = clustered_bundle();
    open_and_walk([&bundle.files[0], nodes, objects, &bundle.files[3]], true);
});
