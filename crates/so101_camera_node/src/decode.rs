//! Frames as rgb8 for image_raw, and YUYV frames as JPEG for image_raw/compressed.

use zune_jpeg::{
    zune_core::{bytestream::ZCursor, colorspace::ColorSpace, options::DecoderOptions},
    JpegDecoder,
};

/// rgb8 of a JPEG of the given size, or why not.
pub fn rgb_from_jpeg(jpeg: &[u8], width: u32, height: u32) -> Result<Vec<u8>, String> {
    let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::RGB);
    let mut decoder = JpegDecoder::new_with_options(ZCursor::new(jpeg), options);
    decoder
        .decode_headers()
        .map_err(|error| error.to_string())?;
    let size = decoder.dimensions().map(|(w, h)| (w as u32, h as u32));
    if size != Some((width, height)) {
        return Err(format!("a {size:?} JPEG in a {width}x{height} stream"));
    }
    decoder.decode().map_err(|error| error.to_string())
}

/// rgb8 of packed YUYV 4:2:2 (BT.601, full range).
pub fn rgb_from_yuyv(yuyv: &[u8]) -> Vec<u8> {
    let byte = |value: f64| value.round().clamp(0.0, 255.0) as u8;
    let mut rgb = Vec::with_capacity(yuyv.len() / 2 * 3);
    for group in yuyv.chunks_exact(4) {
        let (u, v) = (f64::from(group[1]) - 128.0, f64::from(group[3]) - 128.0);
        for y in [f64::from(group[0]), f64::from(group[2])] {
            rgb.extend([
                byte(y + 1.402 * v),
                byte(y - 0.344_136 * u - 0.714_136 * v),
                byte(y + 1.772 * u),
            ]);
        }
    }
    rgb
}

/// JPEG of an rgb8 frame.
pub fn jpeg_from_rgb(rgb: &[u8], width: u32, height: u32, quality: u8) -> Result<Vec<u8>, String> {
    let side = |value: u32| u16::try_from(value).map_err(|_| "frame too large for JPEG".to_owned());
    let mut jpeg = Vec::with_capacity(rgb.len() / 8);
    jpeg_encoder::Encoder::new(&mut jpeg, quality)
        .encode(
            rgb,
            side(width)?,
            side(height)?,
            jpeg_encoder::ColorType::Rgb,
        )
        .map_err(|error| error.to_string())?;
    Ok(jpeg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fake::{picture, yuyv_from_rgb};

    fn mean_error(a: &[u8], b: &[u8]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| f64::from(x.abs_diff(*y)))
            .sum::<f64>()
            / a.len() as f64
    }

    #[test]
    fn a_jpeg_decodes_close_to_its_picture() {
        let rgb = picture(64, 48, 5);
        let jpeg = jpeg_from_rgb(&rgb, 64, 48, 95).unwrap();
        let decoded = rgb_from_jpeg(&jpeg, 64, 48).unwrap();
        assert_eq!(decoded.len(), rgb.len());
        assert!(mean_error(&decoded, &rgb) < 2.0);
        assert!(rgb_from_jpeg(&jpeg, 32, 48).is_err());
        assert!(rgb_from_jpeg(&jpeg[..20], 64, 48).is_err());
    }

    #[test]
    fn yuyv_round_trips_within_rounding() {
        // Neighbours differ by at most one level here, so sharing chroma per pair loses nothing
        // beyond rounding.
        let rgb = picture(256, 4, 3);
        let back = rgb_from_yuyv(&yuyv_from_rgb(&rgb));
        assert_eq!(back.len(), rgb.len());
        assert!(mean_error(&back, &rgb) < 1.0, "{}", mean_error(&back, &rgb));
    }
}
