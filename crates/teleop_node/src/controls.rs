//! Episode controls from buttons and keys, and how they go out: std_msgs/String on /episode/events
//! (the recorder's interface, docs/recorder_interface.md) and std_srvs/Trigger /sim/reset.

/// One control the operator (or the expert) gives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Control {
    /// Start recording an episode (optionally with its task text and seed).
    Start {
        task: Option<String>,
        seed: Option<u64>,
    },
    Stop,
    /// Start if nothing is being recorded, else stop.
    ToggleRecording,
    MarkSuccess,
    MarkFailure,
    /// Drop the running episode and start it again.
    Rerecord,
    /// /sim/reset: a new episode of the simulation.
    ResetSim,
    /// Joint <-> Cartesian.
    ToggleMode,
    /// Stop moving (hold the current targets).
    Halt,
    Quit,
}

/// The /episode/events text of a control, or `None` for controls that are not episode events.
/// `recording` says whether an episode is being recorded (for [`Control::ToggleRecording`]).
pub fn event_text(control: &Control, recording: bool) -> Option<String> {
    match control {
        Control::Start { task, seed } => Some(start_text(task.as_deref(), *seed)),
        Control::ToggleRecording if recording => Some("stop".into()),
        Control::ToggleRecording => Some("start".into()),
        Control::Stop => Some("stop".into()),
        Control::MarkSuccess => Some("success".into()),
        Control::MarkFailure => Some("failure".into()),
        Control::Rerecord => Some("rerecord".into()),
        Control::ResetSim | Control::ToggleMode | Control::Halt | Control::Quit => None,
    }
}

/// `start`, followed by a JSON object with the task and seed when there are any.
fn start_text(task: Option<&str>, seed: Option<u64>) -> String {
    let mut details = serde_json::Map::new();
    if let Some(task) = task {
        details.insert("task".into(), task.into());
    }
    if let Some(seed) = seed {
        details.insert("seed".into(), seed.into());
    }
    if details.is_empty() {
        "start".into()
    } else {
        format!("start {}", serde_json::Value::Object(details))
    }
}

/// Whether an episode is being recorded after `control` (starting from `recording`).
pub fn recording_after(control: &Control, recording: bool) -> bool {
    match control {
        Control::Start { .. } | Control::Rerecord => true,
        Control::Stop => false,
        Control::ToggleRecording => !recording,
        _ => recording,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn controls_become_the_recorders_event_words() {
        assert_eq!(
            event_text(&Control::ToggleRecording, false).as_deref(),
            Some("start")
        );
        assert_eq!(
            event_text(&Control::ToggleRecording, true).as_deref(),
            Some("stop")
        );
        assert_eq!(
            event_text(&Control::MarkSuccess, true).as_deref(),
            Some("success")
        );
        assert_eq!(
            event_text(&Control::MarkFailure, true).as_deref(),
            Some("failure")
        );
        assert_eq!(
            event_text(&Control::Rerecord, true).as_deref(),
            Some("rerecord")
        );
        assert_eq!(event_text(&Control::ResetSim, true), None);
        let start = Control::Start {
            task: Some("put the cube in the bin".into()),
            seed: Some(4),
        };
        let text = event_text(&start, false).unwrap();
        let json: serde_json::Value =
            serde_json::from_str(text.strip_prefix("start ").unwrap()).unwrap();
        assert_eq!(json["task"], "put the cube in the bin");
        assert_eq!(json["seed"], 4);
    }

    #[test]
    fn recording_state_follows_the_controls() {
        assert!(recording_after(&Control::ToggleRecording, false));
        assert!(!recording_after(&Control::ToggleRecording, true));
        assert!(recording_after(&Control::Rerecord, false));
        assert!(!recording_after(&Control::Stop, true));
        assert!(recording_after(&Control::MarkSuccess, true));
    }
}
