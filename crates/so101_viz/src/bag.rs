//! Episode bags (recorder_node's rosbag2 MCAP directories) read back into a [`Bridge`].

use so101_core::episode_bag;
use std::{
    collections::HashMap,
    io::Read,
    path::{Path, PathBuf},
};

use byteorder::{BigEndian, LittleEndian};
use mcap::{
    records::Record,
    sans_io::linear_reader::{LinearReadEvent, LinearReader},
};
use serde::de::DeserializeOwned;
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

/// A CDR payload (4-byte encapsulation header, then the data) as `T`.
fn decode<T: DeserializeOwned>(data: &[u8]) -> Option<T> {
    let (header, payload) = (data.get(..4)?, data.get(4..)?);
    let decoded = match header[1] {
        0x01 => cdr_encoding::from_bytes::<T, LittleEndian>(payload),
        0x00 => cdr_encoding::from_bytes::<T, BigEndian>(payload),
        _ => return None,
    };
    decoded.ok().map(|(value, _)| value)
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
        let mut input = std::fs::File::open(&file).map_err(read_error)?;
        let mut reader = LinearReader::new();
        // Channel id -> topic, as the file declares them before their messages.
        let mut topics: HashMap<u16, String> = HashMap::new();
        while let Some(event) = reader.next_event() {
            let record = match event {
                Ok(LinearReadEvent::ReadRequest(wanted)) => {
                    let read = input.read(reader.insert(wanted)).map_err(read_error)?;
                    reader.notify_read(read);
                    continue;
                }
                Ok(LinearReadEvent::Record { data, opcode }) => mcap::parse_record(opcode, data),
                Err(error) => Err(error),
            };
            match record {
                Ok(Record::Channel(channel)) => {
                    topics.insert(channel.id, channel.topic);
                }
                Ok(Record::Message { header, data }) => {
                    report.messages += 1;
                    let topic = topics.get(&header.channel_id).map_or("", String::as_str);
                    if !handle(bridge, topic, &data)? {
                        report.undecodable += 1;
                        tracing::debug!(topic, "undecodable message");
                    }
                }
                Ok(_) => {}
                Err(error) => {
                    // A recording cut short ends in a truncated file: what came before is kept.
                    report.truncated = Some(format!("{}: {error}", file.display()));
                    break;
                }
            }
        }
    }
    Ok(report)
}

/// Hands one message to the bridge by its topic; false when it did not decode.
fn handle(bridge: &mut Bridge, topic: &str, data: &[u8]) -> Result<bool, BagError> {
    let handled = if topic.ends_with("/joint_states") && !topic.ends_with("leader/joint_states") {
        decode::<JointState>(data).map(|m| bridge.joint_state(&m))
    } else if topic.ends_with("/joint_commands") {
        decode::<JointState>(data).map(|m| bridge.command(&m))
    } else if topic.ends_with("/cube/pose") {
        decode::<PoseStamped>(data).map(|m| bridge.cube(&m))
    } else if topic.ends_with("/task/reward") {
        decode::<Float64>(data).map(|m| bridge.reward(m.data))
    } else if topic.ends_with("/task/success") {
        decode::<Bool>(data).map(|m| bridge.success(m.data))
    } else if let Some(camera) = camera_name(topic) {
        decode::<Image>(data).map(|m| bridge.image(camera, &m))
    } else if let Some(camera) = compressed_camera_name(topic) {
        decode::<CompressedImage>(data).map(|m| bridge.compressed_image(camera, &m))
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

    #[test]
    fn a_cdr_payload_decodes_into_the_message() {
        let state = JointState {
            name: vec!["gripper".into()],
            position: vec![0.5],
            ..Default::default()
        };
        let mut bytes = vec![0x00, 0x01, 0x00, 0x00];
        bytes.extend(cdr_encoding::to_vec::<_, LittleEndian>(&state).expect("encodes"));
        assert_eq!(decode::<JointState>(&bytes), Some(state));
        assert_eq!(decode::<JointState>(&bytes[..6]), None);
    }
}
