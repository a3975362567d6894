//! Accuracy of detections against truth boxes: a detection is a true
//! positive when its centre falls inside a truth box not yet matched, or
//! when its crown box overlaps one by a given intersection over union,
//! taking detections greedily from the highest score. Beside the overall figures:
//! per class (a confusion of detection classes against truth classes, with
//! each class's precision and recall) and the matches as GeoJSON, so a user
//! sees where detection fails.

use crate::veg::db::VegObject;
use crate::veg::samples::Sample;
use crate::{Error, Result};
use serde_json::json;
use std::collections::BTreeMap;

/// A truth box `[xmin, ymin, xmax, ymax]` and its class, when the truth
/// names one (VOC `<name>`, the CSV's fifth column).
#[derive(Debug, Clone, PartialEq)]
pub struct TruthBox {
    pub bounds: [f64; 4],
    pub class: Option<String>,
}

/// The bounds of `truth`, for [`evaluate`].
pub fn bounds(truth: &[TruthBox]) -> Vec<[f64; 4]> {
    truth.iter().map(|t| t.bounds).collect()
}

/// Precision, recall and F1 with the counts behind them.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Evaluation {
    pub detections: usize,
    pub truth: usize,
    pub true_positives: usize,
    pub false_positives: usize,
    pub false_negatives: usize,
    pub precision: f64,
    pub recall: f64,
    pub f1: f64,
}

/// A detection as the evaluation sees it: its centre and crown diameter
/// in the truth boxes' units, and its score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    pub x: f64,
    pub y: f64,
    pub diameter: f64,
    pub score: f32,
}

impl Detection {
    /// The database's objects as detections, their sizes (metres) turned
    /// into the units of x and y, of which there are `metres_per_unit`
    /// metres (1 where x and y are metres; the pixel size where they are
    /// pixels).
    pub fn of_objects(objects: &[VegObject], metres_per_unit: f64) -> Vec<Detection> {
        objects
            .iter()
            .map(|o| Detection {
                x: o.x,
                y: o.y,
                diameter: o.size / metres_per_unit,
                score: o.score,
            })
            .collect()
    }

    /// The crown's box `[xmin, ymin, xmax, ymax]`: a square of its diameter.
    pub fn bounds(&self) -> [f64; 4] {
        let r = self.diameter / 2.0;
        [self.x - r, self.y - r, self.x + r, self.y + r]
    }
}

/// When a detection matches a truth box.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(tag = "by", rename_all = "lowercase")]
pub enum Criterion {
    /// Its centre lies in the box.
    Centre,
    /// Its crown box overlaps the box by at least this intersection over
    /// union (0.4 and 0.5 are the usual thresholds for tree crowns, e.g.
    /// the NeonTreeEvaluation benchmark's 0.4).
    Iou { min: f64 },
}

/// Match `detections` to `[xmin, ymin, xmax, ymax]` boxes under
/// `criterion` and score the result (`matches`, [`Evaluation::of`]).
pub fn evaluate(detections: &[Detection], truth: &[[f64; 4]], criterion: Criterion) -> Evaluation {
    Evaluation::of(&matches(detections, truth, criterion), truth.len())
}

/// Intersection over union of two boxes `[xmin, ymin, xmax, ymax]`.
pub fn iou(a: [f64; 4], b: [f64; 4]) -> f64 {
    let w = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let h = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = w * h;
    let area = |r: [f64; 4]| (r[2] - r[0]) * (r[3] - r[1]);
    let union = area(a) + area(b) - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// For each detection, the truth box it matches. Detections are taken
/// greedily from the highest score; each takes, among the boxes still free
/// that `criterion` accepts, the best: the one whose middle is nearest its
/// centre ([`Criterion::Centre`]), or the largest overlap
/// ([`Criterion::Iou`]).
pub fn matches(
    detections: &[Detection],
    truth: &[[f64; 4]],
    criterion: Criterion,
) -> Vec<Option<usize>> {
    let mut order: Vec<usize> = (0..detections.len()).collect();
    order.sort_by(|&a, &b| {
        detections[b]
            .score
            .total_cmp(&detections[a].score)
            .then(a.cmp(&b))
    });
    let mut matched = vec![false; truth.len()];
    let mut found = vec![None; detections.len()];
    for k in order {
        let d = detections[k];
        // How well box `b` fits (higher is better), `None` when it does not.
        let fit = |b: &[f64; 4]| match criterion {
            Criterion::Centre => {
                (b[0] <= d.x && d.x <= b[2] && b[1] <= d.y && d.y <= b[3]).then(|| {
                    -(((b[0] + b[2]) / 2.0 - d.x).powi(2) + ((b[1] + b[3]) / 2.0 - d.y).powi(2))
                })
            }
            Criterion::Iou { min } => Some(iou(d.bounds(), *b)).filter(|&v| v >= min && v > 0.0),
        };
        let best = truth
            .iter()
            .enumerate()
            .filter(|(t, _)| !matched[*t])
            .filter_map(|(t, b)| fit(b).map(|f| (t, f)))
            .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)));
        if let Some((t, _)) = best {
            matched[t] = true;
            found[k] = Some(t);
        }
    }
    found
}

impl Evaluation {
    /// The figures of `matches` (one per detection) against `truth` boxes.
    pub fn of(matches: &[Option<usize>], truth: usize) -> Evaluation {
        let tp = matches.iter().flatten().count();
        let detections = matches.len();
        let ratio = |a: usize, b: usize| if b == 0 { 0.0 } else { a as f64 / b as f64 };
        let precision = ratio(tp, detections);
        let recall = ratio(tp, truth);
        let f1 = if precision + recall == 0.0 {
            0.0
        } else {
            2.0 * precision * recall / (precision + recall)
        };
        Evaluation {
            detections,
            truth,
            true_positives: tp,
            false_positives: detections - tp,
            false_negatives: truth - tp,
            precision,
            recall,
            f1,
        }
    }
}

/// Per truth box (of `boxes`), whether a detection matched it.
fn boxes_found(matches: &[Option<usize>], boxes: usize) -> Vec<bool> {
    let mut found = vec![false; boxes];
    for &t in matches.iter().flatten() {
        found[t] = true;
    }
    found
}

/// One class's figures: its detections and how many matched a box of any
/// class (precision), its truth boxes and how many were found (recall).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ClassFigures {
    pub class: String,
    pub detections: usize,
    pub matched: usize,
    pub precision: f64,
    pub truth: usize,
    pub found: usize,
    pub recall: f64,
}

/// Per-class figures and the confusion between detection and truth
/// classes: `confusion[detection class][truth class]` counts matches,
/// with "(none)" for a detection that matched no box or a box no detection
/// found. A class named in both is one row (names compared without letter
/// case). A class's precision counts matches to a box of any class.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PerClass {
    pub classes: Vec<ClassFigures>,
    pub confusion: BTreeMap<String, BTreeMap<String, usize>>,
}

/// The name used for a truth box without a class, and for "no match".
pub const NO_CLASS: &str = "(none)";

/// Per-class figures of `matches` between detections of `detection_classes`
/// and `truth` boxes.
pub fn per_class(
    detection_classes: &[&str],
    truth: &[TruthBox],
    matches: &[Option<usize>],
) -> PerClass {
    let truth_class = |t: usize| truth[t].class.as_deref().unwrap_or(NO_CLASS);
    let mut confusion: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    let found = boxes_found(matches, truth.len());
    for (&class, m) in detection_classes.iter().zip(matches) {
        let to = m.map_or(NO_CLASS, truth_class);
        *confusion
            .entry(class.into())
            .or_default()
            .entry(to.into())
            .or_default() += 1;
    }
    for t in (0..truth.len()).filter(|&t| !found[t]) {
        *confusion
            .entry(NO_CLASS.into())
            .or_default()
            .entry(truth_class(t).into())
            .or_default() += 1;
    }
    // One row per class name, letter case aside ("alive" samples, "Alive"
    // truth), spelt as the truth spells it.
    let mut names: BTreeMap<String, &str> = BTreeMap::new();
    for name in detection_classes.iter().copied() {
        names.entry(name.to_lowercase()).or_insert(name);
    }
    for name in (0..truth.len()).map(truth_class) {
        names.insert(name.to_lowercase(), name);
    }
    let same = |a: &str, b: &str| a.to_lowercase() == b.to_lowercase();
    let ratio = |a: usize, b: usize| if b == 0 { 0.0 } else { a as f64 / b as f64 };
    let classes = names
        .into_values()
        .map(|class| {
            let mine: Vec<&Option<usize>> = detection_classes
                .iter()
                .zip(matches)
                .filter(|(c, _)| same(c, class))
                .map(|(_, m)| m)
                .collect();
            let matched = mine.iter().filter(|m| m.is_some()).count();
            let boxes: Vec<usize> = (0..truth.len())
                .filter(|&t| same(truth_class(t), class))
                .collect();
            let hit = boxes.iter().filter(|&&t| found[t]).count();
            ClassFigures {
                class: class.into(),
                detections: mine.len(),
                matched,
                precision: ratio(matched, mine.len()),
                truth: boxes.len(),
                found: hit,
                recall: ratio(hit, boxes.len()),
            }
        })
        .collect();
    PerClass { classes, confusion }
}

/// The matches as a GeoJSON FeatureCollection, in the coordinates of the
/// inputs (pixels, y down, for VOC truth): each detection a Point with its
/// class, score and the truth class it matched (null: a false positive);
/// each truth box a Polygon with its class and whether it was found (false:
/// a miss).
pub fn matches_geojson(
    objects: &[VegObject],
    truth: &[TruthBox],
    matches: &[Option<usize>],
) -> String {
    let found = boxes_found(matches, truth.len());
    let mut features = Vec::with_capacity(objects.len() + truth.len());
    for (o, m) in objects.iter().zip(matches) {
        features.push(json!({
            "type": "Feature",
            "properties": {"kind": "detection", "id": o.id, "class": o.class, "score": o.score,
                           "matched": m.is_some(),
                           "truth_class": m.map(|t| truth[t].class.clone().unwrap_or_else(|| NO_CLASS.into()))},
            "geometry": {"type": "Point", "coordinates": [o.x, o.y]},
        }));
    }
    for (t, b) in truth.iter().enumerate() {
        let [x0, y0, x1, y1] = b.bounds;
        features.push(json!({
            "type": "Feature",
            "properties": {"kind": "truth", "class": b.class, "found": found[t]},
            "geometry": {"type": "Polygon",
                         "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]},
        }));
    }
    json!({"type": "FeatureCollection", "features": features}).to_string()
}

/// How the pixels of one land-cover class were classified: labelled pixels
/// (centres inside its polygons), how many fell in vegetation regions, and
/// how many in each extraction class.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LandCoverFigures {
    pub class: String,
    pub pixels: usize,
    pub vegetation: usize,
    /// `vegetation / pixels`.
    pub vegetation_share: f64,
    pub by_class: BTreeMap<String, usize>,
}

/// Score a classification against land-cover labels, per land-cover class.
/// `labels` are polygons in pixel coordinates of a `width`×`height` image
/// (a point label is a one-pixel square); `pixel(i)` is the extraction's
/// class of pixel `i` and whether it is vegetation, `None` without data.
pub fn land_cover<'a>(
    labels: &[Sample],
    width: usize,
    height: usize,
    pixel: impl Fn(usize) -> Option<(&'a str, bool)>,
) -> Vec<LandCoverFigures> {
    let mut figures: BTreeMap<&str, LandCoverFigures> = BTreeMap::new();
    for label in labels {
        let entry = figures
            .entry(label.class.as_str())
            .or_insert_with(|| LandCoverFigures {
                class: label.class.clone(),
                pixels: 0,
                vegetation: 0,
                vegetation_share: 0.0,
                by_class: BTreeMap::new(),
            });
        let [x0, y0, x1, y1] = label.bounds();
        let clamp = |v: f64, n: usize| v.floor().clamp(0.0, n as f64) as usize;
        let (c0, c1) = (clamp(x0, width), clamp(x1 + 1.0, width));
        let (r0, r1) = (clamp(y0, height), clamp(y1 + 1.0, height));
        for r in r0..r1 {
            for c in c0..c1 {
                if !label.contains(c as f64 + 0.5, r as f64 + 0.5) {
                    continue;
                }
                let Some((class, vegetation)) = pixel(r * width + c) else {
                    continue;
                };
                entry.pixels += 1;
                entry.vegetation += usize::from(vegetation);
                *entry.by_class.entry(class.to_string()).or_default() += 1;
            }
        }
    }
    figures
        .into_values()
        .map(|mut f| {
            f.vegetation_share = if f.pixels == 0 {
                0.0
            } else {
                f.vegetation as f64 / f.pixels as f64
            };
            f
        })
        .collect()
}

/// Truth boxes from Pascal VOC XML (`text` starting with `<`) or CSV
/// lines `xmin,ymin,xmax,ymax[,class]`.
pub fn parse_truth(text: &str) -> Result<Vec<TruthBox>> {
    if text.trim_start().starts_with('<') {
        parse_voc(text)
    } else {
        parse_box_csv(text)
    }
}

/// Boxes of a Pascal VOC annotation (`<object><bndbox><xmin>…`).
pub fn parse_voc(text: &str) -> Result<Vec<TruthBox>> {
    let doc =
        roxmltree::Document::parse(text).map_err(|e| Error::Input(format!("not XML: {e}")))?;
    let mut boxes = Vec::new();
    for (k, bndbox) in doc
        .descendants()
        .filter(|n| n.has_tag_name("bndbox"))
        .enumerate()
    {
        let mut b = [0.0; 4];
        for (slot, name) in b.iter_mut().zip(["xmin", "ymin", "xmax", "ymax"]) {
            *slot = bndbox
                .children()
                .find(|n| n.has_tag_name(name))
                .and_then(|n| n.text())
                .and_then(|t| t.trim().parse::<f64>().ok())
                .ok_or_else(|| Error::Input(format!("object {}: no numeric <{name}>", k + 1)))?;
        }
        // The class: the <name> of the <object> holding the box.
        let class = bndbox
            .parent()
            .and_then(|o| o.children().find(|n| n.has_tag_name("name")))
            .and_then(|n| n.text())
            .map(|t| t.trim().to_string())
            .filter(|t| !t.is_empty());
        boxes.push(TruthBox { bounds: b, class });
    }
    if boxes.is_empty() {
        return Err(Error::Input("no <bndbox> in the annotation".into()));
    }
    Ok(boxes)
}

/// Boxes from `xmin,ymin,xmax,ymax[,class]` lines (an optional header is
/// skipped).
pub fn parse_box_csv(text: &str) -> Result<Vec<TruthBox>> {
    let mut boxes = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') || (number == 0 && line.starts_with("xmin")) {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let (numbers, class) = match fields.len() {
            5 if !fields[4].is_empty() => (&fields[..4], Some(fields[4].to_string())),
            _ => (&fields[..], None),
        };
        let values: Vec<f64> = numbers
            .iter()
            .map(|v| v.parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| Error::Input(format!("line {}: not four numbers", number + 1)))?;
        match values[..] {
            [a, b, c, d] if a <= c && b <= d => boxes.push(TruthBox {
                bounds: [a, b, c, d],
                class,
            }),
            _ => {
                return Err(Error::Input(format!(
                    "line {}: expected xmin,ymin,xmax,ymax with min ≤ max",
                    number + 1
                )))
            }
        }
    }
    if boxes.is_empty() {
        return Err(Error::Input("no boxes".into()));
    }
    Ok(boxes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn greedy_matching_by_score() {
        let truth = [[0.0, 0.0, 10.0, 10.0], [20.0, 0.0, 30.0, 10.0]];
        // Two detections in the first box: the better one matches, the other
        // is a false positive; the second box is missed.
        let e = evaluate(
            &[(5.0, 5.0, 0.6), (4.0, 4.0, 0.9), (50.0, 50.0, 1.0)].map(|(x, y, score)| Detection {
                x,
                y,
                diameter: 10.0,
                score,
            }),
            &truth,
            Criterion::Centre,
        );
        assert_eq!(
            (e.true_positives, e.false_positives, e.false_negatives),
            (1, 2, 1)
        );
        assert!((e.precision - 1.0 / 3.0).abs() < 1e-12 && (e.recall - 0.5).abs() < 1e-12);
        assert!((e.f1 - 0.4).abs() < 1e-12);
        assert_eq!(evaluate(&[], &truth, Criterion::Centre).f1, 0.0);
    }

    #[test]
    fn iou_matching_takes_the_best_overlap_above_the_threshold() {
        assert!((iou([0.0, 0.0, 2.0, 2.0], [1.0, 0.0, 3.0, 2.0]) - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(iou([0.0, 0.0, 1.0, 1.0], [2.0, 2.0, 3.0, 3.0]), 0.0);
        let truth = [[0.0, 0.0, 10.0, 10.0], [8.0, 0.0, 18.0, 10.0]];
        let at = |x: f64, diameter: f64, score: f32| Detection {
            x,
            y: 5.0,
            diameter,
            score,
        };
        // The best detection overlaps the second box most (IoU 0.82 vs
        // 0.18); the next takes the first box (0.73); a crown far too small
        // for its box (0.04) matches nothing, though by centre it would.
        let d = [at(12.0, 10.0, 0.9), at(4.0, 9.0, 0.8), at(15.0, 2.0, 0.5)];
        assert_eq!(
            matches(&d, &truth, Criterion::Iou { min: 0.4 }),
            [Some(1), Some(0), None]
        );
        let tiny = [at(5.0, 2.0, 0.5)];
        assert_eq!(matches(&tiny, &truth, Criterion::Iou { min: 0.4 }), [None]);
        assert_eq!(matches(&tiny, &truth, Criterion::Centre), [Some(0)]);
        let f = evaluate(&d, &truth, Criterion::Iou { min: 0.5 });
        assert_eq!((f.true_positives, f.false_positives), (2, 1));
    }

    #[test]
    fn per_class_figures_and_confusion() {
        let truth = [
            ([0.0, 0.0, 10.0, 10.0], "Alive"),
            ([20.0, 0.0, 30.0, 10.0], "Dead"),
            ([40.0, 0.0, 50.0, 10.0], "Alive"),
        ]
        .map(|(bounds, class)| TruthBox {
            bounds,
            class: Some(class.into()),
        });
        let detections = [(5.0, 0.9), (60.0, 0.8), (25.0, 0.7)].map(|(x, score)| Detection {
            x,
            y: 5.0,
            diameter: 8.0,
            score,
        });
        let m = matches(&detections, &bounds(&truth), Criterion::Centre);
        assert_eq!(m, vec![Some(0), None, Some(1)]);
        let p = per_class(&["tree", "tree", "dead"], &truth, &m);
        let figures = |c: &str| p.classes.iter().find(|f| f.class == c).unwrap().clone();
        assert_eq!((figures("Alive").truth, figures("Alive").found), (2, 1));
        assert_eq!((figures("Dead").truth, figures("Dead").found), (1, 1));
        assert_eq!(
            (figures("tree").detections, figures("tree").matched),
            (2, 1)
        );
        // "dead" detections and "Dead" boxes are one class.
        assert_eq!(
            (figures("Dead").detections, figures("Dead").precision),
            (1, 1.0)
        );
        assert_eq!(p.classes.len(), 3);
        assert_eq!(p.confusion["tree"]["Alive"], 1);
        assert_eq!(p.confusion["tree"][NO_CLASS], 1);
        assert_eq!(p.confusion["dead"]["Dead"], 1);
        assert_eq!(p.confusion[NO_CLASS]["Alive"], 1);
        let objects: Vec<VegObject> = detections
            .iter()
            .enumerate()
            .map(|(k, d)| VegObject {
                id: k as u64,
                x: d.x,
                y: d.y,
                class: "tree".into(),
                size: 1.0,
                score: d.score,
            })
            .collect();
        let geojson: serde_json::Value =
            serde_json::from_str(&matches_geojson(&objects, &truth, &m)).unwrap();
        let features = geojson["features"].as_array().unwrap();
        assert_eq!(features.len(), 6);
        assert_eq!(features[1]["properties"]["matched"], false);
        assert_eq!(features[5]["properties"]["found"], false);
    }

    #[test]
    fn land_cover_counts_pixels_inside_each_label() {
        // A 10×10 image: the left half forest (vegetation), the right water.
        let square = |class: &str, x0: f64, x1: f64| Sample {
            class: class.into(),
            polygon: vec![[x0, 0.0], [x1, 0.0], [x1, 10.0], [x0, 10.0]],
        };
        let labels = [square("tree", 0.0, 4.0), square("water", 4.0, 10.0)];
        let classes = ["forest", "water"];
        let f = land_cover(&labels, 10, 10, |i| {
            let forest = i % 10 < 5;
            Some((classes[usize::from(!forest)], forest))
        });
        assert_eq!(
            (f[0].class.as_str(), f[0].pixels, f[0].vegetation),
            ("tree", 40, 40)
        );
        assert_eq!(
            (f[1].class.as_str(), f[1].pixels, f[1].vegetation),
            ("water", 60, 10)
        );
        assert_eq!(f[1].by_class["water"], 50);
        assert!((f[1].vegetation_share - 1.0 / 6.0).abs() < 1e-12);
    }

    #[test]
    fn truth_formats() {
        let voc = "<annotation><object><name>Tree</name><bndbox><xmin>1</xmin><ymin>2</ymin>\
                   <xmax>3</xmax><ymax>4</ymax></bndbox></object></annotation>";
        assert_eq!(
            parse_voc(voc).unwrap(),
            vec![TruthBox {
                bounds: [1.0, 2.0, 3.0, 4.0],
                class: Some("Tree".into())
            }]
        );
        assert_eq!(
            parse_box_csv("1,2,3,4,Dead\n").unwrap()[0].class.as_deref(),
            Some("Dead")
        );
        assert!(parse_voc("<a/>").is_err());
        assert!(parse_voc("<a").is_err());
        assert_eq!(
            parse_box_csv("xmin,ymin,xmax,ymax\n1,2,3,4\n")
                .unwrap()
                .len(),
            1
        );
        assert!(parse_box_csv("1,2,3\n").is_err());
        assert!(parse_box_csv("3,2,1,4\n").is_err());
    }
}
