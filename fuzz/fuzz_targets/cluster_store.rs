//! Cluster files one of which (index, nodes, objects or frames, chosen by
//! the first byte) is the fuzzer's input, opened as `store::read` opens
//! them: parsing, the structure checks and, where they pass, the atlas
//! checks and the cut from several cameras must end in a value or an
//! error, never a panic, a loop or an abort.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "common/clustered_bundle.rs"]
mod clustered_bundle;
use clustered_bundle::{clustered_bundle, open_and_walk};

fuzz_target!(|data: &[u8]| {
    let Some((&which, content)) = data.split_first() else {
        return;
    };
    let original = &clustered_bundle().files;
    let mut files: [&[u8]; 4] = std::array::from_fn(|i| original[i].as_slice());
    files[which as usize % 4] = content;
    open_and_walk(files, false);
});
