//! The cut's options: the distance bands (the largest cluster each band
//! draws), the magnification a cluster's texture may take, the view switch
//! and cross-fades, culling.

/// One distance band.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CutBand {
    /// Outer edge of the band, metres from the eye.
    pub until_m: f64,
    /// Most objects one drawn cluster may stand for inside this band.
    pub max_cluster: u32,
}

/// The parameters of a cut (fields left out take their defaults).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CutOptions {
    /// Bands by increasing distance.
    pub bands: Vec<CutBand>,
    /// Elevation of the line of sight above which an impostor shows its top
    /// view, degrees (the seed's θ, 45° after its 0–90° sweep).
    pub view_angle_deg: f64,
    /// Width of the cross-fade around the view-angle threshold and around
    /// each 45° boundary between side views, degrees (0: the view flips).
    pub crossfade_deg: f64,
    /// Choose the threshold per impostor instead: the elevation from which
    /// its top view shows more than its side view — a box of height h and
    /// width w seen from elevation e shows w² sin e from above and w h cos e
    /// from the side, equal at tan e = h / w. Flat clusters switch early,
    /// tall conifers late (the automatic choice the seed proposes, §4.1.3).
    pub automatic_view_angle: bool,
    /// Largest ratio of screen pixels to texture texels a cluster may be
    /// drawn at.
    pub magnification: f64,
    /// Width of the cross-fade between a cluster and its children, as a
    /// fraction of the margin left before the cluster is refused (by its
    /// band or its magnification): a cluster within that margin of being
    /// refused shares the pixels with its children by ordered dither, so
    /// the cut changes level without popping (0: it switches).
    pub level_fade: f64,
    /// Leave out what lies wholly outside the view frustum (the seed's
    /// object culling, §4.2.2); off, every object within the last band is
    /// drawn, as the seed's table 4.2 measured without it.
    pub cull: bool,
}

impl Default for CutOptions {
    /// Five bands from 300 m to 20 km, clusters of 1, 4, 16, 64 and 256.
    fn default() -> Self {
        CutOptions {
            bands: [
                (300.0, 1),
                (1_000.0, 4),
                (3_000.0, 16),
                (8_000.0, 64),
                (20_000.0, 256),
            ]
            .map(|(until_m, max_cluster)| CutBand {
                until_m,
                max_cluster,
            })
            .to_vec(),
            view_angle_deg: 45.0,
            crossfade_deg: 10.0,
            automatic_view_angle: false,
            magnification: 1.5,
            level_fade: 0.1,
            cull: true,
        }
    }
}

impl CutOptions {
    /// The seed's configurations 1–3 (fig. 4.15) for a terrain whose
    /// diagonal is `diagonal_m`: three bands, d₁ = diagonal/8, d₂ =
    /// diagonal/4 and d₃ = 2 × diagonal (beyond the terrain, as in the
    /// seed's test, so that nothing is culled by distance). The figure is not
    /// in the text; its prose fixes the middle band (at most 2 objects per
    /// cluster in configuration 1, 6 in configuration 3) and table 4.4 shows
    /// configuration 1 drawing the fewest billboards, so configuration 1
    /// groups the most in the far band. Maximum cluster sizes per band:
    /// 1: (1, 2, 64); 2: (1, 4, 16); 3: (1, 6, 8). Texture magnification is
    /// not limited, as the seed did not limit it.
    pub fn seed_configuration(number: u8, diagonal_m: f64) -> Option<CutOptions> {
        let sizes = match number {
            1 => [1, 2, 64],
            2 => [1, 4, 16],
            3 => [1, 6, 8],
            _ => return None,
        };
        let until = [diagonal_m / 8.0, diagonal_m / 4.0, 2.0 * diagonal_m];
        Some(CutOptions {
            bands: (0..3)
                .map(|i| CutBand {
                    until_m: until[i],
                    max_cluster: sizes[i],
                })
                .collect(),
            // The largest finite number: unlimited, and still a JSON number.
            magnification: f64::MAX,
            ..CutOptions::default()
        })
    }

    /// Bands from text `UNTIL_M:MAX_CLUSTER,…`, e.g. `300:1,1000:4,3000:16`
    /// (checked).
    pub fn parse_bands(text: &str) -> Result<Vec<CutBand>, String> {
        let bands = text
            .split(',')
            .map(|band| {
                let (until, size) = band
                    .split_once(':')
                    .ok_or_else(|| format!("{band:?}: expected UNTIL_M:MAX_CLUSTER"))?;
                Ok(CutBand {
                    until_m: until
                        .trim()
                        .parse()
                        .map_err(|_| format!("{until:?} is not a distance in metres"))?,
                    max_cluster: size
                        .trim()
                        .parse()
                        .map_err(|_| format!("{size:?} is not a cluster size"))?,
                })
            })
            .collect::<Result<Vec<CutBand>, String>>()?;
        CutOptions {
            bands: bands.clone(),
            ..CutOptions::default()
        }
        .check()?;
        Ok(bands)
    }

    /// Check the bands: increasing distances, sizes at least 1.
    pub fn check(&self) -> Result<(), String> {
        if self.bands.is_empty() {
            return Err("no distance bands".into());
        }
        for (i, b) in self.bands.iter().enumerate() {
            if !b.until_m.is_finite() || b.until_m <= 0.0 || b.max_cluster == 0 {
                return Err(format!(
                    "band {}: needs a positive distance and a cluster size of at least 1",
                    i + 1
                ));
            }
            if i > 0 && b.until_m <= self.bands[i - 1].until_m {
                return Err(format!("band {}: distances must increase", i + 1));
            }
        }
        if !(0.0..=90.0).contains(&self.view_angle_deg)
            || self.crossfade_deg.is_nan()
            || self.crossfade_deg < 0.0
        {
            return Err("the view angle must lie in 0–90° and the cross-fade be ≥ 0".into());
        }
        if !(self.magnification.is_finite() && self.magnification > 0.0) {
            return Err("the magnification must be a positive number".into());
        }
        if !(0.0..=1.0).contains(&self.level_fade) {
            return Err("the level fade must lie in 0–1".into());
        }
        Ok(())
    }

    /// Distance beyond which nothing is drawn, metres.
    pub fn last_distance(&self) -> f64 {
        self.bands.last().map_or(0.0, |b| b.until_m)
    }

    /// Largest cluster allowed at `distance_m`; `None` beyond the last band.
    pub fn max_cluster_at(&self, distance_m: f64) -> Option<u32> {
        self.bands
            .iter()
            .find(|b| distance_m <= b.until_m)
            .map(|b| b.max_cluster)
    }

    /// Nearest distance at which a cluster of `count` objects may be drawn:
    /// the inner edge of the first band that allows it.
    pub fn nearest_distance_for(&self, count: u32) -> Option<f64> {
        let i = self.bands.iter().position(|b| b.max_cluster >= count)?;
        Some(if i == 0 {
            0.0
        } else {
            self.bands[i - 1].until_m
        })
    }

    /// Largest cluster any band allows.
    pub fn largest_cluster(&self) -> u32 {
        self.bands.iter().map(|b| b.max_cluster).max().unwrap_or(1)
    }
}
