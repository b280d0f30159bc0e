//! What each camera's thread counts, read once a second for /diagnostics. Pure.

use so101_msgs::diagnostic_msgs::{DiagnosticStatus, KeyValue};

use crate::controls::ControlKind;

/// One camera's counters and state.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CameraStatus {
    pub name: String,
    pub device: String,
    /// The mode it streams in, or why it does not.
    pub state: String,
    pub streaming: bool,
    /// Frames published.
    pub frames: u64,
    /// Frames lost in the device (gaps in its sequence numbers).
    pub device_drops: u64,
    /// Frames dropped here because they were not a whole JPEG.
    pub broken_frames: u64,
    /// Waits for a frame that timed out (a stalled camera).
    pub timeouts: u64,
    /// Times the camera went away.
    pub unplugs: u64,
    /// Capture to publish of the last frame, ms.
    pub latency_ms: f64,
    /// The image controls as the camera reports them (-1: automatic).
    pub controls: Vec<(ControlKind, i64)>,
}

/// The diagnostic status of a camera, with its frame rate over the last report period.
pub fn diagnostic(status: &CameraStatus, fps: f64) -> DiagnosticStatus {
    let (level, message) = if !status.streaming {
        (DiagnosticStatus::ERROR, status.state.clone())
    } else if fps == 0.0 {
        (
            DiagnosticStatus::WARN,
            "no frame in the last report period (stalled)".to_owned(),
        )
    } else {
        (DiagnosticStatus::OK, "streaming".to_owned())
    };
    let value = |key: &str, value: String| KeyValue {
        key: key.to_owned(),
        value,
    };
    let mut values = vec![
        value("mode", status.state.clone()),
        value("fps", format!("{fps:.2}")),
        value("frames", status.frames.to_string()),
        value("device_drops", status.device_drops.to_string()),
        value("broken_frames", status.broken_frames.to_string()),
        value("timeouts", status.timeouts.to_string()),
        value("unplugs", status.unplugs.to_string()),
        value("latency_ms", format!("{:.2}", status.latency_ms)),
    ];
    values.extend(
        status
            .controls
            .iter()
            .map(|(kind, setting)| value(kind.key(), setting.to_string())),
    );
    DiagnosticStatus {
        level,
        name: format!("so101_camera_node: {}", status.name),
        message,
        hardware_id: status.device.clone(),
        values,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_say_streaming_stalled_or_gone() {
        let mut status = CameraStatus {
            name: "top".into(),
            streaming: true,
            state: "MJPG 640x480@30".into(),
            ..CameraStatus::default()
        };
        assert_eq!(diagnostic(&status, 30.0).level, DiagnosticStatus::OK);
        assert_eq!(diagnostic(&status, 0.0).level, DiagnosticStatus::WARN);
        status.streaming = false;
        status.state = "unplugged: reopening".into();
        let gone = diagnostic(&status, 0.0);
        assert_eq!(gone.level, DiagnosticStatus::ERROR);
        assert_eq!(gone.message, "unplugged: reopening");
        assert_eq!(gone.name, "so101_camera_node: top");
    }
}
