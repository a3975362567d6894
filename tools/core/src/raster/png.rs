//! PNG encoding of RGBA8 images (drape textures, renders, overlays) and of
//! 16-bit grey values (golden records' reference grids).

use crate::{Error, Result};

/// An RGBA8 image (row-major, `width`×`height`) encoded as PNG.
pub fn encode_rgba(rgba: &[u8], width: usize, height: usize) -> Result<Vec<u8>> {
    encode(
        rgba,
        width,
        height,
        png::ColorType::Rgba,
        png::BitDepth::Eight,
    )
}

/// Samples (big-endian where 16-bit) encoded as a PNG of one kind.
fn encode(
    samples: &[u8],
    width: usize,
    height: usize,
    colour: png::ColorType,
    depth: png::BitDepth,
) -> Result<Vec<u8>> {
    let too_large = || Error::Input(format!("{width}×{height} is too large for a PNG"));
    let (w, h) = (
        u32::try_from(width).map_err(|_| too_large())?,
        u32::try_from(height).map_err(|_| too_large())?,
    );
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, w, h);
    encoder.set_color(colour);
    encoder.set_depth(depth);
    encoder
        .write_header()
        .and_then(|mut writer| writer.write_image_data(samples))
        .map_err(|e| Error::Input(format!("PNG encoding: {e}")))?;
    Ok(out)
}

/// The width and height a PNG's header declares, without decoding it.
pub fn size(bytes: &[u8]) -> Result<(usize, usize)> {
    let info = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .map_err(|e| Error::Input(format!("PNG decoding: {e}")))?;
    let (w, h) = info.info().size();
    Ok((w as usize, h as usize))
}

/// Refuse, before decoding, a PNG whose header declares more pixels than
/// the memory budget holds at `bytes_per_pixel` (the decoded buffer and
/// its conversion): a small file that decodes to a huge image is refused.
fn check_decoded_size(width: u32, height: u32, bytes_per_pixel: u64) -> Result<()> {
    crate::memory::check(
        &format!("decoding a {width}×{height} PNG"),
        u64::from(width) * u64::from(height),
        bytes_per_pixel,
        "use a smaller image",
    )
}

/// A PNG decoded to RGBA8 (grey, grey-alpha and RGB are expanded; 16-bit
/// samples keep their high byte): pixels, width, height.
pub fn decode_rgba(bytes: &[u8]) -> Result<(Vec<u8>, usize, usize)> {
    let bad = |e: png::DecodingError| Error::Input(format!("PNG decoding: {e}"));
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().map_err(bad)?;
    let (w, h) = reader.info().size();
    check_decoded_size(w, h, 8)?;
    let (buf, info) = next_frame(&mut reader)?;
    let (w, h) = (info.width as usize, info.height as usize);
    let rgba = match info.color_type.samples() {
        4 => buf,
        3 => buf
            .chunks_exact(3)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect(),
        2 => buf
            .chunks_exact(2)
            .flat_map(|p| [p[0], p[0], p[0], p[1]])
            .collect(),
        _ => buf.iter().flat_map(|&g| [g, g, g, 255]).collect(),
    };
    Ok((rgba, w, h))
}

/// The image's samples, once its declared size has passed the budget.
fn next_frame<R: std::io::BufRead + std::io::Seek>(
    reader: &mut png::Reader<R>,
) -> Result<(Vec<u8>, png::OutputInfo)> {
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| Error::Input(format!("PNG decoding: {e}")))?;
    buf.truncate(info.buffer_size());
    Ok((buf, info))
}

/// 16-bit greyscale values (row-major, `width`×`height`) encoded as PNG.
pub fn encode_grey16(values: &[u16], width: usize, height: usize) -> Result<Vec<u8>> {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    encode(
        &bytes,
        width,
        height,
        png::ColorType::Grayscale,
        png::BitDepth::Sixteen,
    )
}

/// A 16-bit greyscale PNG decoded: values, width, height. Any other kind
/// of PNG is refused; the declared size is checked against the memory
/// budget before anything is decoded.
pub fn decode_grey16(bytes: &[u8]) -> Result<(Vec<u16>, usize, usize)> {
    let bad = |e: png::DecodingError| Error::Input(format!("PNG decoding: {e}"));
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().map_err(bad)?;
    let (w, h) = reader.info().size();
    let (colour, depth) = (reader.info().color_type, reader.info().bit_depth);
    if (colour, depth) != (png::ColorType::Grayscale, png::BitDepth::Sixteen) {
        return Err(Error::Input(format!(
            "a {colour:?} PNG of {depth:?} bits, expected 16-bit greyscale"
        )));
    }
    check_decoded_size(w, h, 4)?;
    let (buf, info) = next_frame(&mut reader)?;
    let values = buf
        .chunks_exact(2)
        .map(|b| u16::from_be_bytes([b[0], b[1]]))
        .collect();
    Ok((values, info.width as usize, info.height as usize))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoded_images_decode_to_the_same_pixels() {
        let rgba: Vec<u8> = (0..3 * 2 * 4).map(|v| (v * 9) as u8).collect();
        let bytes = encode_rgba(&rgba, 3, 2).unwrap();
        assert_eq!(decode_rgba(&bytes).unwrap(), (rgba, 3, 2));
        assert!(decode_rgba(b"not a png").is_err());
    }
}
