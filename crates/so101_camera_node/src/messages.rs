//! The node's message contents that are pure: CameraInfo of a calibrated or uncalibrated camera,
//! and stamps.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use so101_msgs::{
    builtin_interfaces::Time,
    sensor_msgs::{CameraInfo, RegionOfInterest},
    std_msgs::Header,
};

use crate::calibration::Intrinsics;

/// CameraInfo of a frame: the calibration's matrices where the camera has one (its size checked
/// at start), else every matrix zero, what ROS tools read as "not calibrated".
pub fn camera_info(
    header: Header,
    width: u32,
    height: u32,
    intrinsics: Option<&Intrinsics>,
) -> CameraInfo {
    let (distortion_model, d, k, r, p) = match intrinsics {
        Some(calibration) => (
            calibration.distortion_model.clone(),
            calibration.d.clone(),
            calibration.k,
            calibration.r,
            calibration.p,
        ),
        None => (String::new(), Vec::new(), [0.0; 9], [0.0; 9], [0.0; 12]),
    };
    CameraInfo {
        header,
        height,
        width,
        distortion_model,
        d,
        k,
        r,
        p,
        binning_x: 0,
        binning_y: 0,
        roi: RegionOfInterest::default(),
    }
}

pub fn now_since_epoch() -> Duration {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default()
}

pub fn stamp_of(since_epoch: Duration) -> Time {
    Time {
        sec: i32::try_from(since_epoch.as_secs()).unwrap_or(i32::MAX),
        nanosec: since_epoch.subsec_nanos(),
    }
}
