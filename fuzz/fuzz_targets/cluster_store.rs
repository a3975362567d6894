//! A clustered bundle one of whose `clusters/` files (index, nodes,
//! objects, frames — chosen by the first byte) is the fuzzer's input:
//! reading, validating and cutting it must end in a value or an error,
//! never a panic, a loop or an abort.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "common/clustered_bundle.rs"]
mod clustered_bundle;
use clustered_bundle::{clustered_bundle, read_and_walk, replace, FILES};

fuzz_target!(|data: &[u8]| {
    let Some((&which, content)) = data.split_first() else {
        return;
    };
    let bundle = clustered_bundle();
    if replace(bundle, FILES[which as usize % FILES.len()], content) {
        read_and_walk(bundle);
    }
});
