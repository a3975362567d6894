//! The vegetation database: one object per line, semicolon-separated
//! `id;x;y;class;size;score` (the seed's position-and-type text file,
//! extended with size and score). x, y are world coordinates of the image's
//! CRS (pixel coordinates when the image is not georeferenced); size is the
//! object's diameter on the ground, metres (its pixels times the pixel's
//! size, whatever units x and y are in); score is the classifier's, in
//! [0.5, 1].

use crate::{Error, Result};

pub const HEADER: &str = "id;x;y;class;size;score";

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct VegObject {
    pub id: u64,
    pub x: f64,
    pub y: f64,
    pub class: String,
    pub size: f64,
    pub score: f32,
}

/// Decimals the database keeps of positions and sizes (millimetres in a
/// metric CRS) and of scores.
const LENGTH_DECIMALS: usize = 3;
const SCORE_DECIMALS: usize = 4;

/// The database text, header first.
pub fn to_csv(objects: &[VegObject]) -> String {
    let mut out = String::with_capacity(40 * (objects.len() + 1));
    out.push_str(HEADER);
    out.push('\n');
    for o in objects {
        use std::fmt::Write;
        let (l, s) = (LENGTH_DECIMALS, SCORE_DECIMALS);
        let _ = writeln!(
            out,
            "{};{:.l$};{:.l$};{};{:.l$};{:.s$}",
            o.id, o.x, o.y, o.class, o.size, o.score
        );
    }
    out
}

/// The objects exactly as [`from_csv`] reads them back from [`to_csv`]:
/// positions and sizes rounded to the millimetre, scores to 10⁻⁴. What is
/// baked from a database in memory then matches what is baked from the
/// bundle's file.
pub fn as_stored(objects: &[VegObject]) -> Vec<VegObject> {
    // Written and parsed back, so the value is the stored one bit for bit.
    let stored = |v: f64, decimals: usize| format!("{v:.decimals$}").parse().unwrap_or(v);
    objects
        .iter()
        .map(|o| VegObject {
            x: stored(o.x, LENGTH_DECIMALS),
            y: stored(o.y, LENGTH_DECIMALS),
            size: stored(o.size, LENGTH_DECIMALS),
            score: format!("{:.SCORE_DECIMALS$}", o.score)
                .parse()
                .unwrap_or(o.score),
            ..o.clone()
        })
        .collect()
}

/// Read a database; errors name the line.
pub fn from_csv(text: &str) -> Result<Vec<VegObject>> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    match lines.next() {
        Some((_, header)) if header.trim() == HEADER => {}
        Some((_, header)) => {
            return Err(Error::Input(format!(
                "line 1: header {:?}, expected {HEADER:?}",
                header.trim()
            )))
        }
        None => return Err(Error::Input("empty file".into())),
    }
    lines
        .map(|(number, line)| {
            let fail = |what: &str| Error::Input(format!("line {}: {what}", number + 1));
            let f: Vec<&str> = line.split(';').map(str::trim).collect();
            if f.len() != 6 {
                return Err(fail(&format!("{} fields, expected 6 ({HEADER})", f.len())));
            }
            let number = |k: usize| {
                f[k].parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| fail(&format!("{:?} is not a number", f[k])))
            };
            Ok(VegObject {
                id: f[0]
                    .parse()
                    .map_err(|_| fail(&format!("id {:?} is not an integer", f[0])))?,
                x: number(1)?,
                y: number(2)?,
                class: f[3].to_string(),
                size: number(4)?,
                score: number(5)? as f32,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_errors() {
        let objects = vec![VegObject {
            id: 1,
            x: 291_000.25,
            y: 9_113_000.5,
            class: "forest".into(),
            size: 12.5,
            score: 0.75,
        }];
        assert_eq!(from_csv(&to_csv(&objects)).unwrap(), objects);
        let fine = vec![VegObject {
            x: 291_000.123_456_7,
            y: -0.000_6,
            size: 2.345_678_9,
            score: 0.912_345_6,
            ..objects[0].clone()
        }];
        assert_eq!(as_stored(&fine), from_csv(&to_csv(&fine)).unwrap());
        assert!(from_csv("x;y\n")
            .unwrap_err()
            .to_string()
            .contains("header"));
        let bad = format!("{HEADER}\n1;2;3;tree;4\n");
        assert!(from_csv(&bad)
            .unwrap_err()
            .to_string()
            .contains("line 2: 5 fields"));
    }
}
