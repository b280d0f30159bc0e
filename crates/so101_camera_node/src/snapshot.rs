//! `--snapshot DIR`: one still of each camera, saved as DIR/NAME/<seconds since 1970>.jpg, then
//! exit. Taken after the camera has streamed for a while (automatic exposure and white balance
//! settle in that time), with the node's mode and controls: the empty workspace the simulation
//! shows behind the arm (the randomization's `backgrounds`, docs/sim_to_real.md).

use std::{
    fs,
    path::{Path, PathBuf},
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

use anyhow::{bail, Context, Result};

use crate::{
    decode::{jpeg_from_rgb, rgb_from_yuyv},
    device::{CameraStream, CaptureError, Frame},
    jpeg::whole_jpeg,
    modes::PixelFormat,
};

/// How long a camera streams before its still is taken.
pub const SETTLE: Duration = Duration::from_millis(1500);

/// The JPEG of the last whole frame `stream` delivers within `settle` (at least one frame).
pub fn take(stream: &mut dyn CameraStream, settle: Duration, jpeg_quality: u8) -> Result<Vec<u8>> {
    let started = Instant::now();
    let mut last = None;
    while last.is_none() || started.elapsed() < settle {
        match stream.next_frame(Duration::from_millis(500)) {
            Ok(frame) => {
                if let Some(jpeg) = jpeg_of(&frame, jpeg_quality) {
                    last = Some(jpeg);
                }
            }
            // A damaged or missed frame: the next one will do.
            Err(CaptureError::Damaged { .. } | CaptureError::Timeout(_)) => {}
            Err(error) => bail!("{error}"),
        }
        if last.is_none() && started.elapsed() > settle + Duration::from_secs(5) {
            bail!("no whole frame in {:?}", started.elapsed());
        }
    }
    last.context("no frame")
}

/// The frame as JPEG: a camera's own JPEG unchanged, a YUYV frame encoded; None when broken.
fn jpeg_of(frame: &Frame, quality: u8) -> Option<Vec<u8>> {
    match frame.format {
        PixelFormat::Mjpeg => whole_jpeg(&frame.data).map(<[u8]>::to_vec),
        PixelFormat::Yuyv => jpeg_from_rgb(
            &rgb_from_yuyv(&frame.data, frame.yuv_range),
            frame.width,
            frame.height,
            quality,
        )
        .ok(),
    }
}

/// Writes `jpeg` as `dir/camera/<seconds>.jpg`; returns its path.
pub fn save(dir: &Path, camera: &str, jpeg: &[u8], at: SystemTime) -> Result<PathBuf> {
    let folder = dir.join(camera);
    fs::create_dir_all(&folder).with_context(|| format!("cannot make {}", folder.display()))?;
    let seconds = at.duration_since(UNIX_EPOCH).unwrap_or_default().as_secs();
    let path = folder.join(format!("{seconds}.jpg"));
    fs::write(&path, jpeg).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        device::CameraDevice,
        fake::{FakeCamera, FakeSettings},
        modes,
    };

    fn still(settings: &str) -> Vec<u8> {
        let settings: FakeSettings = settings.parse().unwrap();
        let mut camera = FakeCamera::new(settings);
        let mode = modes::choose(&camera.modes().unwrap(), None, None).unwrap();
        let mut stream = camera.open(mode).unwrap();
        take(stream.as_mut(), Duration::from_millis(200), 90).unwrap()
    }

    #[test]
    fn a_still_is_a_whole_jpeg_of_the_cameras_mode() {
        for settings in ["64x48@50", "yuyv,64x48@50", "64x48@50,truncate_every=2"] {
            let jpeg = still(settings);
            assert!(whole_jpeg(&jpeg).is_some(), "{settings}");
            let rgb = crate::decode::rgb_from_jpeg(&jpeg, 64, 48).unwrap();
            assert_eq!(rgb.len(), 64 * 48 * 3);
        }
    }

    #[test]
    fn stills_go_in_a_folder_per_camera() {
        let dir = std::env::temp_dir().join(format!("so101_snapshot_{}", std::process::id()));
        let at = UNIX_EPOCH + Duration::from_secs(1_795_753_018);
        let path = save(&dir, "top", b"jpeg", at).unwrap();
        assert_eq!(path, dir.join("top").join("1795753018.jpg"));
        assert_eq!(fs::read(&path).unwrap(), b"jpeg");
        fs::remove_dir_all(&dir).unwrap();
    }
}
