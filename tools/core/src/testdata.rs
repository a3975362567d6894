//! Real inputs for the unit tests: small crops of real DEMs and one NEON
//! image, committed under `data/crops/` (provenance in its README), so
//! `cargo test -p relevo-core` needs nothing else.

use crate::veg::Image;
use std::path::PathBuf;

/// A real heightfield crop: heights (metres, row-major), side and the
/// nominal vertex spacing the tests use.
pub struct Dem {
    pub name: &'static str,
    pub heights: Vec<f32>,
    pub side: usize,
    pub cell_size_m: f64,
}

/// `data/crops/NAME` of the repository.
pub fn path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/crops")
        .join(name)
}

/// The four 257² DEM crops: SRTM (eastern Turkey), Copernicus (Grenoble),
/// Gironde (coast and sea floor) and Mount Fuji (Terrain-RGB).
pub fn dems() -> Vec<Dem> {
    [
        ("srtm_ref_257.f32", 90.0),
        ("copernicus_grenoble_257.f32", 150.0),
        ("gironde_257.f32", 100.0),
        ("fuji_257.f32", 30.0),
    ]
    .into_iter()
    .map(|(name, cell_size_m)| {
        let bytes = std::fs::read(path(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        let heights: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        assert_eq!(heights.len(), 257 * 257, "{name}");
        Dem {
            name,
            heights,
            side: 257,
            cell_size_m,
        }
    })
    .collect()
}

/// One DEM crop by file name.
pub fn dem(name: &str) -> Dem {
    dems()
        .into_iter()
        .find(|d| d.name == name)
        .unwrap_or_else(|| panic!("no crop {name}"))
}

/// `SOAP_061.png` (NEON RGB, 400², 0.1 m) as an 8-bit three-band image.
pub fn soap_061() -> Image {
    let bytes = std::fs::read(path("SOAP_061.png")).unwrap();
    let (rgba, w, h) = crate::raster::png::decode_rgba(&bytes).unwrap();
    let rgb: Vec<u8> = rgba
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    Image::new(w, h, 3, rgb).unwrap()
}

/// SOAP_061 as the vegetation pipeline takes it (0.1 m pixels, not
/// georeferenced), with its ten committed samples.
pub fn soap_061_marked() -> (
    crate::veg::pipeline::VegImage,
    Vec<crate::veg::samples::Sample>,
) {
    let image = crate::veg::pipeline::VegImage {
        image: soap_061(),
        crs_wkt: String::new(),
        geotransform: None,
        pixel_m: 0.1,
        valid: None,
    };
    let marks =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/trees/soap_061_samples.csv");
    let samples = crate::veg::samples::read_file(&marks, None, 400, 400).unwrap();
    (image, samples)
}

/// A deterministic pseudo-random sequence in [0, 1).
pub struct Lcg(pub u64);

impl Lcg {
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}
