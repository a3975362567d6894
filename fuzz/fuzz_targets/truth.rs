//! Ground-truth boxes for `veg eval`: Pascal VOC XML and box CSV, then
//! matched against a few detections by centre and by crown-box overlap.
#![no_main]

use libfuzzer_sys::fuzz_target;
use relevo_core::veg::db::VegObject;
use relevo_core::veg::eval::{
    bounds, matches, matches_geojson, parse_truth, per_class, Criterion, Detection, Evaluation,
};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let detections = [(10.0, 10.0, 0.9), (50.0, 40.0, 0.5), (200.0, 120.0, 0.1)];
    let objects: Vec<VegObject> = detections
        .iter()
        .enumerate()
        .map(|(k, &(x, y, score))| VegObject {
            id: k as u64,
            x,
            y,
            class: ["Alive", "Dead", "tree"][k].into(),
            size: 3.0,
            score,
        })
        .collect();
    let crowns = Detection::of_objects(&objects, 0.1);
    if let Ok(truth) = parse_truth(text) {
        for criterion in [Criterion::Centre, Criterion::Iou { min: 0.4 }] {
            let found = matches(&crowns, &bounds(&truth), criterion);
            let _ = Evaluation::of(&found, truth.len());
            let _ = per_class(&["Alive", "Dead", "tree"], &truth, &found);
            let _ = matches_geojson(&objects, &truth, &found);
        }
    }
});
