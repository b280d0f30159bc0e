//! SimClock against a real rosgraph_msgs/Clock publisher over DDS (two participants, one process).
//! Opens DDS participants: runs only inside a loopback-only network namespace (scripts/test.sh
//! runs cargo test inside scripts/isolated).

use std::time::{Duration, Instant};

use so101_core::ros::{clock::SimClock, qos, shutdown::Shutdown, NodeArgs, RosNode};
use so101_msgs::{builtin_interfaces::Time, rosgraph_msgs::Clock};

/// Refuses to open a DDS participant where multicast could leave the machine.
fn assert_in_loopback_only_namespace() {
    assert!(
        so101_core::ros::context::only_loopback(),
        "DDS tests must run inside a loopback-only network namespace: scripts/isolated cargo test"
    );
}

#[test]
fn sim_clock_follows_a_standard_clock_publisher() {
    assert_in_loopback_only_namespace();
    let args = NodeArgs {
        namespace: Some("clock_test".into()),
    };
    let mut source = RosNode::start("clock_source", &args).unwrap();
    let publisher = source
        .publisher::<Clock>("clock", qos::default_topic())
        .unwrap();
    let mut listener = RosNode::start("clock_listener", &args).unwrap();
    let shutdown = Shutdown::new();
    let clock = SimClock::subscribe(&mut listener, shutdown.clone()).unwrap();
    assert_eq!(clock.now(), None, "no time before the first /clock message");

    let deadline = Instant::now() + Duration::from_secs(15);
    for expected in [
        Time {
            sec: 5,
            nanosec: 250,
        },
        Time { sec: 7, nanosec: 0 },
    ] {
        while clock.now() != Some(expected) {
            assert!(
                Instant::now() < deadline,
                "SimClock never saw {expected:?} (has {:?})",
                clock.now()
            );
            publisher.publish(Clock { clock: expected }).unwrap();
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    shutdown.request();
}
