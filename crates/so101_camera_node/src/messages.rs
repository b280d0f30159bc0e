//! The node's message contents that are pure: CameraInfo of a calibrated or uncalibrated camera,
//! and capture instants as stamps.

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

/// A stamp of a time since the epoch (saturating, as `Time::from_nanos` does).
pub fn stamp_of(since_epoch: Duration) -> Time {
    Time::from_nanos(i64::try_from(since_epoch.as_nanos()).unwrap_or(i64::MAX))
}
