//! Premultiplied RGBA8 images: the impostor views, the atlas pages and
//! their mip levels.
//!
//! Every texel stores colour already multiplied by its coverage, so that
//! filtering (bilinear sampling, mip reduction, compositing) averages what
//! is *there* and never the colour of empty texels: the white or dark
//! borders of straight-alpha textures cannot arise. Invariant: each colour
//! channel is at most alpha.

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
