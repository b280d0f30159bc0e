//! Whether the recorder receives every stream it records: each publisher it has discovered on a
//! topic it records has been matched by its reader (or refused, for a QoS the reader cannot
//! take). A timed session begins its first episode only then, so that the episode holds every
//! stream from its start. Pure logic.

use so101_msgs::std_srvs::TriggerResponse;

/// How far the recorder is with one discovered publisher of a topic it records.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reception {
    /// The topic has no reader yet (the next discovery makes one).
    NotSubscribed,
    /// The reader has not matched this publisher yet: its samples would be lost.
    Matching,
    /// Matched (or refused for its QoS, which waiting would not change).
    Settled,
}

/// The topics with a publisher the recorder does not receive yet, sorted, each once.
pub fn waiting_topics<'a>(
    publishers: impl IntoIterator<Item = (&'a str, Reception)>,
) -> Vec<&'a str> {
    let mut waiting: Vec<&str> = publishers
        .into_iter()
        .filter(|(_, reception)| *reception != Reception::Settled)
        .map(|(topic, _)| topic)
        .collect();
    waiting.sort_unstable();
    waiting.dedup();
    waiting
}

/// The answer of /recorder/ready.
pub fn answer(waiting: &[&str]) -> TriggerResponse {
    if waiting.is_empty() {
        TriggerResponse {
            success: true,
            message: "receiving every publisher of the recorded topics".into(),
        }
    } else {
        TriggerResponse {
            success: false,
            message: format!("not receiving yet: {}", waiting.join(", ")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_topic_waits_while_any_of_its_publishers_is_not_matched() {
        let publishers = [
            ("/joint_states", Reception::Settled),
            ("/camera/top/image_raw/compressed", Reception::Matching),
            ("/joint_states", Reception::Matching),
            ("/cube/pose", Reception::NotSubscribed),
            ("/camera/top/image_raw/compressed", Reception::Matching),
            ("/diagnostics", Reception::Settled),
        ];
        assert_eq!(
            waiting_topics(publishers),
            [
                "/camera/top/image_raw/compressed",
                "/cube/pose",
                "/joint_states"
            ]
        );
    }

    #[test]
    fn the_answer_names_the_topics_still_waiting() {
        let ready = answer(&[]);
        assert!(ready.success, "{}", ready.message);
        let waiting = answer(&["/cube/pose", "/joint_states"]);
        assert!(!waiting.success);
        assert_eq!(
            waiting.message,
            "not receiving yet: /cube/pose, /joint_states"
        );
    }
}
