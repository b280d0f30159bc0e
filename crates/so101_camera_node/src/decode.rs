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

/// How a camera's YUYV samples span their bytes. USB cameras (UVC) and V4L2 drivers send limited
/// range unless they say otherwise; JPEG's own YCbCr is full range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum YuvRange {
    /// Luma 16..=235, chroma 16..=240 (ITU-R BT.601 "studio swing").
    Limited,
    /// Every sample 0..=255.
    Full,
}

/// rgb8 of packed YUYV 4:2:2 (BT.601) in the given range. Fixed point (16 fractional bits): it
/// runs for every frame of a YUYV camera, on small computers too.
pub fn rgb_from_yuyv(yuyv: &[u8], range: YuvRange) -> Vec<u8> {
    // BT.601's matrix, limited range stretched to full first: luma offset and scale, then the
    // chroma terms for R (Cr), G (Cb, Cr) and B (Cb), each times 65536.
    let (luma_offset, luma, r_cr, g_cb, g_cr, b_cb) = match range {
        YuvRange::Limited => (16, 76_309, 104_597, 25_675, 53_279, 132_201),
        YuvRange::Full => (0, 65_536, 91_881, 22_554, 46_802, 116_130),
    };
    let byte = |value: i32| ((value + 32_768) >> 16).clamp(0, 255) as u8;
    let mut rgb = Vec::with_capacity(yuyv.len() / 2 * 3);
    for group in yuyv.chunks_exact(4) {
        let (cb, cr) = (i32::from(group[1]) - 128, i32::from(group[3]) - 128);
        let (red, green, blue) = (r_cr * cr, -g_cb * cb - g_cr * cr, b_cb * cb);
        for sample in [group[0], group[2]] {
            let y = (i32::from(sample) - luma_offset) * luma;
            rgb.extend([byte(y + red), byte(y + green), byte(y + blue)]);
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
        // beyond rounding (and limited range's 219 luma levels).
        let rgb = picture(256, 4, 3);
        let back = rgb_from_yuyv(&yuyv_from_rgb(&rgb), YuvRange::Limited);
        assert_eq!(back.len(), rgb.len());
        assert!(mean_error(&back, &rgb) < 1.0, "{}", mean_error(&back, &rgb));
    }

    #[test]
    fn limited_range_black_and_white_are_black_and_white() {
        // What a UVC camera or vivid sends for black, 75 % white and white (Y, Cb, Y, Cr).
        let rgb = |y: u8| rgb_from_yuyv(&[y, 128, y, 128], YuvRange::Limited)[0];
        assert_eq!(rgb(16), 0);
        assert_eq!(rgb(180), 191);
        assert_eq!(rgb(235), 255);
        // Limited-range red (Y 81, Cb 90, Cr 240) is red, not a washed-out one.
        let red = rgb_from_yuyv(&[81, 90, 81, 240], YuvRange::Limited);
        assert!(red[0] >= 254 && red[1] <= 1 && red[2] <= 1, "{red:?}");
        assert_eq!(rgb_from_yuyv(&[16, 128, 16, 128], YuvRange::Full)[0], 16);
    }
}
