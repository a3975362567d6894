//! Mapping raster values to 8 bits for display and for vegetation analysis:
//! a linear stretch between per-band percentiles.

use super::Raster;

/// The stretch asked for, or by default none for 8-bit data (values kept)
/// and the 2nd to 98th percentiles for deeper data.
pub fn stretch_or_default(stretch: Option<[f64; 2]>, eight_bit: bool) -> Option<[f64; 2]> {
    stretch.or(if eight_bit { None } else { Some([2.0, 98.0]) })
}

/// Per band, the values mapped to 0 and 255: the `[low, high]` percentiles
/// of its valid cells, or `(0, 255)` (values kept) when `stretch` is `None`.
pub fn stretch_ranges(raster: &Raster, stretch: Option<[f64; 2]>) -> Vec<(f64, f64)> {
    (0..raster.bands)
        .map(|b| match stretch {
            None => (0.0, 255.0),
            Some([lo, hi]) => {
                let mut values: Vec<f64> = raster
                    .band(b)
                    .iter()
                    .copied()
                    .filter(|v| !v.is_nan())
                    .collect();
                values.sort_unstable_by(f64::total_cmp);
                let at =
                    |p: f64| values[((p / 100.0) * (values.len() - 1) as f64).round() as usize];
                if values.is_empty() {
                    (0.0, 255.0)
                } else {
                    (at(lo), at(hi).max(at(lo) + f64::EPSILON))
                }
            }
        })
        .collect()
}

/// `value` mapped linearly from `range` to 0..255, rounded and clamped
/// (no-data, NaN, gives 0).
#[inline]
pub fn to_u8(value: f64, (lo, hi): (f64, f64)) -> u8 {
    ((value - lo) / (hi - lo) * 255.0).round().clamp(0.0, 255.0) as u8
}

/// Three bands to RGBA8 with [`stretch_ranges`] and [`to_u8`]. Alpha is
/// 255 where the raster has data.
pub fn to_rgba8(raster: &Raster, stretch: Option<[f64; 2]>) -> Vec<u8> {
    to_rgba8_in(raster, &stretch_ranges(raster, stretch))
}

/// Three bands to RGBA8 with `ranges` (one a band, from [`stretch_ranges`]
/// of this raster or of a larger one it is part of) and [`to_u8`]. Alpha
/// is 255 where the raster has data.
pub fn to_rgba8_in(raster: &Raster, ranges: &[(f64, f64)]) -> Vec<u8> {
    let mut out = vec![0u8; raster.cells() * 4];
    for i in 0..raster.cells() {
        if !raster.is_valid(i) {
            continue;
        }
        for (b, &range) in ranges.iter().take(3).enumerate() {
            out[i * 4 + b] = to_u8(raster.band(b)[i], range);
        }
        out[i * 4 + 3] = 255;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_map_to_the_ends_and_no_data_stays_transparent() {
        let data: Vec<f64> = (0..101).map(|v| v as f64).chain([f64::NAN]).collect();
        let n = data.len();
        let raster = Raster::from_data(n, 1, 1, data);
        let ranges = stretch_ranges(&raster, Some([10.0, 90.0]));
        assert_eq!(ranges, vec![(10.0, 90.0)]);
        assert_eq!(to_u8(10.0, ranges[0]), 0);
        assert_eq!(to_u8(90.0, ranges[0]), 255);
        assert_eq!(to_u8(50.0, ranges[0]), 128);
        assert_eq!(stretch_or_default(None, true), None);
        assert_eq!(stretch_or_default(None, false), Some([2.0, 98.0]));
        let grey = Raster::from_data(2, 1, 3, vec![7.0, f64::NAN, 7.0, 1.0, 7.0, 1.0]);
        assert_eq!(to_rgba8(&grey, None), vec![7, 7, 7, 255, 0, 0, 0, 0]);
    }
}
