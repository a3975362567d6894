//! An RGBA8 image shown in a frame of another size, as a window shows it:
//! scaled to fit with its aspect kept (bilinear, through tiny-skia), centred
//! on a background colour.

use crate::{Error, Result};

/// `rgba` (`width`×`height`, straight alpha) fitted into a
/// `frame_width`×`frame_height` RGBA8 image filled with `background`.
///
/// ```
/// use relevo_core::raster::fit::fit_rgba;
/// let white = vec![255u8; 4 * 4 * 2];
/// let framed = fit_rgba(&white, 4, 2, 8, 8, [0, 0, 0, 255]).unwrap();
/// assert_eq!(framed.len(), 8 * 8 * 4);
/// assert_eq!(&framed[(4 * 8 + 4) * 4..][..4], &[255; 4]); // the image, in the middle
/// assert_eq!(&framed[..4], &[0, 0, 0, 255]); // the background above it
/// ```
pub fn fit_rgba(
    rgba: &[u8],
    width: usize,
    height: usize,
    frame_width: usize,
    frame_height: usize,
    background: [u8; 4],
) -> Result<Vec<u8>> {
    let size = |w: usize, h: usize| {
        tiny_skia::IntSize::from_wh(u32::try_from(w).unwrap_or(0), u32::try_from(h).unwrap_or(0))
            .ok_or_else(|| Error::Input(format!("{w}×{h} is not an image size")))
    };
    let premultiplied: Vec<u8> = rgba
        .chunks_exact(4)
        .flat_map(|p| {
            let a = u16::from(p[3]);
            let scale = |c: u8| ((u16::from(c) * a + 127) / 255) as u8;
            [scale(p[0]), scale(p[1]), scale(p[2]), p[3]]
        })
        .collect();
    let image =
        tiny_skia::Pixmap::from_vec(premultiplied, size(width, height)?).ok_or_else(|| {
            Error::Input(format!(
                "{width}×{height} RGBA8 needs {} bytes",
                width * height * 4
            ))
        })?;
    let mut frame = tiny_skia::Pixmap::new(
        u32::try_from(frame_width).unwrap_or(0),
        u32::try_from(frame_height).unwrap_or(0),
    )
    .ok_or_else(|| Error::Input(format!("{frame_width}×{frame_height} is not an image size")))?;
    let [r, g, b, a] = background;
    frame.fill(tiny_skia::Color::from_rgba8(r, g, b, a));
    let scale = (frame_width as f32 / width as f32).min(frame_height as f32 / height as f32);
    let (dx, dy) = (
        (frame_width as f32 - width as f32 * scale) / 2.0,
        (frame_height as f32 - height as f32 * scale) / 2.0,
    );
    let paint = tiny_skia::PixmapPaint {
        quality: tiny_skia::FilterQuality::Bilinear,
        ..Default::default()
    };
    frame.draw_pixmap(
        0,
        0,
        image.as_ref(),
        &paint,
        tiny_skia::Transform::from_scale(scale, scale).post_translate(dx, dy),
        None,
    );
    Ok(frame
        .pixels()
        .iter()
        .flat_map(|p| {
            let c = p.demultiply();
            [c.red(), c.green(), c.blue(), c.alpha()]
        })
        .collect())
}
