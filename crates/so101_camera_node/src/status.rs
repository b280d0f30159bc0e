//! What each camera's thread counts, read once a second for /diagnostics. Pure.

use so101_msgs::diagnostic_msgs::{DiagnosticStatus, KeyValue};

use std::{collections::VecDeque, time::Duration};

use crate::controls::ControlKind;

/// Latencies kept for the summary: five and a half minutes at 30 fps.
pub const LATENCY_SAMPLES: usize = 10_000;

impl CameraStatus {
    /// Counts one published frame, captured `latency_ms` before it went out.
    pub fn published(&mut self, latency_ms: f64) {
        self.frames += 1;
        self.latency_ms = latency_ms;
        if self.latencies_ms.len() == LATENCY_SAMPLES {
            self.latencies_ms.pop_front();
        }
        self.latencies_ms.push_back(latency_ms);
    }

    /// Counts one published frame whose capture instant lies after the node's clock reading: the
    /// driver's timestamps are not start-of-capture on CLOCK_MONOTONIC (end-of-frame stamps, or
    /// another clock). Its latency is unknown, not zero.
    pub fn published_stamped_ahead(&mut self) {
        self.frames += 1;
        self.stamped_ahead += 1;
    }

    /// Counts `missed` frames (a gap in the device's sequence before a frame), blaming the node
    /// when that frame had waited more than a frame period to be taken (`behind`): the driver
    /// drops a frame when every buffer is full because the node is slow, and a camera or USB
    /// loss leaves the next frame fresh.
    pub fn missed(&mut self, missed: u32, behind: bool) {
        if behind {
            self.node_drops += u64::from(missed);
        } else {
            self.device_drops += u64::from(missed);
        }
    }
}

/// `values` in ascending order, for [`quantile`].
pub fn sorted(values: impl IntoIterator<Item = f64>) -> Vec<f64> {
    let mut sorted: Vec<f64> = values.into_iter().collect();
    sorted.sort_by(f64::total_cmp);
    sorted
}

/// The `q` quantile (0..=1, nearest rank) of ascending `sorted` values, or None for none.
pub fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    let last = sorted.len().checked_sub(1)?;
    Some(sorted[((last as f64) * q).round() as usize])
}

/// One line on a camera's run, printed at exit: what a user checks a camera with.
pub fn summary(status: &CameraStatus, elapsed: Duration) -> String {
    let seconds = elapsed.as_secs_f64().max(1e-9);
    let latencies = sorted(status.latencies_ms.iter().copied());
    let latency = match (quantile(&latencies, 0.5), quantile(&latencies, 0.99)) {
        (Some(p50), Some(p99)) => format!("latency p50 {p50:.1} ms, p99 {p99:.1} ms"),
        _ => "no latency (no frame)".to_owned(),
    };
    let ahead = if status.stamped_ahead > 0 {
        format!(
            " ({} frames stamped after the node's clock: not measured)",
            status.stamped_ahead
        )
    } else {
        String::new()
    };
    format!(
        "{}: {} frames in {seconds:.1} s ({:.1} fps), {} dropped by the camera or USB, {} dropped while the node was behind, {} broken, {} late, {} stalls, {} unplugs, {} stream errors; capture to publish {latency}{ahead}",
        status.name,
        status.frames,
        status.frames as f64 / seconds,
        status.device_drops,
        status.node_drops,
        status.broken_frames,
        status.late_frames,
        status.timeouts,
        status.unplugs,
        status.stream_errors,
    )
}

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
    /// Frames lost in the camera or on USB (gaps in its sequence numbers before a fresh frame).
    pub device_drops: u64,
    /// Frames the driver dropped while the node was behind (gaps before a frame that had waited).
    pub node_drops: u64,
    /// Frames published more than a frame period after their capture.
    pub late_frames: u64,
    /// Frames dropped here: marked damaged by the driver, or not a whole JPEG.
    pub broken_frames: u64,
    /// Waits for a frame that timed out (a stalled camera).
    pub timeouts: u64,
    /// Times the camera went away.
    pub unplugs: u64,
    /// Times the stream failed with the camera still there (EIO) and was started again.
    pub stream_errors: u64,
    /// Frames whose capture instant lay after the node's clock (latency not measured).
    pub stamped_ahead: u64,
    /// Capture to publish of the last frame, ms (late: over a frame period).
    pub latency_ms: f64,
    /// Capture to publish of the latest frames (up to [`LATENCY_SAMPLES`]), ms, for the summary.
    pub latencies_ms: VecDeque<f64>,
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
        value("node_drops", status.node_drops.to_string()),
        value("broken_frames", status.broken_frames.to_string()),
        value("late_frames", status.late_frames.to_string()),
        value("timeouts", status.timeouts.to_string()),
        value("unplugs", status.unplugs.to_string()),
        value("stream_errors", status.stream_errors.to_string()),
        value("stamped_ahead", status.stamped_ahead.to_string()),
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

    #[test]
    fn the_summary_says_rate_losses_and_latency_quantiles() {
        let mut status = CameraStatus {
            name: "top".into(),
            device_drops: 2,
            ..CameraStatus::default()
        };
        for latency in 1..=100 {
            status.published(f64::from(latency));
        }
        let line = summary(&status, Duration::from_secs(4));
        assert!(
            line.starts_with("top: 100 frames in 4.0 s (25.0 fps), 2 dropped by the camera or USB, 0 dropped while the node was behind"),
            "{line}"
        );
        assert!(!line.contains("stamped after"), "{line}");
        assert!(line.contains("latency p50 51.0 ms, p99 99.0 ms"), "{line}");
        let idle = summary(&CameraStatus::default(), Duration::from_secs(1));
        assert!(idle.contains("no latency"), "{idle}");
        for latency in 0..LATENCY_SAMPLES + 5 {
            status.published(latency as f64);
        }
        assert_eq!(status.latencies_ms.len(), LATENCY_SAMPLES);
    }

    #[test]
    fn a_gap_before_a_frame_that_waited_is_the_node_s_and_a_frame_stamped_ahead_has_no_latency() {
        let mut status = CameraStatus::default();
        status.missed(2, false);
        status.missed(3, true);
        assert_eq!((status.device_drops, status.node_drops), (2, 3));
        status.published_stamped_ahead();
        assert_eq!((status.frames, status.stamped_ahead), (1, 1));
        assert!(
            status.latencies_ms.is_empty(),
            "no latency of 0 ms is made up"
        );
        let line = summary(&status, Duration::from_secs(1));
        assert!(
            line.contains("3 dropped while the node was behind"),
            "{line}"
        );
        assert!(
            line.contains("1 frames stamped after the node's clock"),
            "{line}"
        );
    }
}
