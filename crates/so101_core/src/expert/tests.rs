//! The planner's tests: the grasp's geometry, the plan's end, and its gates against arms that
//! lag, stall or meet the cube.

use super::*;
use rand::SeedableRng;

pub fn sim_config() -> ExpertConfig {
    ExpertConfig {
        task: TaskKind::CubeToBin,
        bin: Vector3::new(0.10, -0.22, 0.02),
        pad: Vector3::new(0.20, 0.18, 0.015),
        stack_base: Vector3::new(0.20, 0.18, 0.015),
        push_target: Vector3::new(0.26, 0.13, 0.0),
        table_z: 0.0,
        gripper_open: 0.9,
        gripper_closed: -0.17,
        waypoint_noise: 0.0,
        action_noise: 0.0,
        slowness: 1.0,
    }
}

const PERIOD: f64 = 1.0 / 30.0;
/// Where the gripper stops closed on the cube, rad.
const HOLDING: f64 = 0.19;

/// Steps the plan `seconds` with an arm that follows its targets exactly (the gripper stopped
/// by the cube); the last targets.
fn play(
    plan: &mut Plan,
    seconds: f64,
    config: &ExpertConfig,
    rng: &mut impl Rng,
    arm: &mut JointPositions,
) -> JointPositions {
    for _ in 0..(seconds / PERIOD).round() as usize {
        *arm = plan.step(PERIOD, arm, None, config, rng);
        arm[5] = arm[5].max(HOLDING);
    }
    *arm
}

#[test]
fn the_jaws_close_across_two_faces_of_the_cube() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    for (x, y, yaw) in [(0.23, -0.05, 0.0), (0.19, 0.07, 0.6), (0.27, -0.07, -0.4)] {
        let cube = Vector3::new(x, y, 0.015);
        let mut plan = Plan::new(&[0.0; 6], cube, yaw, &sim_config(), &mut rng).unwrap();
        // At the grasp (after approach and descent), the grasp point is on the cube ...
        let mut arm = [0.0; 6];
        let targets = play(
            &mut plan,
            1.6 + 1.0 + 0.1,
            &sim_config(),
            &mut rng,
            &mut arm,
        );
        let arm: ArmPositions = std::array::from_fn(|j| targets[j]);
        let frame = kinematics::grasp_frame(&arm);
        let at = frame.translation.vector;
        let off = at - Vector3::new(x, y, GRASP_ABOVE_TABLE);
        assert!((off.norm() - JAW_CLEARANCE).abs() < 1e-3, "{at:?}");
        // ... pointing down, with the jaw axis along a face normal of the cube.
        let approach = frame.rotation * -Vector3::z();
        assert!(approach.z < -0.99, "{approach:?}");
        let jaw = frame.rotation * Vector3::x();
        let misalignment = kinematics::wrap_angle(4.0 * (jaw.y.atan2(jaw.x) - yaw)) / 4.0;
        assert!(
            misalignment.abs() < 0.03,
            "jaw off the faces by {misalignment} rad"
        );
        assert_eq!(targets[5], 0.9);
    }
}

#[test]
fn the_plan_ends_open_over_the_bin_inside_the_limits() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
    let config = ExpertConfig {
        waypoint_noise: 0.005,
        action_noise: 0.01,
        ..sim_config()
    };
    let mut plan = Plan::new(
        &[0.0; 6],
        Vector3::new(0.21, 0.03, 0.015),
        0.3,
        &config,
        &mut rng,
    )
    .unwrap();
    let mut arm = [0.0; 6];
    let mut t = 0.0;
    while !plan.finished() {
        arm = plan.step(PERIOD, &arm, None, &config, &mut rng);
        arm[5] = arm[5].max(HOLDING);
        for (joint, value) in arm.iter().enumerate() {
            assert!(
                JOINT_LIMITS[joint].contains(*value),
                "t={t}: {joint}={value}"
            );
        }
        t += PERIOD;
        assert!(
            t < plan.duration() + 3.0 * GATE_TIMEOUT,
            "the plan never ends"
        );
    }
    let quiet = sim_config();
    let end = play(&mut plan, 1.0, &quiet, &mut rng, &mut arm);
    let arm: ArmPositions = std::array::from_fn(|j| end[j]);
    let over = kinematics::task_pose(&arm).position;
    assert!(
        (over.xy() - Vector3::new(0.10, -0.22, 0.0).xy()).norm() < 0.02,
        "{over:?}"
    );
    assert!(end[5] > 0.8);
}

#[test]
fn each_task_ends_where_it_asks_the_lift_held_and_the_touch_open_at_the_cube() {
    let cube = Vector3::new(0.22, 0.04, 0.015);
    for task in [
        TaskKind::LiftCube,
        TaskKind::TouchCube,
        TaskKind::TouchCubeSparse,
    ] {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let config = sim_config().for_task(task);
        let mut plan = Plan::new(&[0.0; 6], cube, 0.2, &config, &mut rng).unwrap();
        let mut arm = [0.0; 6];
        let mut closed_at_the_cube = false;
        while !plan.finished() {
            arm = plan.step(PERIOD, &arm, None, &config, &mut rng);
            arm[5] = arm[5].max(HOLDING);
            let at: ArmPositions = std::array::from_fn(|j| arm[j]);
            let near = (kinematics::task_pose(&at).position.xy() - cube.xy()).norm() < 0.015;
            closed_at_the_cube |= near && arm[5] < 0.5;
        }
        let end: ArmPositions = std::array::from_fn(|j| arm[j]);
        let tip = kinematics::task_pose(&end).position;
        // Never over the bin, wherever the task ends.
        assert!((tip.xy() - cube.xy()).norm() < 0.015, "{task}: {tip:?}");
        if task == TaskKind::LiftCube {
            // Closed on the cube, then held high above the table, still closed.
            assert!(
                closed_at_the_cube && arm[5] < 0.5 && tip.z > cube.z + 0.08,
                "{task}: {tip:?} {arm:?}"
            );
        } else {
            // The jaws stay open at the cube.
            assert!(
                !closed_at_the_cube && arm[5] > 0.8 && tip.z < cube.z + 0.01,
                "{task}: {tip:?} {arm:?}"
            );
        }
        assert!(plan.duration() < 5.0, "{task}: {}", plan.duration());
    }
}

/// Plays a set-down task's plan (the arm following exactly, the gripper stopped by the cube) for
/// a cube away from `goal`: how low the closed jaws came over the goal, and the arm at the end.
fn set_down_over(task: TaskKind, goal: Vector3<f64>) -> (f64, JointPositions) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    let config = sim_config().for_task(task);
    let cube = Vector3::new(0.24, -0.03, 0.015);
    let mut plan = Plan::new(&[0.0; 6], cube, -0.3, &config, &mut rng).unwrap();
    let mut arm = [0.0; 6];
    let mut lowest_closed_over_the_goal = f64::INFINITY;
    while !plan.finished() {
        arm = plan.step(PERIOD, &arm, None, &config, &mut rng);
        arm[5] = arm[5].max(HOLDING);
        let at: ArmPositions = std::array::from_fn(|j| arm[j]);
        let tip = kinematics::task_pose(&at).position;
        if (tip.xy() - goal.xy()).norm() < 0.005 && arm[5] < 0.5 {
            lowest_closed_over_the_goal = lowest_closed_over_the_goal.min(tip.z);
        }
    }
    (lowest_closed_over_the_goal, arm)
}

#[test]
fn place_cube_sets_the_cube_down_on_the_pad_and_lets_go() {
    let pad = sim_config().pad;
    let (lowest, arm) = set_down_over(TaskKind::PlaceCube, pad);
    // Carried to the pad still closed, down to just above the table, then opened and away.
    assert!(
        (lowest - (GRASP_ABOVE_TABLE + PLACE_CLEARANCE)).abs() < 0.003,
        "{lowest}"
    );
    let end: ArmPositions = std::array::from_fn(|j| arm[j]);
    let tip = kinematics::task_pose(&end).position;
    assert!(
        (tip.xy() - pad.xy()).norm() < 0.01 && tip.z > 0.1 && arm[5] > 0.8,
        "{tip:?}"
    );
}

#[test]
fn stack_cube_sets_the_cube_down_on_the_green_cube_and_lets_go() {
    let (lowest, arm) = set_down_over(TaskKind::StackCube, sim_config().stack_base);
    // Down to one cube's edge above where place_cube lets go: on top of the green cube.
    let release = GRASP_ABOVE_TABLE + STACK_BASE_EDGE + PLACE_CLEARANCE;
    assert!((lowest - release).abs() < 0.003, "{lowest}");
    assert!(arm[5] > 0.8, "let go: {}", arm[5]);
}

/// Plays a push_cube plan with an arm that follows its targets exactly and a cube reported at
/// `cube_at` (from the grasp point's pose); how many pushes it took.
fn pushes_with(cube_at: impl Fn(Vector3<f64>) -> Vector3<f64>) -> u32 {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let config = sim_config().for_task(TaskKind::PushCube);
    let start = Vector3::new(0.22, -0.04, 0.015);
    let mut plan = Plan::new(&[0.0; 6], start, 0.0, &config, &mut rng).unwrap();
    let mut arm = [0.0; 6];
    let mut lowest = f64::INFINITY;
    for _ in 0..(30.0 / PERIOD) as usize {
        let at: ArmPositions = std::array::from_fn(|j| arm[j]);
        let tip = kinematics::task_pose(&at).position;
        lowest = lowest.min(tip.z);
        arm = plan.step(PERIOD, &arm, Some((cube_at(tip), 0.0)), &config, &mut rng);
        // The jaws never open to grasp: pushing only.
        assert!(arm[5] <= push::GRIPPER + 1e-9, "{}", arm[5]);
        if plan.finished() {
            break;
        }
    }
    assert!(plan.finished());
    assert!((lowest - GRASP_ABOVE_TABLE).abs() < 0.003, "{lowest}");
    plan.regrasps() + 1
}

#[test]
fn push_cube_pushes_again_only_while_the_cube_is_off_the_target() {
    // A cube that the push takes to the target: one push.
    let target = sim_config().push_target;
    assert_eq!(pushes_with(|_| target), 1);
    // A cube that never moves (it slid off the pusher each time): two more pushes, then the end.
    assert_eq!(
        pushes_with(|_| Vector3::new(0.22, -0.04, 0.015)),
        1 + MAX_REGRASPS
    );
}

#[test]
fn the_gripper_closes_only_once_a_lagging_arm_has_reached_the_grasp() {
    let config = sim_config();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let cube = Vector3::new(0.22, 0.02, 0.015);
    let mut plan = Plan::new(&[0.0; 6], cube, 0.2, &config, &mut rng).unwrap();
    // An arm that reaches each target half a second late (15 periods: ramped servos behind a
    // slow bus), more than the plan's pause between reaching the grasp and closing.
    let mut arm = [0.0; 6];
    let mut in_flight = std::collections::VecDeque::from(vec![[0.0; 6]; 15]);
    let mut closing_started_at_grasp = None;
    let mut opened = false;
    for _ in 0..1200 {
        let targets = plan.step(PERIOD, &arm, None, &config, &mut rng);
        opened |= targets[5] >= GRIPPER_OPEN - 1e-9;
        if opened && targets[5] < GRIPPER_OPEN - 0.01 && closing_started_at_grasp.is_none() {
            let at: ArmPositions = std::array::from_fn(|j| arm[j]);
            let grasp = plan.clean_grasp.position;
            closing_started_at_grasp = Some((kinematics::task_pose(&at).position - grasp).norm());
        }
        in_flight.push_back(targets);
        arm = in_flight.pop_front().unwrap();
        arm[5] = arm[5].max(HOLDING);
        if plan.finished() {
            break;
        }
    }
    assert!(plan.finished() && plan.regrasps() == 0);
    let off = closing_started_at_grasp.expect("the gripper never closed");
    assert!(
        off < REACHED_TOLERANCE,
        "the jaws began closing {off} m from the grasp"
    );
}

#[test]
fn a_grasp_blocked_by_the_cube_is_retried_from_above_without_the_noise() {
    let config = ExpertConfig {
        waypoint_noise: 0.01,
        ..sim_config()
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    let cube = Vector3::new(0.24, -0.03, 0.015);
    let mut plan = Plan::new(&[0.0; 6], cube, 0.0, &config, &mut rng).unwrap();
    let mut arm = [0.0; 6];
    // The arm follows, but a jaw sits on the cube: it stops 15 mm above the grasp.
    let floor = plan.clean_grasp.position.z + 0.015;
    let mut lowest_after_retry: Option<Vector3<f64>> = None;
    let mut rose_first = None;
    let mut opened = false;
    for _ in 0..400 {
        let targets = plan.step(PERIOD, &arm, None, &config, &mut rng);
        opened |= targets[5] >= GRIPPER_OPEN - 1e-9;
        let regrasped = plan.regrasps() > 0;
        assert!(
            !opened || targets[5] > 0.8 || regrasped,
            "closed on a blocked grasp"
        );
        let reached: ArmPositions = std::array::from_fn(|j| targets[j]);
        let blocked = !regrasped && kinematics::task_pose(&reached).position.z < floor;
        if !blocked {
            arm = targets;
            arm[5] = arm[5].max(HOLDING);
        }
        if regrasped {
            let at: ArmPositions = std::array::from_fn(|j| arm[j]);
            let point = kinematics::task_pose(&at).position;
            // The first move after the retry is up, not sideways.
            rose_first.get_or_insert(point);
            if lowest_after_retry.is_none_or(|low| point.z < low.z) {
                lowest_after_retry = Some(point);
            }
        }
        if plan.finished() {
            break;
        }
    }
    assert!(plan.regrasps() == 1 && plan.finished());
    let lowest = lowest_after_retry.unwrap();
    let clean = plan.clean_grasp.position;
    assert!(
        (lowest - clean).norm() < 1e-3,
        "retried at {lowest:?}, not {clean:?}"
    );
    assert!(plan.grasp_was_noisy(), "the noise moved the first grasp");
}

#[test]
fn a_grasp_that_closed_on_nothing_goes_back_for_the_cube_where_it_lies_now() {
    let config = sim_config();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let planned = Vector3::new(0.22, 0.0, 0.015);
    let moved = Vector3::new(0.25, 0.03, 0.015);
    let mut plan = Plan::new(&[0.0; 6], planned, 0.0, &config, &mut rng).unwrap();
    let mut arm = [0.0; 6];
    let mut lowest: Option<Vector3<f64>> = None;
    for _ in 0..600 {
        // The jaws close on nothing (the cube was knocked to `moved`), once.
        arm = plan.step(PERIOD, &arm, Some((moved, 0.0)), &config, &mut rng);
        if plan.regrasps() > 0 {
            let at: ArmPositions = std::array::from_fn(|j| arm[j]);
            let point = kinematics::task_pose(&at).position;
            if lowest.is_none_or(|low| point.z < low.z) {
                lowest = Some(point);
            }
            // Holding the cube this time: the jaws stop short of closed.
            arm[5] = arm[5].max(HOLDING);
        }
        if plan.finished() {
            break;
        }
    }
    assert_eq!(plan.regrasps(), 1);
    assert!(plan.finished());
    let lowest = lowest.unwrap();
    let off = (lowest.xy() - moved.xy()).norm();
    assert!(
        off < JAW_CLEARANCE + 2e-3,
        "regrasped {off} m from the cube"
    );
}

#[test]
fn cube_yaw_reads_a_flat_cubes_turn() {
    let half = 0.3_f64 / 2.0;
    assert!((cube_yaw([half.cos(), 0.0, 0.0, half.sin()]) - 0.3).abs() < 1e-12);
    assert_eq!(cube_yaw([1.0, 0.0, 0.0, 0.0]), 0.0);
}

#[test]
fn grasp_roll_picks_the_face_pair_needing_the_least_roll() {
    for heading in [-0.5, 0.0, 0.4] {
        for yaw in [-1.0, 0.0, 0.7, 2.5] {
            let roll = grasp_roll(heading, yaw);
            assert!(roll.abs() <= FRAC_PI_2 / 2.0 + 1e-12, "{roll}");
        }
    }
}

/// The quiet expert's plan, from home, for a cube in front of the arm.
fn plan_from_home(seed: u64) -> (ExpertConfig, rand_chacha::ChaCha8Rng, Plan) {
    let config = sim_config();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let cube = Vector3::new(0.22, 0.0, 0.015);
    let plan = Plan::new(&[0.0; 6], cube, 0.0, &config, &mut rng).unwrap();
    (config, rng, plan)
}

#[test]
fn an_arm_that_never_moves_ends_the_plan_after_two_regrasps() {
    let (config, mut rng, mut plan) = plan_from_home(6);
    let still = [0.0; 6];
    let mut steps = 0;
    while !plan.finished() {
        plan.step(PERIOD, &still, None, &config, &mut rng);
        steps += 1;
        assert!(
            steps < 40 * 30,
            "the plan waits forever for an arm that never moves"
        );
    }
    assert_eq!(plan.regrasps(), MAX_REGRASPS);
}

#[test]
fn a_stall_of_the_callers_clock_is_neither_followed_nor_counted_as_waiting() {
    let (config, mut rng, mut plan) = plan_from_home(7);
    let mut arm = [0.0; 6];
    play(&mut plan, 2.4, &config, &mut rng, &mut arm);
    // Two seconds in one call, just before the grasp gate: the plan moves one capped step.
    arm = plan.step(2.0, &arm, None, &config, &mut rng);
    arm[5] = arm[5].max(HOLDING);
    play(&mut plan, 12.0, &config, &mut rng, &mut arm);
    assert!(plan.finished());
    assert_eq!(
        plan.regrasps(),
        0,
        "the stall was taken for a blocked grasp"
    );
}

#[test]
fn stack_cube_moves_the_carry_until_the_held_cube_itself_is_over_the_green_cube() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    let config = sim_config().for_task(TaskKind::StackCube);
    let cube = Vector3::new(0.24, -0.03, 0.015);
    let mut plan = Plan::new(&[0.0; 6], cube, -0.3, &config, &mut rng).unwrap();
    // The cube hangs 1 cm off the grasp point (beyond what the held-offset estimate saw).
    let held_off = Vector3::new(0.01, -0.006, 0.0);
    let mut arm = [0.0; 6];
    let mut lowest_closed = (f64::INFINITY, Vector3::zeros());
    while !plan.finished() {
        let at: ArmPositions = std::array::from_fn(|j| arm[j]);
        let tip = kinematics::task_pose(&at).position;
        let lifted = arm[5] < 0.5 && tip.z > 0.05;
        let cube_now = if lifted { tip + held_off } else { cube };
        arm = plan.step(PERIOD, &arm, Some((cube_now, 0.0)), &config, &mut rng);
        arm[5] = arm[5].max(HOLDING);
        let near_the_base = (tip.xy() - config.stack_base.xy()).norm() < 0.03;
        if arm[5] < 0.5 && tip.z < lowest_closed.0 && near_the_base {
            lowest_closed = (tip.z, tip);
        }
    }
    // Set down with the cube, not the grasp point, over the green cube.
    let (_, tip) = lowest_closed;
    let cube_there = tip + held_off;
    assert!(
        (cube_there.xy() - config.stack_base.xy()).norm() < SET_DOWN_TOLERANCE + 0.002,
        "{cube_there:?}"
    );
}
