//! Vegetation samples, as the CSV of pixel rectangles and as GeoJSON
//! polygons, for a 1000×800 image.
#![no_main]

use libfuzzer_sys::fuzz_target;
use relevo_core::veg::samples::{parse_csv, parse_geojson};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let _ = parse_csv(text, 1000, 800);
    let _ = parse_geojson(text, |x, y| Some([x, y]), 1000, 800);
});
