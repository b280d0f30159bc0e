//! The driver's bus side against the servo emulator over a real pseudo-terminal, opened with the
//! serialport crate exactly as a USB adapter is: handshake and configuration, reads and writes,
//! every fault class, reconnection, calibration and motor set-up.

// Test helpers fail loudly: a panic is the right report here.
#![allow(clippy::unwrap_used)]

use std::{
    path::PathBuf,
    time::{Duration, Instant},
};

mod common;

use common::calibration;
use so101_feetech_driver::{
    args::{is_pseudo_terminal, PortArgs, ADAPTER_SLACK_MS, PSEUDO_TERMINAL_SLACK_MS},
    arm::{open_bus, Arm, ArmSettings, CalibrationWrite, ServoInfo},
    bus::{BusConfig, BusError},
    calibration::{ArmCalibration, ArmRole},
    protocol::registers,
    tools::{
        calibrate::{CalibrateError, Calibration},
        scan::{find_servos, probe_config},
        setup_motors::{assign, SetupError},
    },
};
use so101_servo_emulator::{Emulator, EmulatorConfig, SlotSnapshot, Timing};

struct Bench {
    emulator: Emulator,
    _dir: tempfile::TempDir,
    link: PathBuf,
}

fn emulator(config: EmulatorConfig) -> Bench {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("bus");
    let emulator = Emulator::start(EmulatorConfig {
        link: Some(link.clone()),
        ..config
    })
    .unwrap();
    Bench {
        emulator,
        _dir: dir,
        link,
    }
}

fn settings(retries: u32) -> ArmSettings {
    ArmSettings {
        bus: BusConfig {
            retries,
            slack: Duration::from_millis(5),
            ..BusConfig::default()
        },
        role: ArmRole::Follower,
        gripper_torque_limit: 500,
    }
}

/// The arm on the bench's emulator, configured and calibrated (the servos start from the factory).
fn connect(bench: &Bench, retries: u32) -> Arm {
    Arm::connect(
        &bench.link,
        &settings(retries),
        calibration(),
        CalibrationWrite::Allowed,
    )
    .unwrap()
}

fn slot(bench: &Bench, index: usize) -> SlotSnapshot {
    bench.emulator.snapshot()[index].clone()
}

fn control(bench: &Bench, line: &str) {
    bench.emulator.control_line(line).unwrap();
}

#[test]
fn a_pseudo_terminal_gets_the_slack_of_a_process_and_an_adapter_the_default() {
    let bench = emulator(EmulatorConfig::default());
    let ports = |port: PathBuf, slack: Option<f64>| PortArgs {
        port,
        baud: 1_000_000,
        retries: 2,
        bus_slack_ms: slack,
    };
    // The emulator's link, followed to /dev/pts/N.
    assert!(is_pseudo_terminal(&bench.link));
    let emulated = ports(bench.link.clone(), None);
    assert_eq!(emulated.bus_slack_ms(), PSEUDO_TERMINAL_SLACK_MS);
    assert_eq!(emulated.bus_config().slack, Duration::from_millis(100));
    // A port that is not a pseudo-terminal (a USB adapter's /dev/ttyACM0 is a character device of
    // its own; a missing path fails at open, with the default in place).
    assert!(!is_pseudo_terminal(std::path::Path::new("/dev/null")));
    assert_eq!(
        ports("/dev/ttyACM9".into(), None).bus_slack_ms(),
        ADAPTER_SLACK_MS
    );
    // What the user gives wins.
    assert_eq!(ports(bench.link.clone(), Some(4.0)).bus_slack_ms(), 4.0);

    // The emulator answering 40 ms late, as when a busy machine keeps its process from a core:
    // the pseudo-terminal's default waits for it, where an adapter's 10 ms gave up (set-up-motors
    // failed so beside a training run).
    control(&bench, "delay 40");
    let mut patient = open_bus(&bench.link, emulated.bus_config()).unwrap();
    assert!(patient.ping(1).is_ok());
    drop(patient); // the port is opened exclusively
    let adapter_like = ports(bench.link.clone(), Some(ADAPTER_SLACK_MS));
    let mut hasty = open_bus(&bench.link, adapter_like.bus_config()).unwrap();
    assert!(matches!(hasty.ping(1), Err(BusError::NoAnswer { .. })));
}

#[test]
fn connect_configures_the_servos_like_lerobot_and_writes_the_calibration() {
    let bench = emulator(EmulatorConfig {
        timing: Timing::Realistic { baud: 1_000_000 },
        ..EmulatorConfig::default()
    });
    let arm = connect(&bench, 2);
    assert_eq!(arm.servos.len(), 6);
    assert!(arm.servos.iter().all(|servo| servo.model == 777));
    for (index, servo) in bench.emulator.snapshot().iter().enumerate() {
        assert_eq!(servo.return_delay_time, 0, "slot {index}");
        assert_eq!(servo.acceleration, 254);
        assert_eq!((servo.p, servo.i, servo.d), (16, 0, 32));
        assert_eq!(servo.operating_mode, 0);
        assert_eq!(servo.lock, 1, "EPROM locked again");
        assert_eq!(servo.torque_enable, 0);
        let motor = arm.calibration.motors[index];
        assert_eq!(servo.homing_offset, motor.homing_offset);
        assert_eq!(
            (servo.min_position_limit, servo.max_position_limit),
            (motor.range_min, motor.range_max)
        );
    }
    let gripper = slot(&bench, 5);
    assert_eq!(gripper.max_torque_limit, 500);
    assert_eq!(gripper.torque_limit, 500);
    assert_eq!(gripper.protection_current, 250);
    assert_eq!(gripper.overload_torque, 25);
    assert_eq!(
        slot(&bench, 0).max_torque_limit,
        1000,
        "only the gripper is limited"
    );
}

#[test]
fn goals_written_with_torque_on_move_the_servos() {
    let bench = emulator(EmulatorConfig::default());
    let mut arm = connect(&bench, 2);
    let start = arm.read_positions().unwrap();
    // The servo subtracts its homing offset: the shaft at 2048 reads 2048 - 100 on shoulder_pan.
    assert_eq!(start[0], 2048 - 100);
    assert_eq!(start[1], 2048 + 200);
    arm.torque_on().unwrap();
    let goals = [1500, 2500, 1800, 2200, 3000, 2900];
    arm.write_goals(&goals).unwrap();
    let deadline = Instant::now() + Duration::from_secs(3);
    loop {
        let now = arm.read_positions().unwrap();
        if now.iter().zip(&goals).all(|(a, b)| (a - b).abs() <= 3) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "servos did not reach {goals:?}: {now:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let telemetry = arm.read_telemetry().unwrap();
    assert!(telemetry
        .iter()
        .all(|t| t.voltage > 5.0 && t.temperature > 0));
    assert!(arm.torque_off_everywhere().confirmed());
    assert!(bench
        .emulator
        .snapshot()
        .iter()
        .all(|s| s.torque_enable == 0));
}

#[test]
fn lost_replies_are_retried_and_counted() {
    let bench = emulator(EmulatorConfig {
        seed: 7,
        ..EmulatorConfig::default()
    });
    let mut arm = connect(&bench, 3);
    control(&bench, "drop 0.05");
    let mut failures = 0;
    for _ in 0..200 {
        if arm.read_positions().is_err() {
            failures += 1;
        }
    }
    let stats = arm.bus.stats();
    assert!(stats.retries > 0 && stats.timeouts > 0, "{stats:?}");
    // With 6 replies per read, ~26 % of attempts lose one; four attempts rarely all do.
    assert!(
        failures <= 5,
        "{failures} of 200 reads failed despite retries"
    );
    assert_eq!(stats.failures, failures);
}

#[test]
fn no_answer_at_all_fails_after_the_retries_and_names_the_servos() {
    let bench = emulator(EmulatorConfig::default());
    let mut arm = connect(&bench, 1);
    control(&bench, "drop 1");
    match arm.read_positions() {
        Err(BusError::NoAnswer {
            missing, attempts, ..
        }) => {
            assert_eq!(missing, [1, 2, 3, 4, 5, 6]);
            assert_eq!(attempts, 2);
        }
        other => panic!("expected NoAnswer, got {other:?}"),
    }
    control(&bench, "clear");
    assert!(
        arm.read_positions().is_ok(),
        "the bus recovers once replies come back"
    );
}

#[test]
fn a_silent_servo_is_named_and_the_others_still_answer_next_time() {
    let bench = emulator(EmulatorConfig::default());
    let mut arm = connect(&bench, 1);
    control(&bench, "silent 3 on");
    match arm.read_positions() {
        Err(BusError::NoAnswer { missing, .. }) => assert_eq!(missing, [3]),
        other => panic!("expected NoAnswer for id 3, got {other:?}"),
    }
    control(&bench, "silent 3 off");
    assert!(arm.read_positions().is_ok());
}

#[test]
fn corrupted_replies_are_detected_never_decoded() {
    let bench = emulator(EmulatorConfig {
        seed: 3,
        ..EmulatorConfig::default()
    });
    let mut arm = connect(&bench, 1);
    let good = arm.read_positions().unwrap();
    control(&bench, "corrupt 1");
    assert!(matches!(
        arm.read_positions(),
        Err(BusError::NoAnswer { .. })
    ));
    assert!(arm.bus.stats().checksum_errors > 0);
    control(&bench, "corrupt 0.2");
    for _ in 0..100 {
        // Whatever got through was a valid packet: the values are the real ones.
        if let Ok(positions) = arm.read_positions() {
            assert_eq!(positions, good);
        }
    }
}

#[test]
fn garbage_bytes_and_late_replies_do_not_desynchronise_the_bus() {
    let bench = emulator(EmulatorConfig::default());
    let mut arm = connect(&bench, 1);
    let good = arm.read_positions().unwrap();
    control(&bench, "garbage 40");
    assert_eq!(arm.read_positions().unwrap(), good);
    assert!(arm.bus.stats().garbage_bytes >= 1);
    // Replies that come after the wait are dropped, and the next read is clean again.
    control(&bench, "delay 30");
    assert!(arm.read_positions().is_err());
    control(&bench, "clear");
    std::thread::sleep(Duration::from_millis(100));
    assert_eq!(arm.read_positions().unwrap(), good);
}

#[test]
fn an_unplugged_adapter_is_reported_and_reattached_limp_until_torque_is_asked_for() {
    let bench = emulator(EmulatorConfig::default());
    let mut arm = connect(&bench, 1);
    arm.torque_on().unwrap();
    control(&bench, "hangup 0.5");
    let deadline = Instant::now() + Duration::from_secs(2);
    let error = loop {
        match arm.read_positions() {
            Err(error) if error.is_disconnected() => break error,
            _ => assert!(Instant::now() < deadline, "the hang-up was never noticed"),
        }
    };
    assert!(error.to_string().contains("serial port"), "{error}");
    drop(arm);
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut arm = loop {
        let attached = open_bus(&bench.link, settings(1).bus)
            .and_then(|bus| Arm::reattach_on(bus, &settings(1), calibration()));
        match attached {
            Ok(arm) => break arm,
            Err(_) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(100)),
            Err(error) => panic!("no reconnection: {error}"),
        }
    };
    assert!(arm.read_positions().is_ok());
    // Opening the port broadcasts torque off: nobody held the servos while the adapter was gone.
    assert!(
        bench
            .emulator
            .snapshot()
            .iter()
            .all(|s| s.torque_enable == 0),
        "reattached servos are limp until torque is asked for"
    );
    arm.torque_on().unwrap();
    assert!(bench
        .emulator
        .snapshot()
        .iter()
        .all(|s| s.torque_enable == 1));
}

#[test]
fn another_arm_after_a_hangup_is_refused_its_eprom_untouched_and_its_torque_off() {
    let bench = emulator(EmulatorConfig::default());
    let arm = connect(&bench, 1);
    drop(arm);
    // Another arm is plugged in: factory calibration (offset 0, limits 0..4095), torque on.
    let mut bus = open_bus(&bench.link, settings(1).bus).unwrap();
    for id in 1..=6 {
        for (register, value) in [
            (registers::LOCK, 0),
            (registers::HOMING_OFFSET, 0),
            (registers::MIN_POSITION_LIMIT, 0),
            (registers::MAX_POSITION_LIMIT, 4095),
            (registers::LOCK, 1),
            (registers::TORQUE_ENABLE, 1),
        ] {
            bus.write(id, register, value).unwrap();
        }
    }
    drop(bus);
    let before = bench.emulator.snapshot();
    let bus = open_bus(&bench.link, settings(1).bus).unwrap();
    let error = Arm::reattach_on(bus, &settings(1), calibration())
        .err()
        .expect("another arm must be refused");
    assert!(error.to_string().contains("differs"), "{error}");
    for (slot, (old, new)) in before.iter().zip(bench.emulator.snapshot()).enumerate() {
        assert_eq!(new.torque_enable, 0, "slot {slot}: torque left on");
        assert_eq!(
            (
                new.homing_offset,
                new.min_position_limit,
                new.max_position_limit
            ),
            (
                old.homing_offset,
                old.min_position_limit,
                old.max_position_limit
            ),
            "slot {slot}: EPROM written"
        );
    }
}

#[test]
fn calibration_centres_on_the_pose_and_records_the_sweep() {
    let bench = emulator(EmulatorConfig::default());
    let ids = [1, 2, 3, 4, 5, 6];
    let mut bus = open_bus(&bench.link, settings(1).bus).unwrap();
    let mut session = Calibration::begin(&mut bus, ids).unwrap();
    // The user holds the arm in the middle of its range: shafts at these raw positions.
    let centre = [1800, 2300, 2047, 1500, 2600, 2100];
    for (id, raw) in ids.iter().zip(centre) {
        control(&bench, &format!("move {id} {raw}"));
    }
    session.set_centre().unwrap();
    session.sample().unwrap();
    // The sweep: each joint (wrist_roll included, whose range stays full) to both ends.
    let ends = [
        (-700, 900),
        (-1000, 800),
        (-950, 950),
        (-600, 1100),
        (-2000, 2000),
        (0, 1200),
    ];
    for (index, (low, high)) in ends.iter().enumerate() {
        for delta in [*low, *high, 0] {
            control(
                &bench,
                &format!("move {} {}", ids[index], centre[index] + delta),
            );
            session.sample().unwrap();
        }
    }
    let result = session.finish().unwrap();
    for (index, motor) in result.motors.iter().enumerate() {
        assert_eq!(motor.homing_offset, centre[index] - 2047, "joint {index}");
        if index == 4 {
            assert_eq!((motor.range_min, motor.range_max), (0, 4095));
        } else {
            assert_eq!(
                (motor.range_min, motor.range_max),
                (2047 + ends[index].0, 2047 + ends[index].1),
                "joint {index}"
            );
        }
        let servo = slot(&bench, index);
        assert_eq!(servo.homing_offset, motor.homing_offset);
        assert_eq!(servo.min_position_limit, motor.range_min);
        assert_eq!(servo.max_position_limit, motor.range_max);
        assert_eq!(servo.lock, 1);
    }
    // What LeRobot would read back is what the driver now uses.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("robots/so_follower/arm.json");
    result.save(&path).unwrap();
    assert_eq!(ArmCalibration::load(&path).unwrap(), result);
}

#[test]
fn calibration_refuses_a_joint_that_was_not_swept_or_an_impossible_offset() {
    let bench = emulator(EmulatorConfig::default());
    let mut bus = open_bus(&bench.link, settings(1).bus).unwrap();
    let mut session = Calibration::begin(&mut bus, [1, 2, 3, 4, 5, 6]).unwrap();
    session.set_centre().unwrap();
    session.sample().unwrap();
    assert!(matches!(
        session.finish(),
        Err(CalibrateError::NoSweep {
            joint: "shoulder_pan",
            ..
        })
    ));
    let mut session = Calibration::begin(&mut bus, [1, 2, 3, 4, 5, 6]).unwrap();
    control(&bench, "move 5 4095");
    assert!(matches!(
        session.set_centre(),
        Err(CalibrateError::OffsetOutOfRange {
            joint: "wrist_roll",
            ..
        })
    ));
}

#[test]
fn setup_motors_gives_each_factory_servo_its_id_one_at_a_time() {
    // Two factory-new servos, both id 1; only the first is connected.
    let bench = emulator(EmulatorConfig {
        ids: vec![1, 1],
        plugged: Some(vec![true, false]),
        ..EmulatorConfig::default()
    });
    let config = settings(0).bus;
    assert_eq!(assign(&bench.link, config, 6, 1_000_000).unwrap(), 1);
    control(&bench, "unplug 0");
    control(&bench, "plug 1");
    assert_eq!(assign(&bench.link, config, 5, 1_000_000).unwrap(), 1);
    let ids: Vec<u8> = bench.emulator.snapshot().iter().map(|s| s.id).collect();
    assert_eq!(ids, [6, 5]);
    assert!(bench.emulator.snapshot().iter().all(|s| s.lock == 1));
    control(&bench, "plug 0");
    let mut bus = open_bus(&bench.link, probe_config(config)).unwrap();
    let found = find_servos(&mut bus, 10, config).unwrap();
    assert_eq!(found.iter().map(|s| s.id).collect::<Vec<_>>(), [5, 6]);
    drop(bus);
    assert!(matches!(
        assign(&bench.link, config, 4, 1_000_000),
        Err(SetupError::SeveralServos(2, _))
    ));
    control(&bench, "unplug 0");
    control(&bench, "unplug 1");
    assert!(matches!(
        assign(&bench.link, config, 4, 1_000_000),
        Err(SetupError::NoServo)
    ));
}

/// The emulator's six servos, ids 1 to 6, each an STS3215 (model 777) with firmware 3.10.
fn assert_six_sts3215(found: &[ServoInfo]) {
    assert_eq!(
        found.iter().map(|s| s.id).collect::<Vec<_>>(),
        [1, 2, 3, 4, 5, 6]
    );
    assert!(found
        .iter()
        .all(|s| s.model == 777 && s.firmware == (3, 10)));
}

#[test]
fn scan_finds_every_servo_with_model_and_firmware() {
    let bench = emulator(EmulatorConfig::default());
    let mut bus = open_bus(&bench.link, probe_config(settings(0).bus)).unwrap();
    let started = Instant::now();
    let found = find_servos(&mut bus, 252, settings(2).bus).unwrap();
    assert_six_sts3215(&found);
    assert!(started.elapsed() < Duration::from_secs(5), "scan too slow");
}

#[test]
fn scan_finds_servos_that_answer_after_the_probes_wait() {
    // Answers 8 ms late, as an emulator kept from a core on a busy machine: later than the probe
    // waits (3 ms), within the port's patience. The scan found 1 of 6 so beside a training run.
    let bench = emulator(EmulatorConfig::default());
    control(&bench, "delay 8");
    let patient = BusConfig {
        slack: Duration::from_millis(100),
        ..settings(2).bus
    };
    let mut bus = open_bus(&bench.link, probe_config(patient)).unwrap();
    let found = find_servos(&mut bus, 12, patient).unwrap();
    assert_six_sts3215(&found);
}
