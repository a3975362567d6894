//! The vegetation protocol's figures as a regression floor: leave one
//! annotated crop out, choose the options on the others, score the one left
//! out (F1 at IoU 0.4), beside the defaults and the excess-green +
//! local-maximum baseline; and the simulated user's correction loop, whose
//! marks detection must never contradict; and the defaults with marks
//! drawn at random from the truth. The figures are those
//! `relevo-bench veg-protocol` reports (docs/benchmarks.md#vegetation).
// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{repo, shared};
use relevo_core::veg::pipeline::VegOptions;
use relevo_core::veg::protocol;

/// F1 at IoU 0.4 a recorded figure may fall by before the test fails.
const SLACK: f64 = 0.02;

/// Per held-out crop: F1 at IoU 0.4 with the options chosen on the
/// others, with the defaults, and of the baseline (recorded).
const LEAVE_ONE_OUT_F1: [(&str, f64, f64, f64); 3] = [
    ("yellowstone", 0.298, 0.483, 0.124),
    ("soap_061", 0.436, 0.464, 0.036),
    ("yellowstone_meadow", 0.262, 0.262, 0.046),
];

/// Per crop: F1 at IoU 0.4 after the first detection and after rounds 1
/// and 2 of the simulated user (recorded).
const CORRECTION_F1: [(&str, [f64; 3]); 3] = [
    ("yellowstone", [0.483, 0.490, 0.481]),
    ("soap_061", [0.464, 0.606, 0.585]),
    ("yellowstone_meadow", [0.262, 0.300, 0.187]),
];

/// Per crop: the mean F1 at IoU 0.4 of the defaults over the sets of marks
/// drawn at random from the truth (recorded).
const DRAWN_MARKS_F1: [(&str, f64); 3] = [
    ("yellowstone", 0.437),
    ("soap_061", 0.421),
    ("yellowstone_meadow", 0.215),
];

fn crops() -> Vec<protocol::Annotated> {
    let data = shared("trees").parent().unwrap().to_path_buf();
    relevo::veg_io::annotated_crops(&repo(""), &data).unwrap()
}

#[test]
fn leave_one_out_figures_hold() {
    let crops = crops();
    let held_out = protocol::leave_one_out(&crops, &protocol::grid()).unwrap();
    for ((name, chosen, defaults, baseline), h) in LEAVE_ONE_OUT_F1.iter().zip(&held_out) {
        assert_eq!(h.image, *name);
        for (what, got, recorded) in [
            ("chosen on the others", h.chosen.iou_0_4.f1, chosen),
            ("defaults", h.defaults.iou_0_4.f1, defaults),
            ("baseline", h.baseline.iou_0_4.f1, baseline),
        ] {
            eprintln!("{name}: {what} F1 {got:.3} (recorded {recorded:.3})");
            assert!(
                got >= recorded - SLACK,
                "{name}: {what} F1 {got:.3} fell below the recorded {recorded:.3}"
            );
        }
        // The stricter overlap never scores higher.
        assert!(h.chosen.iou_0_5.f1 <= h.chosen.iou_0_4.f1);
    }
}

#[test]
fn the_correction_loop_never_contradicts_the_marks() {
    for ((name, recorded), crop) in CORRECTION_F1.iter().zip(crops()) {
        assert_eq!(crop.name, *name);
        let rounds = protocol::correction_loop(&crop, &VegOptions::default(), 2).unwrap();
        assert_eq!(rounds.len(), 3, "{name}: a round added no mark");
        for (round, recorded) in rounds.iter().zip(recorded) {
            let f1 = round.scores.iou_0_4.f1;
            eprintln!(
                "{name} round {}: {} marks ({} added), F1 {f1:.3} (recorded {recorded:.3})",
                round.round,
                round.marks,
                round.added.len()
            );
            assert_eq!(round.marks_contradicted, 0, "{name} round {}", round.round);
            assert!(round.added.len() <= protocol::MARKS_PER_ROUND);
            assert!(
                f1 >= recorded - SLACK,
                "{name} round {}: F1 {f1:.3} fell below the recorded {recorded:.3}",
                round.round
            );
        }
    }
}

#[test]
fn figures_with_marks_drawn_from_the_truth_hold() {
    let defaults = VegOptions::default();
    for ((name, recorded), crop) in DRAWN_MARKS_F1.iter().zip(crops()) {
        assert_eq!(crop.name, *name);
        for seed in 0..protocol::DRAWN_SETS {
            let marks = protocol::drawn_marks(&crop, seed, &defaults.negative_class);
            let others = marks
                .iter()
                .filter(|m| m.class == defaults.negative_class)
                .count();
            assert_eq!(
                (marks.len() - others, others),
                (protocol::DRAWN_OF_EACH, protocol::DRAWN_OF_EACH),
                "{name} set {seed}"
            );
        }
        let sets = protocol::with_drawn_marks(&crop, &defaults).unwrap();
        assert_eq!(sets.len() as u64, protocol::DRAWN_SETS);
        let mean = sets.iter().map(|s| s.iou_0_4.f1).sum::<f64>() / sets.len() as f64;
        eprintln!("{name}: drawn marks, mean F1 {mean:.3} (recorded {recorded:.3})");
        assert!(
            mean >= recorded - SLACK,
            "{name}: drawn marks' mean F1 {mean:.3} fell below the recorded {recorded:.3}"
        );
    }
}
