//! Elevation tiles encoded in 8-bit RGB images.

use serde::{Deserialize, Serialize};

/// How a tile stores its heights.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Encoding {
    /// Band 1 holds the height itself.
    #[default]
    Plain,
    /// Mapbox Terrain-RGB: h = (R·65536 + G·256 + B)/10 − 10000 metres.
    TerrainRgb,
    /// Mapzen/AWS Terrarium: h = R·256 + G + B/256 − 32768 metres.
    Terrarium,
}

impl Encoding {
    /// Bands the encoding reads.
    pub fn bands_needed(self) -> usize {
        match self {
            Encoding::Plain => 1,
            Encoding::TerrainRgb | Encoding::Terrarium => 3,
        }
    }

    /// The heights a decoded raster holds: the raster itself when
    /// [`Encoding::Plain`], else one band decoded from its first three.
    pub fn decode_raster(self, raw: super::Raster) -> super::Raster {
        if self == Encoding::Plain {
            return raw;
        }
        let (r, g, b) = (raw.band(0), raw.band(1), raw.band(2));
        let heights = (0..raw.cells())
            .map(|i| self.decode(r[i], g[i], b[i]))
            .collect();
        super::Raster::from_data(raw.width, raw.height, 1, heights)
    }

    /// Height in metres of one pixel, computed in f64.
    pub fn decode(self, r: f64, g: f64, b: f64) -> f64 {
        match self {
            Encoding::Plain => r,
            Encoding::TerrainRgb => (r * 65536.0 + g * 256.0 + b) / 10.0 - 10000.0,
            Encoding::Terrarium => r * 256.0 + g + b / 256.0 - 32768.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values() {
        // Sea level in both encodings.
        assert_eq!(Encoding::TerrainRgb.decode(1.0, 134.0, 160.0), 0.0);
        assert_eq!(Encoding::Terrarium.decode(128.0, 0.0, 0.0), 0.0);
        assert_eq!(Encoding::Terrarium.decode(128.0, 1.0, 128.0), 1.5);
    }
}
