//! Premultiplied RGBA8 images: the impostor views, the atlas pages and
//! their mip levels.
//!
//! Every texel stores colour already multiplied by its coverage, so that
//! filtering (bilinear sampling, mip reduction, compositing) averages what
//! is *there* and never the colour of empty texels: the white or dark
//! borders of straight-alpha textures cannot arise. Invariant: each colour
//! channel is at most alpha.

/// Rounding allowed, in 8-bit units of premultiplied colour, when a texel
/// is compared with a [`ColourRange`]: a composition's and each mip
/// reduction's.
pub const ROUNDING_UNITS: f64 = 2.0;

/// The per-channel range of (un-premultiplied) colours that source images
/// hold: a texel composed from them, a blend of their colours, lies within
/// it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ColourRange {
    pub lo: [u8; 3],
    pub hi: [u8; 3],
}

impl ColourRange {
    /// The range of `images`' texels. A texel of coverage A and
    /// premultiplied value P holds a colour within (P ± ½)·255/A; texels
    /// with A ≥ 16 add that whole interval (at most 16 units wide), so
    /// colours seen only at thin edges — a trunk, a twig — count too.
    pub fn of(images: &[PremulImage]) -> ColourRange {
        let (mut lo, mut hi) = ([255u8; 3], [0u8; 3]);
        for t in images.iter().flat_map(|i| &i.texels).filter(|t| t[3] >= 16) {
            let a = t[3] as f64;
            for k in 0..3 {
                let low = ((t[k] as f64 - 0.5) * 255.0 / a).floor().clamp(0.0, 255.0) as u8;
                let high = ((t[k] as f64 + 0.5) * 255.0 / a).ceil().clamp(0.0, 255.0) as u8;
                lo[k] = lo[k].min(low);
                hi[k] = hi[k].max(high);
            }
        }
        ColourRange { lo, hi }
    }

    /// The premultiplied values channel `k` of a texel of coverage `alpha`
    /// may hold: a·lo − rounding to a·hi + rounding.
    fn bounds(&self, alpha: u8, k: usize) -> (f64, f64) {
        let a = alpha as f64 / 255.0;
        (
            a * self.lo[k] as f64 - ROUNDING_UNITS,
            a * self.hi[k] as f64 + ROUNDING_UNITS,
        )
    }

    /// Whether the partly covered texel `t` lies within the range.
    pub fn holds(&self, t: [u8; 4]) -> bool {
        (0..3).all(|k| {
            let (low, high) = self.bounds(t[3], k);
            (low..=high).contains(&(t[k] as f64))
        })
    }

    /// `t` moved into the range, channel by channel, if partly covered
    /// (empty and full texels are kept). A composite of thousands of
    /// layers needs it: the 8-bit rounding of faint edge texels (a
    /// premultiplied 1 at coverage 3 stands for any colour from 42 to 127)
    /// adds up, stacked that deep, to texels well outside the blend of the
    /// sources.
    pub fn clamp(&self, t: [u8; 4]) -> [u8; 4] {
        if t[3] == 0 || t[3] == 255 {
            return t;
        }
        let mut out = t;
        for k in 0..3 {
            let (low, high) = self.bounds(t[3], k);
            let (low, high) = (low.ceil().max(0.0), high.floor().min(t[3] as f64));
            out[k] = (t[k] as f64).clamp(low, high) as u8;
        }
        out
    }
}

/// A premultiplied RGBA8 image, row-major, texels `[r, g, b, a]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PremulImage {
    pub width: usize,
    pub height: usize,
    pub texels: Vec<[u8; 4]>,
}

impl PremulImage {
    /// A fully transparent image.
    pub fn transparent(width: usize, height: usize) -> PremulImage {
        PremulImage {
            width,
            height,
            texels: vec![[0; 4]; width * height],
        }
    }

    #[inline]
    pub fn texel(&self, x: usize, y: usize) -> [u8; 4] {
        self.texels[y * self.width + x]
    }

    /// The texels as bytes (RGBA8, premultiplied), e.g. to upload or encode.
    pub fn bytes(&self) -> &[u8] {
        self.texels.as_flattened()
    }

    /// Copy `source` with its top-left corner at (`x`, `y`); the caller keeps
    /// it inside.
    pub fn paste(&mut self, source: &PremulImage, x: usize, y: usize) {
        for row in 0..source.height {
            let to = (y + row) * self.width + x;
            let from = row * source.width;
            self.texels[to..to + source.width]
                .copy_from_slice(&source.texels[from..from + source.width]);
        }
    }

    /// The `w`×`h` block at (`x`, `y`).
    pub fn crop(&self, x: usize, y: usize, w: usize, h: usize) -> PremulImage {
        let mut out = PremulImage::transparent(w, h);
        for row in 0..h {
            let from = (y + row) * self.width + x;
            out.texels[row * w..(row + 1) * w].copy_from_slice(&self.texels[from..from + w]);
        }
        out
    }

    /// Half the size (rounded up), each texel the mean of the 2×2 block under
    /// it, premultiplied channels and alpha alike. Averaging premultiplied
    /// values keeps coverage (an alpha-tested leaf covering a quarter of the
    /// block leaves a quarter alpha) and only mixes colours that are present.
    pub fn reduce(&self) -> PremulImage {
        let (w, h) = (self.width.div_ceil(2), self.height.div_ceil(2));
        let mut out = PremulImage::transparent(w, h);
        for y in 0..h {
            for x in 0..w {
                let mut sum = [0u32; 4];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (sx, sy) = (2 * x + dx, 2 * y + dy);
                    if sx < self.width && sy < self.height {
                        let t = self.texel(sx, sy);
                        for c in 0..4 {
                            sum[c] += t[c] as u32;
                        }
                    }
                }
                // Rounded mean over four texels (missing ones are empty).
                out.texels[y * w + x] = sum.map(|s| ((s + 2) / 4) as u8);
            }
        }
        out
    }

    /// This image and `levels - 1` successive reductions.
    pub fn mip_chain(&self, levels: usize) -> Vec<PremulImage> {
        let mut chain = vec![self.clone()];
        while chain.len() < levels {
            let next = chain[chain.len() - 1].reduce();
            chain.push(next);
        }
        chain
    }

    /// Straight-alpha RGBA8 bytes (colour divided by coverage), for looking at
    /// an image in an ordinary viewer.
    pub fn to_straight(&self) -> Vec<u8> {
        self.texels
            .iter()
            .flat_map(|&[r, g, b, a]| {
                if a == 0 {
                    [0; 4]
                } else {
                    let un = |c: u8| ((c as u32 * 255 + a as u32 / 2) / a as u32).min(255) as u8;
                    [un(r), un(g), un(b), a]
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_range_holds_blends_of_its_sources_and_clamps_drift_back() {
        // Two sources: a dark green and a brown, a fully and a half covered texel.
        let sources = PremulImage {
            width: 2,
            height: 1,
            texels: vec![[20, 100, 20, 255], [40, 15, 10, 128]],
        };
        let range = ColourRange::of(std::slice::from_ref(&sources));
        assert_eq!((range.lo, range.hi), ([19, 28, 18], [81, 101, 21]));
        // A half-covered blend of the two lies within; drift does not.
        assert!(range.holds([10, 50, 10, 128]));
        let drifted = [3, 3, 0, 3];
        assert!(!range.holds(drifted));
        let clamped = range.clamp(drifted);
        assert!(range.holds(clamped), "{clamped:?}");
        assert!(clamped[..3].iter().all(|&c| c <= clamped[3]));
        // Blends are kept as they are; empty and full texels too.
        for t in [[10, 50, 10, 128], [0, 0, 0, 0], [200, 0, 0, 255]] {
            assert_eq!(range.clamp(t), t);
        }
    }

    #[test]
    fn reduction_keeps_coverage_and_never_exceeds_alpha() {
        // One opaque red texel in a 2×2 block: a quarter of the coverage,
        // still pure red once un-premultiplied.
        let mut image = PremulImage::transparent(4, 2);
        image.texels[0] = [200, 0, 0, 255];
        image.texels[3] = [40, 40, 40, 80];
        let half = image.reduce();
        assert_eq!((half.width, half.height), (2, 1));
        assert_eq!(half.texels[0], [50, 0, 0, 64]);
        assert_eq!(half.texels[1], [10, 10, 10, 20]);
        assert_eq!(half.to_straight()[..4], [199, 0, 0, 64]);
        let chain = image.mip_chain(3);
        assert_eq!(chain.len(), 3);
        assert_eq!((chain[2].width, chain[2].height), (1, 1));
        for level in &chain {
            assert!(level
                .texels
                .iter()
                .all(|t| t[..3].iter().all(|&c| c <= t[3])));
        }
    }
}
