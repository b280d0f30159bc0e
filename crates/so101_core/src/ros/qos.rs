//! QoS presets that match what rclpy users get by default, so every rclpy peer connects.

use ros2_client::{
    qos::{Durability, History, Reliability, WhenFull},
    QosProfile,
};

/// rclpy's default for publishers and subscriptions given a depth of 10: reliable, volatile,
/// keep last 10. ros2-client's own defaults differ (depth 1, best-effort subscriptions).
pub fn reliable(depth: usize) -> QosProfile {
    QosProfile::publisher_default()
        .reliability(Reliability::Reliable {
            when_full: WhenFull::DEFAULT,
        })
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth })
}

/// The default topic QoS of the stack (= `rclpy` `qos_profile=10`).
pub fn default_topic() -> QosProfile {
    reliable(10)
}

/// Command subscriptions keep a longer queue so a burst from a teleop or policy is not dropped
/// before the control loop reads it.
pub fn command_subscription() -> QosProfile {
    reliable(100)
}

/// Latched: reliable, transient local, keep last 1, as robot_state_publisher offers
/// /robot_description and tf2 /tf_static: a peer that joins later still gets the last message.
pub fn latched() -> QosProfile {
    QosProfile::publisher_default()
        .reliability(Reliability::Reliable {
            when_full: WhenFull::DEFAULT,
        })
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 1 })
}

/// rclpy's service default (rmw_qos_profile_services_default): reliable, volatile, keep last 10.
pub fn service() -> QosProfile {
    reliable(10)
}
