//! PNG encoding of RGBA8 images (drape textures, renders, overlays).

use crate::{Error, Result};

/// An RGBA8 image (row-major, `width`×`height`) encoded as PNG.
pub fn encode_rgba(rgba: &[u8], width: usize, height: usize) -> Result<Vec<u8>> {
    let too_large = || Error::Input(format!("{width}×{height} is too large for a PNG"));
    let (w, h) = (
        u32::try_from(width).map_err(|_| too_large())?,
        u32::try_from(height).map_err(|_| too_large())?,
    );
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, w, h);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    encoder
        .write_header()
        .and_then(|mut writer| writer.write_image_data(rgba))
        .map_err(|e| Error::Input(format!("PNG encoding: {e}")))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoded_images_decode_to_the_same_pixels() {
        let rgba: Vec<u8> = (0..3 * 2 * 4).map(|v| (v * 9) as u8).collect();
        let bytes = encode_rgba(&rgba, 3, 2).unwrap();
        let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (3, 2));
        assert_eq!(&buf[..info.buffer_size()], &rgba[..]);
    }
}
