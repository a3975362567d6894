//! Samples a user marks on the image: rectangles in a semicolon CSV
//! (`class;xmin;ymin;xmax;ymax`, pixel coordinates) or GeoJSON polygons with
//! a `class` property (coordinates in the image CRS).

use super::Image;
use crate::geo::GeoTransform;
use crate::{Error, Result};
use std::path::Path;

/// One marked sample: a class and a polygon in pixel coordinates (x right,
/// y down; pixel `i` spans `[i, i+1)`).
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    pub class: String,
    pub polygon: Vec<[f64; 2]>,
}

impl Sample {
    /// The rectangle `[x0, y0, x1, y1]` (pixels) as a sample of `class`.
    pub fn rectangle(class: &str, [x0, y0, x1, y1]: [f64; 4]) -> Sample {
        Sample {
            class: class.to_string(),
            polygon: vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]],
        }
    }

    /// The same sample moved by `(dx, dy)` pixels.
    pub fn translated(&self, dx: f64, dy: f64) -> Sample {
        Sample {
            class: self.class.clone(),
            polygon: self
                .polygon
                .iter()
                .map(|p| [p[0] + dx, p[1] + dy])
                .collect(),
        }
    }

    /// Centre of the polygon's bounding box.
    pub fn centre(&self) -> [f64; 2] {
        let [x0, y0, x1, y1] = self.bounds();
        [(x0 + x1) / 2.0, (y0 + y1) / 2.0]
    }

    /// Bounding box `[x0, y0, x1, y1]` of the polygon, in pixels.
    pub fn bounds(&self) -> [f64; 4] {
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for p in &self.polygon {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        [lo[0], lo[1], hi[0], hi[1]]
    }

    /// The whole pixels `[x0, y0, x1, y1)` of `width`×`height` that the
    /// bounding box touches.
    pub fn pixel_bounds(&self, width: usize, height: usize) -> [usize; 4] {
        let [x0, y0, x1, y1] = self.bounds();
        let lo = |v: f64, n: usize| (v.floor().max(0.0) as usize).min(n);
        let hi = |v: f64, n: usize| (v.ceil().max(0.0) as usize).min(n);
        [lo(x0, width), lo(y0, height), hi(x1, width), hi(y1, height)]
    }

    /// Standard deviation of brightness (the mean of the bands, 8-bit
    /// units) over the pixels whose centre lies inside; `None` below two.
    pub fn brightness_std(&self, image: &Image) -> Option<f32> {
        let [x0, y0, x1, y1] = self.pixel_bounds(image.width, image.height);
        let (mut n, mut sum, mut sum_sq) = (0.0f64, 0.0f64, 0.0f64);
        for y in y0..y1 {
            for x in x0..x1 {
                if self.contains(x as f64 + 0.5, y as f64 + 0.5) {
                    let b = image.colour(x, y)[0] as f64;
                    n += 1.0;
                    sum += b;
                    sum_sq += b * b;
                }
            }
        }
        (n >= 2.0).then(|| (sum_sq / n - (sum / n).powi(2)).max(0.0).sqrt() as f32)
    }

    /// Whether the point lies inside the polygon (even–odd rule).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        let p = &self.polygon;
        let mut inside = false;
        let mut j = p.len() - 1;
        for i in 0..p.len() {
            let ([xi, yi], [xj, yj]) = (p[i], p[j]);
            if (yi > y) != (yj > y) && x < (xj - xi) * (y - yi) / (yj - yi) + xi {
                inside = !inside;
            }
            j = i;
        }
        inside
    }
}

/// The samples' contrast: the median over samples of the standard deviation
/// of brightness inside each (8-bit units), `None` without a sample of two
/// pixels. The median keeps one uniform rectangle (water) or one busy one
/// (a road edge) from setting it.
pub fn contrast(image: &Image, samples: &[Sample]) -> Option<f32> {
    median_spread(
        samples
            .iter()
            .filter_map(|s| s.brightness_std(image))
            .collect(),
    )
}

/// The median of the samples' brightness spreads (the upper one of an even
/// count): [`contrast`] of spreads measured sample by sample.
pub fn median_spread(mut spreads: Vec<f32>) -> Option<f32> {
    spreads.sort_by(f32::total_cmp);
    spreads.get(spreads.len() / 2).copied()
}

const CSV_COLUMNS: [&str; 5] = ["class", "xmin", "ymin", "xmax", "ymax"];

/// Parse the CSV form. Blank lines and lines starting with `#` are skipped;
/// a header line, if present, must name exactly the five columns. Every box
/// must lie within the `width`×`height` image.
pub fn parse_csv(text: &str, width: usize, height: usize) -> Result<Vec<Sample>> {
    let mut samples = Vec::new();
    let mut first = true;
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fail = |message: String| Error::Input(format!("line {}: {message}", number + 1));
        let fields: Vec<&str> = line.split(';').map(str::trim).collect();
        if std::mem::take(&mut first) && fields.first() == Some(&"class") {
            if fields != CSV_COLUMNS {
                return Err(fail(format!(
                    "unknown columns {:?}: expected class;xmin;ymin;xmax;ymax",
                    fields
                )));
            }
            continue;
        }
        if fields.len() != 5 {
            return Err(fail(format!(
                "{} fields: expected class;xmin;ymin;xmax;ymax",
                fields.len()
            )));
        }
        if fields[0].is_empty() {
            return Err(fail("empty class".into()));
        }
        let mut numbers = [0.0f64; 4];
        for (k, value) in numbers.iter_mut().enumerate() {
            *value = fields[k + 1]
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    fail(format!(
                        "{} = {:?} is not a number",
                        CSV_COLUMNS[k + 1],
                        fields[k + 1]
                    ))
                })?;
        }
        let [x0, y0, x1, y1] = numbers;
        if !(x0 < x1 && y0 < y1) {
            return Err(fail(format!(
                "empty box: needs xmin < xmax and ymin < ymax ({x0}, {y0}, {x1}, {y1})"
            )));
        }
        if x0 < 0.0 || y0 < 0.0 || x1 > width as f64 || y1 > height as f64 {
            return Err(fail(format!(
                "box ({x0}, {y0}, {x1}, {y1}) lies outside the {width}×{height} image"
            )));
        }
        samples.push(Sample::rectangle(fields[0], [x0, y0, x1, y1]));
    }
    if samples.is_empty() {
        return Err(Error::Input("no samples".into()));
    }
    Ok(samples)
}

/// The CSV form [`parse_csv`] reads: each sample's bounding box clipped to
/// the `width`×`height` image, in pixels written exactly (the shortest
/// decimal that reads back to the same value). A sample with nothing left
/// inside the image is left out.
pub fn to_csv(samples: &[Sample], width: usize, height: usize) -> String {
    let mut csv = CSV_COLUMNS.join(";") + "\n";
    for sample in samples {
        let [x0, y0, x1, y1] = sample.bounds();
        let (x0, x1) = (x0.clamp(0.0, width as f64), x1.clamp(0.0, width as f64));
        let (y0, y1) = (y0.clamp(0.0, height as f64), y1.clamp(0.0, height as f64));
        if x0 < x1 && y0 < y1 {
            csv.push_str(&format!("{};{x0};{y0};{x1};{y1}\n", sample.class));
        }
    }
    csv
}

/// Parse the GeoJSON form: a FeatureCollection of Polygon or MultiPolygon
/// features with a non-empty string property `class`. Outer rings are used
/// (holes are ignored). `to_pixel` maps image-CRS coordinates to pixels.
pub fn parse_geojson(
    text: &str,
    to_pixel: impl Fn(f64, f64) -> Option<[f64; 2]>,
    width: usize,
    height: usize,
) -> Result<Vec<Sample>> {
    let json: serde_json::Value =
        serde_json::from_str(text).map_err(|e| Error::Input(format!("not JSON: {e}")))?;
    let features = json
        .get("features")
        .and_then(|f| f.as_array())
        .ok_or_else(|| Error::Input("not a GeoJSON FeatureCollection".into()))?;
    let mut samples = Vec::new();
    for (k, feature) in features.iter().enumerate() {
        let fail = |message: &str| Error::Input(format!("feature {k}: {message}"));
        let class = feature
            .pointer("/properties/class")
            .and_then(|c| c.as_str())
            .map(str::trim)
            .filter(|c| !c.is_empty())
            .ok_or_else(|| fail("needs a non-empty string property \"class\""))?;
        let geometry = feature
            .get("geometry")
            .ok_or_else(|| fail("has no geometry"))?;
        let coordinates = geometry
            .get("coordinates")
            .ok_or_else(|| fail("geometry has no coordinates"))?;
        let rings: Vec<&serde_json::Value> = match geometry.get("type").and_then(|t| t.as_str()) {
            Some("Polygon") => vec![&coordinates[0]],
            Some("MultiPolygon") => coordinates
                .as_array()
                .map(|polys| polys.iter().map(|p| &p[0]).collect())
                .unwrap_or_default(),
            other => {
                return Err(fail(&format!(
                    "geometry type {other:?}: samples must be Polygon or MultiPolygon"
                )))
            }
        };
        for ring in rings {
            let points = ring
                .as_array()
                .filter(|r| r.len() >= 4)
                .ok_or_else(|| fail("a ring needs at least 4 positions"))?;
            let mut polygon = Vec::with_capacity(points.len());
            for p in points {
                let (Some(x), Some(y)) = (p[0].as_f64(), p[1].as_f64()) else {
                    return Err(fail("a position is not a pair of numbers"));
                };
                let pixel = to_pixel(x, y).ok_or_else(|| fail("cannot map to pixels"))?;
                if pixel[0] < 0.0
                    || pixel[1] < 0.0
                    || pixel[0] > width as f64
                    || pixel[1] > height as f64
                {
                    return Err(fail(&format!(
                        "({x}, {y}) lies outside the {width}×{height} image"
                    )));
                }
                polygon.push(pixel);
            }
            samples.push(Sample {
                class: class.to_string(),
                polygon,
            });
        }
    }
    if samples.is_empty() {
        return Err(Error::Input("no samples".into()));
    }
    Ok(samples)
}

/// Read a samples file for a `width`×`height` image georeferenced by
/// `geotransform`: `.geojson`/`.json` polygons in the image CRS, else the
/// semicolon CSV of pixel rectangles. Errors name the file.
pub fn read_file(
    path: &Path,
    geotransform: Option<GeoTransform>,
    w: usize,
    h: usize,
) -> Result<Vec<Sample>> {
    let text = crate::files::read_to_string(path)?;
    let is_json = matches!(
        path.extension().and_then(|e| e.to_str()),
        Some("geojson" | "json")
    );
    let parsed = if is_json {
        let geo = geotransform.unwrap_or(GeoTransform::IDENTITY);
        parse_geojson(&text, |x, y| geo.invert(x, y).map(|(c, r)| [c, r]), w, h)
    } else {
        parse_csv(&text, w, h)
    };
    parsed.map_err(|e| Error::Input(format!("{}: {e}", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_parses_with_and_without_header() {
        let s = parse_csv(
            "class;xmin;ymin;xmax;ymax\ntree;1;2;10;12\n\n# c\nother;0;0;5;5\n",
            20,
            20,
        )
        .unwrap();
        assert_eq!(s.len(), 2);
        assert!(s[0].contains(5.0, 5.0) && !s[0].contains(0.5, 5.0));
        assert_eq!(parse_csv("tree;1;2;10;12", 20, 20).unwrap().len(), 1);
    }

    #[test]
    fn csv_written_reads_back_clipped_to_the_image() {
        let samples = [
            Sample::rectangle("tree", [1.25, 2.0, 10.0, 12.5]),
            Sample::rectangle("other", [-3.0, 15.0, 4.0, 30.0]),
            Sample::rectangle("gone", [25.0, 1.0, 30.0, 5.0]),
        ];
        let csv = to_csv(&samples, 20, 20);
        assert_eq!(
            csv,
            "class;xmin;ymin;xmax;ymax\ntree;1.25;2;10;12.5\nother;0;15;4;20\n"
        );
        let back = parse_csv(&csv, 20, 20).unwrap();
        assert_eq!(back[0], samples[0]);
        assert_eq!(back[1].bounds(), [0.0, 15.0, 4.0, 20.0]);
        assert_eq!(back.len(), 2);
    }

    #[test]
    fn csv_errors_name_the_line_and_problem() {
        let err = |t: &str| parse_csv(t, 20, 20).unwrap_err().to_string();
        assert!(err("class;x;y;w;h\n").contains("unknown columns"));
        assert!(err("tree;1;2;10;12\n;1;2;3;4").contains("line 2: empty class"));
        assert!(err("tree;1;2;30;12").contains("outside the 20×20 image"));
        assert!(err("tree;-1;2;3;4").contains("outside"));
        assert!(err("tree;1;two;3;4").contains("ymin = \"two\" is not a number"));
        assert!(err("tree;5;2;3;4").contains("empty box"));
        assert!(err("tree;1;2;3").contains("4 fields"));
        assert!(err("# nothing\n").contains("no samples"));
    }

    #[test]
    fn geojson_polygons_map_to_pixels() {
        let text = r#"{"type":"FeatureCollection","features":[
            {"type":"Feature","properties":{"class":"forest"},
             "geometry":{"type":"Polygon","coordinates":[[[100,200],[110,200],[110,190],[100,190],[100,200]]]}}]}"#;
        // 1 unit per pixel, origin (100, 200), y down.
        let s = parse_geojson(text, |x, y| Some([x - 100.0, 200.0 - y]), 20, 20).unwrap();
        assert_eq!(s[0].class, "forest");
        assert!(s[0].contains(5.0, 5.0));
        let outside = parse_geojson(text, |x, y| Some([x, y]), 20, 20).unwrap_err();
        assert!(outside.to_string().contains("outside"));
        let no_class = text.replace("\"class\":\"forest\"", "\"kind\":\"forest\"");
        assert!(parse_geojson(&no_class, |x, y| Some([x, y]), 20, 20)
            .unwrap_err()
            .to_string()
            .contains("class"));
    }
}
