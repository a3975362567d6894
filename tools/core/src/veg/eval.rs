//! Accuracy of detections against truth boxes: a detection is a true
//! positive when its centre falls inside a truth box not yet matched, taking
//! detections greedily from the highest score.

use crate::{Error, Result};

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

/// Match `(x, y, score)` detections to `[xmin, ymin, xmax, ymax]` boxes.
/// Among the free boxes holding a centre, the one whose middle is nearest wins.
pub fn evaluate(detections: &[(f64, f64, f32)], truth: &[[f64; 4]]) -> Evaluation {
    let mut order: Vec<usize> = (0..detections.len()).collect();
    order.sort_by(|&a, &b| detections[b].2.total_cmp(&detections[a].2).then(a.cmp(&b)));
    let mut matched = vec![false; truth.len()];
    let mut tp = 0;
    for k in order {
        let (x, y, _) = detections[k];
        let best = truth
            .iter()
            .enumerate()
            .filter(|(t, b)| !matched[*t] && b[0] <= x && x <= b[2] && b[1] <= y && y <= b[3])
            .min_by(|(_, a), (_, b)| {
                let d = |b: &[f64; 4]| {
                    ((b[0] + b[2]) / 2.0 - x).powi(2) + ((b[1] + b[3]) / 2.0 - y).powi(2)
                };
                d(a).total_cmp(&d(b))
            });
        if let Some((t, _)) = best {
            matched[t] = true;
            tp += 1;
        }
    }
    let ratio = |a: usize, b: usize| if b == 0 { 0.0 } else { a as f64 / b as f64 };
    let precision = ratio(tp, detections.len());
    let recall = ratio(tp, truth.len());
    let f1 = if precision + recall == 0.0 {
        0.0
    } else {
        2.0 * precision * recall / (precision + recall)
    };
    Evaluation {
        detections: detections.len(),
        truth: truth.len(),
        true_positives: tp,
        false_positives: detections.len() - tp,
        false_negatives: truth.len() - tp,
        precision,
        recall,
        f1,
    }
}

/// Boxes of a Pascal VOC annotation (`<object><bndbox><xmin>…`).
pub fn parse_voc(text: &str) -> Result<Vec<[f64; 4]>> {
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
        boxes.push(b);
    }
    if boxes.is_empty() {
        return Err(Error::Input("no <bndbox> in the annotation".into()));
    }
    Ok(boxes)
}

/// Boxes from `xmin,ymin,xmax,ymax` lines (an optional header is skipped).
pub fn parse_box_csv(text: &str) -> Result<Vec<[f64; 4]>> {
    let mut boxes = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') || (number == 0 && line.starts_with("xmin")) {
            continue;
        }
        let values: Vec<f64> = line
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| Error::Input(format!("line {}: not four numbers", number + 1)))?;
        match values[..] {
            [a, b, c, d] if a <= c && b <= d => boxes.push([a, b, c, d]),
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
            &[(5.0, 5.0, 0.6), (4.0, 4.0, 0.9), (50.0, 50.0, 1.0)],
            &truth,
        );
        assert_eq!(
            (e.true_positives, e.false_positives, e.false_negatives),
            (1, 2, 1)
        );
        assert!((e.precision - 1.0 / 3.0).abs() < 1e-12 && (e.recall - 0.5).abs() < 1e-12);
        assert!((e.f1 - 0.4).abs() < 1e-12);
        assert_eq!(evaluate(&[], &truth).f1, 0.0);
    }

    #[test]
    fn truth_formats() {
        let voc = "<annotation><object><name>Tree</name><bndbox><xmin>1</xmin><ymin>2</ymin>\
                   <xmax>3</xmax><ymax>4</ymax></bndbox></object></annotation>";
        assert_eq!(parse_voc(voc).unwrap(), vec![[1.0, 2.0, 3.0, 4.0]]);
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
