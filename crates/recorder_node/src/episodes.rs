//! Episode control: the events teleop (or anyone) publishes on /episode/events as std_msgs/String,
//! and the metadata an episode carries. Pure logic.
//!
//! Events: `start`, optionally followed by a JSON object (`start {"task": "put the cube in the bin",
//! "seed": 3}`), `stop`, `success`, `failure`, `discard` (throw the current episode away) and
//! `rerecord` (discard and start again) and `discard_last` (between episodes: delete the one just
//! closed, to record it again).

use serde::Deserialize;
use so101_core::episode_bag::custom_data;

#[derive(Debug, Clone, PartialEq)]
pub enum EpisodeEvent {
    Start(StartOptions),
    Stop,
    Success,
    Failure,
    Discard,
    Rerecord,
    DiscardLast,
}

/// What a `start` may set for the episode it starts.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartOptions {
    pub task: Option<String>,
    pub seed: Option<i64>,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EventError {
    #[error(
        "unknown episode event {0:?} (expected start, stop, success, failure, discard, rerecord or discard_last)"
    )]
    Unknown(String),
    #[error("bad options after start: {0} (expected a JSON object like {{\"task\": \"...\", \"seed\": 3}})")]
    Options(String),
}

pub fn parse_event(text: &str) -> Result<EpisodeEvent, EventError> {
    let text = text.trim();
    let (word, rest) = text
        .split_once(char::is_whitespace)
        .map_or((text, ""), |(word, rest)| (word, rest.trim()));
    let event = match word.to_ascii_lowercase().as_str() {
        "start" => {
            let options = if rest.is_empty() {
                StartOptions::default()
            } else {
                serde_json::from_str(rest)
                    .map_err(|error| EventError::Options(error.to_string()))?
            };
            return Ok(EpisodeEvent::Start(options));
        }
        "stop" => EpisodeEvent::Stop,
        "success" => EpisodeEvent::Success,
        "failure" => EpisodeEvent::Failure,
        "discard" => EpisodeEvent::Discard,
        "rerecord" => EpisodeEvent::Rerecord,
        "discard_last" => EpisodeEvent::DiscardLast,
        _ => return Err(EventError::Unknown(text.to_owned())),
    };
    if rest.is_empty() {
        Ok(event)
    } else {
        Err(EventError::Unknown(text.to_owned()))
    }
}

/// What is known about one episode; written into its bag.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeInfo {
    pub index: u64,
    pub task: String,
    pub seed: Option<i64>,
    /// Marked by an event or service; otherwise the last /task/success seen, if any.
    pub success: Option<bool>,
    pub start_ns: u64,
    pub stop_ns: Option<u64>,
    /// Samples known lost (sequence gaps, full queue, a failed write).
    pub dropped: u64,
    /// Why the recording failed, if it did (a full disk).
    pub error: Option<String>,
    /// The simulation's /sim/episode settings (JSON: servo model, randomization and its draw);
    /// none on the real arm.
    pub simulation: Option<String>,
}

impl EpisodeInfo {
    /// The key/values of rosbag2's `custom_data` and of the bag's `episode` metadata record.
    pub fn custom_data(&self) -> Vec<(String, String)> {
        let success = match self.success {
            Some(true) => "true",
            Some(false) => "false",
            None => "unknown",
        };
        vec![
            (custom_data::EPISODE_INDEX.into(), self.index.to_string()),
            (custom_data::TASK.into(), self.task.clone()),
            (custom_data::SUCCESS.into(), success.into()),
            (
                custom_data::SEED.into(),
                self.seed.map_or(String::new(), |seed| seed.to_string()),
            ),
            ("start_time_ns".into(), self.start_ns.to_string()),
            (
                "stop_time_ns".into(),
                self.stop_ns.map_or(String::new(), |ns| ns.to_string()),
            ),
            ("dropped_messages".into(), self.dropped.to_string()),
            ("error".into(), self.error.clone().unwrap_or_default()),
            (
                custom_data::SIMULATION.into(),
                self.simulation.clone().unwrap_or_default(),
            ),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_parse_with_optional_start_options() {
        assert_eq!(
            parse_event("start"),
            Ok(EpisodeEvent::Start(StartOptions::default()))
        );
        assert_eq!(
            parse_event(" start {\"task\": \"put the cube in the bin\", \"seed\": 3} "),
            Ok(EpisodeEvent::Start(StartOptions {
                task: Some("put the cube in the bin".into()),
                seed: Some(3)
            }))
        );
        assert_eq!(parse_event("STOP"), Ok(EpisodeEvent::Stop));
        assert_eq!(parse_event("rerecord"), Ok(EpisodeEvent::Rerecord));
        assert_eq!(parse_event("discard_last"), Ok(EpisodeEvent::DiscardLast));
        assert!(matches!(
            parse_event("start {\"colour\": 1}"),
            Err(EventError::Options(_))
        ));
        assert!(matches!(
            parse_event("stop now"),
            Err(EventError::Unknown(_))
        ));
        assert!(matches!(parse_event(""), Err(EventError::Unknown(_))));
    }

    #[test]
    fn custom_data_says_unknown_rather_than_guessing() {
        let info = EpisodeInfo {
            index: 4,
            task: "t".into(),
            seed: None,
            simulation: None,
            success: None,
            start_ns: 10,
            stop_ns: Some(20),
            dropped: 0,
            error: None,
        };
        let data = info.custom_data();
        assert!(data.contains(&("success".into(), "unknown".into())));
        assert!(data.contains(&("seed".into(), String::new())));
        assert!(data.contains(&("stop_time_ns".into(), "20".into())));
    }
}
