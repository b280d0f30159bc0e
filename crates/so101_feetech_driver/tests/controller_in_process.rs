//! The driver's state machine against the emulated servos in-process (no pty, no ROS): each fault
//! of the safety contract, judged from the emulated servos' own registers. Whatever fails, no
//! servo keeps torque the user did not ask for, no EPROM is written unasked, and no goal is ever
//! more than --max-step from where its joint is (audited on every goal the servos receive).

// Test helpers fail loudly: a panic is the right report here.
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use so101_core::{command::targets_from_joint_state, robot::JOINT_NAMES};
mod common;

use common::calibration;
use so101_feetech_driver::{
    arm::{ArmSettings, CalibrationWrite},
    bus::BusConfig,
    calibration::{ArmCalibration, ArmRole},
    node::controller::{Controller, ControllerConfig},
    protocol::{registers as reg, ServoErrors},
    safety::SafetyConfig,
};
use so101_servo_emulator::{BusEmulator, InProcessBus, Timing};

/// 0.05 rad in ticks (4095 ticks per turn): the step every goal is audited against.
const MAX_STEP: f64 = 0.05;
const MAX_STEP_TICKS: i32 = 33;

/// Six servos calibrated with `calibration()`, shafts at mid-range.
fn calibrated_servos() -> InProcessBus {
    let mut bus = BusEmulator::with_factory_servos(&[1, 2, 3, 4, 5, 6], Timing::Instant, 3);
    write_calibration(&mut bus, &calibration());
    InProcessBus::new(bus)
}

fn write_calibration(bus: &mut BusEmulator, calibration: &ArmCalibration) {
    for (slot, motor) in bus.slots.iter_mut().zip(&calibration.motors) {
        for (register, value) in [
            (reg::HOMING_OFFSET, motor.homing_offset),
            (reg::MIN_POSITION_LIMIT, motor.range_min),
            (reg::MAX_POSITION_LIMIT, motor.range_max),
        ] {
            slot.servo.set_register(register, value).unwrap();
        }
    }
}

fn settings() -> ArmSettings {
    ArmSettings {
        bus: BusConfig {
            retries: 1,
            slack: Duration::from_millis(3),
            ..BusConfig::default()
        },
        role: ArmRole::Follower,
        gripper_torque_limit: 500,
    }
}

fn config() -> ControllerConfig {
    ControllerConfig {
        leader: false,
        safety: SafetyConfig {
            max_step: MAX_STEP,
            command_timeout: None,
        },
        torque_at_start: true,
        calibration_write: CalibrationWrite::Refused,
        reopen_after: Duration::from_millis(100),
        reconnect_interval: Duration::from_millis(20),
        telemetry_period: Duration::from_millis(100),
    }
}

/// A controller on `servos`, one cycle run (so it knows where the arm is).
fn start(servos: &InProcessBus, config: ControllerConfig) -> Controller<InProcessBus> {
    let mut controller = Controller::start(
        servos.clone(),
        settings(),
        calibration(),
        config,
        Instant::now(),
    )
    .unwrap();
    controller.cycle(Instant::now());
    controller
}

/// Runs `count` cycles, 2 ms apart (the servos move in between).
fn cycles(controller: &mut Controller<InProcessBus>, count: usize) {
    for _ in 0..count {
        controller.cycle(Instant::now());
        std::thread::sleep(Duration::from_millis(2));
    }
}

fn torque(servos: &InProcessBus) -> Vec<i32> {
    servos.with_bus(|bus| {
        bus.slots
            .iter()
            .map(|slot| slot.servo.register(reg::TORQUE_ENABLE))
            .collect()
    })
}

/// Cycles until torque is on again (after a reconnect), 2 s at most.
fn cycle_until_torque_is_on(controller: &mut Controller<InProcessBus>) {
    let deadline = Instant::now() + Duration::from_secs(2);
    while !controller.status().torque_on {
        assert!(
            Instant::now() < deadline,
            "{:?}",
            controller.status().problem
        );
        cycles(controller, 1);
    }
}

/// Sends a command; whether the controller could take it (it knows where the arm is).
fn command(controller: &mut Controller<InProcessBus>, joint: &str, value: f64) -> bool {
    let targets = targets_from_joint_state(&[joint.to_owned()], &[value]).unwrap();
    controller.command(&targets, Instant::now())
}

fn assert_no_jump(servos: &InProcessBus) {
    let audit = servos.goal_audit();
    assert!(
        audit.max_jump_ticks <= MAX_STEP_TICKS + 1,
        "a goal {} ticks from its joint (max step {MAX_STEP_TICKS}) in {} goal writes",
        audit.max_jump_ticks,
        audit.goal_writes
    );
}

#[test]
fn a_silent_first_servo_does_not_keep_the_others_stiff_at_exit() {
    let servos = calibrated_servos();
    let mut controller = start(&servos, config());
    cycles(&mut controller, 5);
    assert_eq!(torque(&servos), [1; 6]);
    // Servo 1 stops answering (it still hears): every servo must still end limp.
    servos.with_bus(|bus| bus.slots[0].silent = true);
    cycles(&mut controller, 3);
    controller.shutdown(false);
    assert_eq!(torque(&servos), [0; 6]);
}

#[test]
fn a_deaf_first_servo_does_not_keep_the_others_stiff_on_request() {
    let servos = calibrated_servos();
    let mut controller = start(&servos, config());
    cycles(&mut controller, 5);
    // Servo 1 is cut off the bus entirely: the others still get torque off, one by one.
    servos.with_bus(|bus| bus.slots[0].plugged = false);
    let (success, message) = controller.request_torque(false);
    assert!(!success, "servo 1 cannot confirm: {message}");
    assert_eq!(&torque(&servos)[1..], [0; 5]);
    assert!(!controller.status().torque_on);
}

#[test]
fn a_servo_that_misses_its_own_torque_off_still_gets_the_broadcast() {
    let servos = calibrated_servos();
    let mut controller = start(&servos, config());
    cycles(&mut controller, 3);
    // Every request to servo 1 alone is lost on the wire, retries included.
    servos.lose_requests_to(1, 100);
    let (success, message) = controller.request_torque(false);
    assert!(!success && message.contains('1'), "{message}");
    assert_eq!(torque(&servos), [0; 6], "the broadcast reached servo 1");
}

#[test]
fn a_misread_at_the_moment_torque_comes_on_is_not_the_pose_held() {
    let servos = calibrated_servos();
    let mut config = config();
    config.torque_at_start = false;
    let mut controller = start(&servos, config);
    cycles(&mut controller, 3);
    // elbow_flex rests at 2048; the first reading of the torque-on reads 2350 (in range).
    servos.glitch_next_position(3, 2350);
    let (success, message) = controller.request_torque(true);
    assert!(success, "{message}");
    cycles(&mut controller, 30);
    let (present, goal) = servos.with_bus(|bus| {
        let elbow = &bus.slots[2].servo;
        (
            elbow.register(reg::PRESENT_POSITION),
            elbow.register(reg::GOAL_POSITION),
        )
    });
    assert!(
        (present - 2048).abs() <= 2,
        "the arm moved to the misread pose: {present}"
    );
    assert!((goal - 2048).abs() <= 2, "goal {goal}");
    assert!(controller.status().safety.implausible_readings >= 1);
}

#[test]
fn a_lost_link_turns_torque_off_and_the_wish_returns_with_the_arm() {
    let servos = calibrated_servos();
    let mut controller = start(&servos, config());
    cycles(&mut controller, 5);
    servos.with_bus(|bus| bus.slots[0].silent = true);
    let deadline = Instant::now() + Duration::from_secs(2);
    while controller.is_connected() {
        assert!(
            Instant::now() < deadline,
            "the silent servo never lost the link"
        );
        cycles(&mut controller, 1);
    }
    assert_eq!(torque(&servos), [0; 6], "nobody supervises the servos now");
    servos.with_bus(|bus| bus.slots[0].silent = false);
    cycle_until_torque_is_on(&mut controller);
    assert_eq!(torque(&servos), [1; 6]);
    assert_eq!(controller.status().reconnects, 1);
    assert_no_jump(&servos);
}

#[test]
fn another_arm_after_a_reconnect_is_refused_untouched_until_the_right_one_returns() {
    let servos = calibrated_servos();
    let mut controller = start(&servos, config());
    cycles(&mut controller, 5);
    assert!(
        servos.with_bus(|bus| bus.take_save_needed()),
        "configured at start"
    );
    servos.unplug_adapter();
    cycles(&mut controller, 2);
    assert!(!controller.is_connected());
    // Another arm on the adapter: factory calibration, torque on.
    servos.with_bus(|bus| {
        for slot in &mut bus.slots {
            for (register, value) in [
                (reg::HOMING_OFFSET, 0),
                (reg::MIN_POSITION_LIMIT, 0),
                (reg::MAX_POSITION_LIMIT, 4095),
                (reg::TORQUE_ENABLE, 1),
            ] {
                slot.servo.set_register(register, value).unwrap();
            }
        }
    });
    servos.plug_adapter();
    for _ in 0..10 {
        cycles(&mut controller, 1);
        std::thread::sleep(Duration::from_millis(5));
    }
    let status = controller.status();
    assert!(!status.connected);
    assert!(
        status.problem.as_deref().unwrap_or("").contains("differs"),
        "{:?}",
        status.problem
    );
    assert_eq!(torque(&servos), [0; 6]);
    let eprom = servos.with_bus(|bus| {
        bus.slots
            .iter()
            .map(|slot| {
                (
                    slot.servo.register(reg::HOMING_OFFSET),
                    slot.servo.register(reg::MIN_POSITION_LIMIT),
                    slot.servo.register(reg::MAX_POSITION_LIMIT),
                )
            })
            .collect::<Vec<_>>()
    });
    assert!(
        eprom.iter().all(|cells| *cells == (0, 0, 4095)),
        "{eprom:?}"
    );
    assert!(
        servos.with_bus(|bus| !bus.take_save_needed()),
        "no flash written"
    );
    // The arm this calibration belongs to comes back: taken, torque as the user asked.
    servos.with_bus(|bus| write_calibration(bus, &calibration()));
    cycle_until_torque_is_on(&mut controller);
    assert!(controller.is_connected());
    assert_no_jump(&servos);
}

#[test]
fn a_different_arm_at_start_is_refused_unless_the_user_asks_to_write() {
    let mut factory = BusEmulator::with_factory_servos(&[1, 2, 3, 4, 5, 6], Timing::Instant, 3);
    factory.slots[2]
        .servo
        .set_register(reg::TORQUE_ENABLE, 1)
        .unwrap();
    let servos = InProcessBus::new(factory);
    let error = Controller::start(
        servos.clone(),
        settings(),
        calibration(),
        config(),
        Instant::now(),
    )
    .err()
    .unwrap();
    assert!(error.to_string().contains("--write-calibration"), "{error}");
    assert_eq!(torque(&servos), [0; 6]);
    let offset = servos.with_bus(|bus| bus.slots[0].servo.register(reg::HOMING_OFFSET));
    assert_eq!(offset, 0, "EPROM untouched");
    let mut asked = config();
    asked.calibration_write = CalibrationWrite::Allowed;
    let controller = start(&servos, asked);
    assert!(controller.status().torque_on);
    let offset = servos.with_bus(|bus| bus.slots[0].servo.register(reg::HOMING_OFFSET));
    assert_eq!(offset, 100);
}

#[test]
fn a_joint_resting_outside_its_range_refuses_torque_instead_of_jumping() {
    let servos = calibrated_servos();
    // shoulder_lift: range 900..3100, offset -200; present = shaft + 200 = 830: 70 ticks below.
    servos.with_bus(|bus| bus.slots[1].servo.set_actual(630.0));
    let mut controller = start(&servos, config());
    cycles(&mut controller, 5);
    let status = controller.status();
    assert!(!status.torque_on);
    let problem = status.problem.unwrap_or_default();
    assert!(
        problem.contains("torque refused") && problem.contains("shoulder_lift"),
        "{problem}"
    );
    assert_eq!(torque(&servos), [0; 6]);
    // Moved back in by hand, torque is asked for again: on, holding, no jump. (Two readings: the
    // filter believes a teleported joint once it reads the same twice.)
    servos.with_bus(|bus| bus.slots[1].servo.set_actual(720.0));
    cycles(&mut controller, 2);
    let (success, message) = controller.request_torque(true);
    assert!(success, "{message}");
    assert!(command(&mut controller, "shoulder_lift", 0.0));
    cycles(&mut controller, 30);
    assert_eq!(torque(&servos), [1; 6]);
    assert!(servos.goal_audit().goal_writes > 0);
    assert_no_jump(&servos);
}

#[test]
fn no_goal_ever_moves_a_joint_more_than_max_step_whatever_is_commanded() {
    let servos = calibrated_servos();
    let mut controller = start(&servos, config());
    servos.with_bus(|bus| bus.faults.drop_probability = 0.05);
    for step in 0..150_usize {
        let joint = JOINT_NAMES[step % JOINT_NAMES.len()];
        let value = [3.0, -3.0, 0.5, -0.2, 1.0][step % 5];
        command(&mut controller, joint, value);
        cycles(&mut controller, 1);
    }
    assert!(servos.goal_audit().goal_writes > 50);
    assert_no_jump(&servos);
}

#[test]
fn one_misread_position_is_not_a_base_for_a_goal() {
    let servos = calibrated_servos();
    let mut controller = start(&servos, config());
    cycles(&mut controller, 5);
    // elbow_flex truly at 2048; one reply says 2350 (inside the calibrated range).
    servos.glitch_next_position(3, 2350);
    let output = controller.cycle(Instant::now());
    assert!(output.positions.is_none(), "the misread cycle is not used");
    cycles(&mut controller, 5);
    let status = controller.status();
    assert_eq!(status.safety.implausible_readings, 1);
    assert!(status.torque_on);
    assert_no_jump(&servos);
}

#[test]
fn an_adapter_unplugged_mid_run_is_survived_and_the_arm_taken_back_without_a_jump() {
    let servos = calibrated_servos();
    let mut controller = start(&servos, config());
    command(&mut controller, "elbow_flex", 0.6);
    cycles(&mut controller, 3);
    servos.unplug_adapter();
    cycles(&mut controller, 3);
    assert!(!controller.is_connected());
    servos.plug_adapter();
    cycle_until_torque_is_on(&mut controller);
    cycles(&mut controller, 1);
    assert!(command(&mut controller, "elbow_flex", -0.6));
    cycles(&mut controller, 20);
    assert_no_jump(&servos);
}

#[test]
fn late_replies_in_the_running_loop_are_discarded_never_taken_for_fresh_positions() {
    let servos = calibrated_servos();
    let mut config = config();
    config.reopen_after = Duration::from_secs(5);
    let mut controller = start(&servos, config);
    assert!(command(&mut controller, "elbow_flex", 0.8));
    for _ in 0..10 {
        // The next answers come 10 ms late: after the timeout, during later transactions.
        servos.hold_back_replies(2, Duration::from_millis(10));
        cycles(&mut controller, 5);
        command(&mut controller, "elbow_flex", -0.8);
    }
    let status = controller.status();
    assert!(status.bus.stale_replies > 0, "{:?}", status.bus);
    assert_eq!(status.safety.implausible_readings, 0);
    assert_no_jump(&servos);
}

#[test]
fn an_adapter_pulled_out_in_the_middle_of_a_write_is_survived() {
    let servos = calibrated_servos();
    let mut controller = start(&servos, config());
    assert!(command(&mut controller, "wrist_flex", 0.7));
    cycles(&mut controller, 3);
    // Each cycle writes two packets (SYNC_READ, SYNC_WRITE): the goals' packet is cut.
    servos.unplug_during_write(1);
    cycles(&mut controller, 2);
    assert!(!controller.is_connected());
    servos.plug_adapter();
    cycle_until_torque_is_on(&mut controller);
    cycles(&mut controller, 1);
    assert!(command(&mut controller, "wrist_flex", -0.7));
    cycles(&mut controller, 20);
    assert_no_jump(&servos);
}

#[test]
fn corrupted_and_lost_replies_never_lead_to_a_jump() {
    let servos = calibrated_servos();
    let mut config = config();
    config.reopen_after = Duration::from_secs(5);
    let mut controller = Controller::start(
        servos.clone(),
        ArmSettings {
            bus: BusConfig {
                retries: 5,
                ..settings().bus
            },
            ..settings()
        },
        calibration(),
        config,
        Instant::now(),
    )
    .unwrap();
    servos.with_bus(|bus| {
        bus.faults.corrupt_probability = 0.2;
        bus.faults.drop_probability = 0.1;
    });
    cycles(&mut controller, 3);
    for step in 0..100 {
        command(
            &mut controller,
            "wrist_flex",
            if step % 20 < 10 { 1.0 } else { -1.0 },
        );
        cycles(&mut controller, 1);
    }
    let status = controller.status();
    assert!(status.bus.checksum_errors > 0);
    assert!(status.failed_cycles > 0);
    assert_no_jump(&servos);
}

#[test]
fn an_overloaded_servo_that_dropped_its_torque_makes_the_whole_arm_limp_until_asked() {
    let servos = calibrated_servos();
    let mut controller = start(&servos, config());
    cycles(&mut controller, 5);
    // The gripper's protection trips: it reports overload and cuts its own torque.
    servos.with_bus(|bus| {
        let gripper = &mut bus.slots[5].servo;
        gripper.errors = ServoErrors::OVERLOAD;
        gripper.set_register(reg::TORQUE_ENABLE, 0).unwrap();
    });
    cycles(&mut controller, 3);
    let status = controller.status();
    assert!(!status.torque_on);
    assert!(
        status.problem.unwrap_or_default().contains("overload"),
        "the reason is reported"
    );
    assert_eq!(torque(&servos), [0; 6]);
    cycles(&mut controller, 10);
    assert_eq!(
        torque(&servos),
        [0; 6],
        "torque does not come back by itself"
    );
    servos.with_bus(|bus| bus.slots[5].servo.errors = 0);
    let (success, message) = controller.request_torque(true);
    assert!(success, "{message}");
    cycles(&mut controller, 2);
    assert!(controller.status().problem.is_none());
    assert_eq!(torque(&servos), [1; 6]);
}

#[test]
fn the_watchdog_holds_and_a_leader_never_takes_torque() {
    let servos = calibrated_servos();
    let mut config = config();
    config.safety.command_timeout = Some(Duration::from_millis(30));
    let mut controller = start(&servos, config.clone());
    assert!(command(&mut controller, "elbow_flex", 1.2));
    cycles(&mut controller, 40);
    assert_eq!(controller.status().safety.watchdog_holds, 1);
    assert_no_jump(&servos);
    controller.shutdown(false);

    let leader_servos = calibrated_servos();
    config.leader = true;
    let mut leader = start(&leader_servos, config);
    let (success, _) = leader.request_torque(true);
    assert!(!success);
    cycles(&mut leader, 3);
    assert_eq!(torque(&leader_servos), [0; 6]);
}
