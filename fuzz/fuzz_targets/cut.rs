//! A clustered bundle whose quadtree is the fuzzer's input — a node count
//! (4 bytes), that many node records, then object records — with the
//! index's counts made to match, so that every input reaches the structure
//! checks and, where they pass, the cut's walk over the tree.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "common/clustered_bundle.rs"]
mod clustered_bundle;
use clustered_bundle::{clustered_bundle, read_and_walk, replace};

/// Bytes of one node and one object record.
const NODE_BYTES: usize = 68;
const OBJECT_BYTES: usize = 28;

fuzz_target!(|data: &[u8]| {
    let Some((count, records)) = data.split_first_chunk::<4>() else {
        return;
    };
    let nodes = (u32::from_le_bytes(*count) as usize).min(records.len() / NODE_BYTES);
    let (node_bytes, rest) = records.split_at(nodes * NODE_BYTES);
    let objects = rest.len() / OBJECT_BYTES;
    let bundle = clustered_bundle();
    let index = &bundle.original[0].1;
    let Ok(mut index) = serde_json::from_slice::<serde_json::Value>(index) else {
        return;
    };
    index["nodes"] = nodes.into();
    index["objects"] = objects.into();
    let Ok(index) = serde_json::to_vec(&index) else {
        return;
    };
    if replace(bundle, "clusters/nodes.bin", node_bytes)
        && std::fs::write(bundle.path.join("clusters/objects.bin"), &rest[..objects * OBJECT_BYTES]).is_ok()
        && std::fs::write(bundle.path.join("clusters/index.json"), index).is_ok()
    {
        read_and_walk(bundle);
    }
});
