//! REGION.toml, parsed and checked as `relevo prep` does.
#![no_main]

use libfuzzer_sys::fuzz_target;
use relevo::prep::region::RegionSpec;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let _ = RegionSpec::parse(text, Path::new("/nonexistent/region"));
});
