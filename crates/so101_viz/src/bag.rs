//! Episode bags (recorder_node's rosbag2 MCAP directories) read back into a [`Bridge`].

use so101_core::{
    bag_read::{decode_cdr, read_messages, ReadError, RECORD_LENGTH_LIMIT},
    episode_bag,
};
use std::path::{Path, PathBuf};

use so101_msgs::geometry_msgs::PoseStamped;
use so101_msgs::sensor_msgs::{CompressedImage, Image, JointState};
use so101_msgs::std_msgs::{Bool, Float64};

use crate::bridge::Bridge;

#[derive(Debug, thiserror::Error)]
pub enum BagError {
    #[error("{0}: no MCAP file (not an episode bag)")]
    NoFiles(PathBuf),
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot log to Rerun: {0}")]
    Log(#[from] rerun::RecordingStreamError),
}

/// What one bag gave.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct BagReport {
    pub messages: u64,
    /// Messages that could not be decoded (logged at debug).
    pub undecodable: u64,
    /// Why a file ended early (a recording cut short leaves a truncated file): what was read
    /// before is kept.
    pub truncated: Option<String>,
}

/// The episode's MCAP files in recording order (so101_core's episode-bag layout); an error when
/// there are none.
pub fn mcap_files(episode: &Path) -> Result<Vec<PathBuf>, BagError> {
    let files = episode_bag::mcap_files(episode).map_err(|error| match error {
        episode_bag::LayoutError::Read { path, source } => BagError::Read { path, source },
        episode_bag::LayoutError::NotFound(path) => BagError::NoFiles(path),
    })?;
    if files.is_empty() {
        return Err(BagError::NoFiles(episode.to_owned()));
    }
    Ok(files)
}

/// Feeds every message of the episode at `episode` to `bridge`, in recording order. Each file is
/// read as a stream (mcap's sans-io reader, chunks decompressed one at a time), so memory does not
/// grow with the episode.
pub fn replay(episode: &Path, bridge: &mut Bridge) -> Result<BagReport, BagError> {
    let mut report = BagReport::default();
    for file in mcap_files(episode)? {
        let read_error = |source: std::io::Error| BagError::Read {
            path: file.clone(),
            source,
        };
        let input = std::fs::File::open(&file).map_err(read_error)?;
        let ended = read_messages(input, RECORD_LENGTH_LIMIT, |topic, data| {
            report.messages += 1;
            if !handle(bridge, topic, data)? {
                report.undecodable += 1;
                tracing::debug!(topic, "undecodable message");
            }
            Ok(())
        })
        .map_err(|error| match error {
            ReadError::Read(source) => read_error(source),
            ReadError::Handler(error) => error,
        })?;
        // A recording cut short ends in a truncated file: what came before is kept.
        if let Some(error) = ended {
            report.truncated = Some(format!("{}: {error}", file.display()));
        }
    }
    Ok(report)
}

/// Hands one message to the bridge by its topic; false when it did not decode.
fn handle(bridge: &mut Bridge, topic: &str, data: &[u8]) -> Result<bool, BagError> {
    let handled = if topic.ends_with("/joint_states") && !topic.ends_with("leader/joint_states") {
        decode_cdr::<JointState>(data).map(|m| bridge.joint_state(&m))
    } else if topic.ends_with("/joint_commands") {
        decode_cdr::<JointState>(data).map(|m| bridge.command(&m))
    } else if topic.ends_with("/cube/pose") {
        decode_cdr::<PoseStamped>(data).map(|m| bridge.cube(&m))
    } else if topic.ends_with("/task/reward") {
        decode_cdr::<Float64>(data).map(|m| bridge.reward(m.data))
    } else if topic.ends_with("/task/success") {
        decode_cdr::<Bool>(data).map(|m| bridge.success(m.data))
    } else if let Some(camera) = camera_name(topic) {
        decode_cdr::<Image>(data).map(|m| bridge.image(camera, &m))
    } else if let Some(camera) = compressed_camera_name(topic) {
        decode_cdr::<CompressedImage>(data).map(|m| bridge.compressed_image(camera, &m))
    } else {
        Some(Ok(()))
    };
    match handled {
        Some(result) => {
            result?;
            Ok(true)
        }
        None => Ok(false),
    }
}

/// `top` of `/camera/top/image_raw` (any namespace before it).
pub fn camera_name(topic: &str) -> Option<&str> {
    let rest = topic.strip_suffix("/image_raw")?;
    let (before, name) = rest.rsplit_once('/')?;
    (before.ends_with("/camera") || before == "camera").then_some(name)
}

/// `top` of `/camera/top/image_raw/compressed` (what the recorder keeps by default).
pub fn compressed_camera_name(topic: &str) -> Option<&str> {
    camera_name(topic.strip_suffix("/compressed")?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_names_come_from_the_topic() {
        assert_eq!(camera_name("/camera/top/image_raw"), Some("top"));
        assert_eq!(camera_name("/left/camera/wrist/image_raw"), Some("wrist"));
        assert_eq!(camera_name("/camera/top/image_raw/compressed"), None);
        assert_eq!(camera_name("/joint_states"), None);
        assert_eq!(
            compressed_camera_name("/camera/top/image_raw/compressed"),
            Some("top")
        );
        assert_eq!(compressed_camera_name("/camera/top/image_raw"), None);
    }
}
