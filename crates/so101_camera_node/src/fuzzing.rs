//! The bodies of the cargo-fuzz targets (fuzz/) over the camera node's parsers of outside input,
//! shared with the corpus replay test (tests/fuzz_corpus.rs) so the two cannot drift. Each takes
//! the raw fuzzer input, never panics on any input, and asserts what the parser promises.

use crate::{
    calibration,
    decode::rgb_from_jpeg,
    jpeg::whole_jpeg,
    request::{CameraRequest, DeviceName},
};

/// The stream size the JPEG target decodes at (its seed frames have it).
pub const JPEG_WIDTH: u32 = 64;
pub const JPEG_HEIGHT: u32 = 48;

/// A camera_calibration YAML file: an accepted one has matrices of the shapes CameraInfo needs
/// and holds for its own image size.
pub fn calibration_yaml(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(intrinsics) = calibration::parse(text) else {
        return;
    };
    assert!(intrinsics.width > 0 && intrinsics.height > 0);
    assert_eq!(
        intrinsics.check_size(intrinsics.width, intrinsics.height),
        Ok(())
    );
}

/// A `--camera` argument: an accepted one has a ROS name, sizes and rates in range, and written
/// back in the same syntax it parses to the same request.
pub fn camera_request(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(request) = text.parse::<CameraRequest>() else {
        return;
    };
    assert!(request.name.starts_with(|c: char| c.is_ascii_alphabetic()));
    if let Some((width, height)) = request.size {
        assert!((1..=8192).contains(&width) && (1..=8192).contains(&height));
    }
    if let Some(fps) = request.fps {
        assert!(fps > 0.0 && fps <= 1000.0);
    }
    let mut written = format!("{}={}", request.name, request.device);
    if !matches!(request.device, DeviceName::Fake(_)) {
        if let Some((width, height)) = request.size {
            written.push_str(&format!(":{width}x{height}"));
        }
        if let Some(fps) = request.fps {
            written.push_str(&format!("@{fps}"));
        }
    }
    assert_eq!(
        written.parse::<CameraRequest>().as_ref(),
        Ok(&request),
        "{written}"
    );
}

/// A camera buffer of an MJPEG stream: what the whole-JPEG check keeps is the buffer up to its
/// EOI with only zero padding after it, and decoding it (as image_raw does) never panics and
/// gives a frame of the stream's size.
pub fn whole_jpeg_frame(data: &[u8]) {
    let Some(jpeg) = whole_jpeg(data) else {
        return;
    };
    assert!(jpeg.starts_with(&[0xFF, 0xD8]) && jpeg.ends_with(&[0xFF, 0xD9]));
    assert!(data.starts_with(jpeg));
    assert!(data[jpeg.len()..].iter().all(|&byte| byte == 0));
    if let Ok(rgb) = rgb_from_jpeg(jpeg, JPEG_WIDTH, JPEG_HEIGHT) {
        assert_eq!(rgb.len(), (JPEG_WIDTH * JPEG_HEIGHT * 3) as usize);
    }
}
