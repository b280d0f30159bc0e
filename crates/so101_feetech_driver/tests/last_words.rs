//! Last words: a panic anywhere in the driver still broadcasts torque off on the bus. Its own test
//! binary, because the panic hook and the line it speaks on are process-wide.

// Test helpers fail loudly: a panic is the right report here.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

mod common;

use so101_feetech_driver::{
    arm::{ArmSettings, CalibrationWrite},
    bus::BusConfig,
    calibration::ArmRole,
    node::{
        controller::{Controller, ControllerConfig},
        emergency,
    },
    protocol::registers as reg,
    safety::SafetyConfig,
};
use so101_servo_emulator::{BusEmulator, InProcessBus, Timing};

#[test]
fn a_panic_broadcasts_torque_off_to_every_servo() {
    let servos = InProcessBus::new(BusEmulator::with_factory_servos(
        &[1, 2, 3, 4, 5, 6],
        Timing::Instant,
        1,
    ));
    let calibration = common::calibration();
    let controller = Controller::start(
        servos.clone(),
        ArmSettings {
            bus: BusConfig {
                slack: Duration::from_millis(3),
                ..BusConfig::default()
            },
            role: ArmRole::Follower,
            gripper_torque_limit: 500,
        },
        calibration,
        ControllerConfig {
            leader: false,
            safety: SafetyConfig {
                max_step: 0.1,
                command_timeout: None,
            },
            torque_at_start: true,
            calibration_write: CalibrationWrite::Allowed,
            reopen_after: Duration::from_secs(1),
            reconnect_interval: Duration::from_millis(100),
            telemetry_period: Duration::from_millis(100),
        },
        std::time::Instant::now(),
    )
    .unwrap();
    let torque = || {
        servos.with_bus(|bus| {
            bus.slots
                .iter()
                .map(|slot| slot.servo.register(reg::TORQUE_ENABLE))
                .collect::<Vec<_>>()
        })
    };
    assert_eq!(torque(), [1; 6]);
    // The node's hook also ends the process afterwards; a test cannot watch that from inside.
    emergency::install_panic_hook(false);
    emergency::set_line(controller.last_words_line());
    let crashed = std::panic::catch_unwind(|| panic!("a bug in the control loop"));
    assert!(crashed.is_err());
    assert_eq!(torque(), [0; 6], "the panic left torque on");
    drop(controller);
}
