//! The simulated arm and scene under MuJoCo 2.2.2, without ROS: the scene binds, the servos track,
//! episodes place the cube where asked, and the demo really puts the cube in the bin.

use std::path::PathBuf;

use so101_core::robot::{DEFAULT_SCENE, JOINT_COUNT, JOINT_LIMITS};
use so101_sim::{
    demo::{Script, PICK_AND_PLACE},
    env::CUBE_SPAWN_AREA,
    placement::CubeStart,
    scene,
    task::{evaluate, TaskKind},
    world::World,
};

const RATE_HZ: f64 = 100.0;

fn world(lite: bool) -> World {
    let simulation = scene::load(&PathBuf::from(DEFAULT_SCENE), lite).expect("the scene loads");
    World::new(simulation, 1.0 / RATE_HZ).expect("the scene has every element the node needs")
}

fn advance_seconds(world: &mut World, seconds: f64) {
    for _ in 0..(seconds * RATE_HZ).round() as usize {
        assert!(world.advance(), "MuJoCo reported a numerical problem");
    }
}

#[test]
fn scene_limits_match_the_robot_model() {
    let world = world(true);
    for (scene, model) in world.limits().iter().zip(JOINT_LIMITS) {
        assert!((scene.min - model.min).abs() < 1e-3 && (scene.max - model.max).abs() < 1e-3);
    }
    assert_eq!(world.timestep(), 0.002);
}

#[test]
fn servos_track_a_pose_within_tolerance() {
    let mut world = world(true);
    let pose = [0.5, -0.4, 0.6, 0.8, -1.0, 1.0];
    *world.targets_mut() = pose;
    advance_seconds(&mut world, 1.5);
    let state = world.arm_state();
    for (joint, target) in pose.iter().enumerate() {
        assert!(
            (state.position[joint] - target).abs() < 0.03,
            "joint {joint}: {state:?}"
        );
        assert!(
            state.velocity[joint].abs() < 0.05,
            "joint {joint} still moving: {state:?}"
        );
    }
    assert!((world.time() - 1.5).abs() < 1e-9);
}

#[test]
fn reset_places_the_cube_and_keeps_time_monotonic() {
    let mut world = world(true);
    advance_seconds(&mut world, 0.5);
    let start = CubeStart {
        x: CUBE_SPAWN_AREA.x.1,
        y: CUBE_SPAWN_AREA.y.0,
        yaw: 0.3,
    };
    world.reset(Some(start));
    assert!(world.time() >= 0.5, "sim time went backwards on reset");
    assert_eq!(world.arm_state().position, [0.0; JOINT_COUNT]);
    advance_seconds(&mut world, 1.0);
    let cube = world.cube_pose();
    assert!(
        (cube.position[0] - start.x).abs() < 2e-3 && (cube.position[1] - start.y).abs() < 2e-3,
        "{cube:?}"
    );
    assert!(
        (cube.position[2] - 0.765).abs() < 2e-3,
        "cube not resting on the table: {cube:?}"
    );
    let outcome = evaluate(TaskKind::CubeToBin, false, &world.task_observation());
    assert!(!outcome.success);
}

#[test]
fn the_world_says_when_each_period_ends_in_whole_physics_steps() {
    let simulation = scene::load(&PathBuf::from(DEFAULT_SCENE), true).expect("the scene loads");
    // 30 Hz on 2 ms steps: periods of 16 or 17 steps, never 1/30 s.
    let mut world = World::new(simulation, 1.0 / 30.0).expect("the scene binds");
    world.settle(0.1);
    for _ in 0..90 {
        let end = world.period_end();
        let steps = (end - world.time()) / world.timestep();
        assert!(
            (steps - 16.0).abs() < 1e-6 || (steps - 17.0).abs() < 1e-6,
            "{steps}"
        );
        assert!(world.advance());
        assert!((world.time() - end).abs() < 1e-12, "{} {end}", world.time());
    }
}

fn run_demo(lite: bool) {
    let mut world = world(lite);
    let script = Script::new(&PICK_AND_PLACE);
    let start = world.time();
    let mut grasped_while_lifted = false;
    while world.time() - start < script.duration() {
        *world.targets_mut() = script.targets_at(world.time() - start);
        assert!(world.advance());
        let observation = world.task_observation();
        grasped_while_lifted |=
            observation.grasped() && observation.cube.z > observation.cube_rest_height + 0.03;
    }
    advance_seconds(&mut world, 0.5);
    let observation = world.task_observation();
    assert!(
        grasped_while_lifted,
        "the cube was never carried between both jaws"
    );
    assert!(
        observation.cube_in_bin(),
        "cube ended at {:?}",
        observation.cube
    );
    assert_eq!(
        evaluate(TaskKind::CubeToBin, false, &observation).reward,
        1.0
    );
}

#[test]
fn demo_puts_the_cube_in_the_bin_lite() {
    run_demo(true);
}

#[test]
fn demo_puts_the_cube_in_the_bin_with_meshes() {
    run_demo(false);
}

#[test]
fn bad_scenes_give_errors_not_exits() {
    let missing = scene::load(&PathBuf::from("/nonexistent/scene.xml"), false).unwrap_err();
    assert!(
        format!("{missing:#}").contains("/nonexistent/scene.xml"),
        "{missing:#}"
    );
    let dir = std::env::temp_dir().join(format!("so101-bad-scene-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.xml");
    std::fs::write(
        &bad,
        "<mujoco><worldbody><body><joint type=\"bogus\"/></body></worldbody></mujoco>",
    )
    .unwrap();
    for lite in [false, true] {
        let error = format!("{:#}", scene::load(&bad, lite).unwrap_err());
        assert!(
            error.to_lowercase().contains("bogus") || error.contains("invalid"),
            "{error}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

fn task_env(seed: u64) -> so101_sim::env::TaskEnv {
    use so101_sim::env::{TaskEnv, TaskSettings};
    let simulation = scene::load(&PathBuf::from(DEFAULT_SCENE), true).expect("the scene loads");
    let settings = TaskSettings {
        kind: TaskKind::CubeToBin,
        dense_reward: false,
    };
    TaskEnv::new(simulation, 30.0, settings, seed).expect("the scene binds")
}

#[test]
fn task_env_resets_settle_the_arm_and_seeds_repeat_episodes() {
    use so101_sim::env::SETTLE_SECONDS;
    let mut env = task_env(0);
    let first = env.reset(Some(9));
    let settled = env.observe();
    // The arm sagged under gravity while settling, and came to rest.
    assert!(
        settled.arm.position[1].abs() > 1e-3,
        "{:?}",
        settled.arm.position
    );
    assert!(settled.arm.velocity.iter().all(|v| v.abs() < 0.05));
    assert!((settled.time - SETTLE_SECONDS).abs() < 1e-9);
    let targets = [0.4, -0.3, 0.3, 0.6, 0.2, 0.5];
    let trajectory: Vec<_> = (0..60)
        .map(|_| {
            env.step(&targets);
            env.observe().state_vector()
        })
        .collect();
    // A reset without a seed goes on with the sequence; with the seed it starts it over.
    assert_ne!(env.reset(None), first);
    assert_eq!(env.reset(Some(9)), first);
    let again: Vec<_> = (0..60)
        .map(|_| {
            env.step(&targets);
            env.observe().state_vector()
        })
        .collect();
    assert_eq!(trajectory, again);
    // Non-finite targets keep the previous ones; out-of-range ones are clamped.
    env.step(&[f64::NAN, 0.0, 0.0, 0.0, 0.0, 9.0]);
    let limits = *env.world().limits();
    let held = *env.world_mut().targets_mut();
    assert_eq!(held[0], 0.4);
    assert_eq!(held[5], limits[5].max);
}

#[test]
fn the_emulators_joint_loads_are_the_scenes_at_home() {
    use so101_core::servo::ARM_LOADS;
    let simulation = scene::load(&PathBuf::from(DEFAULT_SCENE), true).expect("the scene loads");
    let world = World::new(simulation, 1.0 / RATE_HZ).expect("the scene binds");
    let sim = world.simulation();
    let mut scene_loads = Vec::new();
    for joint in 0..JOINT_COUNT {
        let id = sim
            .id(
                so101_sim::mujoco::ObjectKind::Joint,
                so101_core::robot::JOINT_NAMES[joint],
            )
            .expect("every joint is in the scene");
        let dof = sim.joint_dof_address(id);
        let (_, _, armature) = sim.dof_friction(dof);
        let inertia = sim.dof_inertia(dof) - armature;
        let gravity = sim.dof_bias(dof);
        println!("joint {joint}: inertia {inertia:.6} gravity {gravity:.4}");
        scene_loads.push((inertia, gravity));
    }
    for (joint, (load, (inertia, gravity))) in ARM_LOADS.iter().zip(scene_loads).enumerate() {
        assert!(
            (load.inertia - inertia).abs() <= 0.1 * inertia.abs() + 1e-5,
            "joint {joint}: inertia {inertia} in the scene, {} in ARM_LOADS",
            load.inertia
        );
        assert!(
            (load.gravity_torque - gravity).abs() <= 0.1 * gravity.abs() + 1e-3,
            "joint {joint}: gravity {gravity} in the scene, {} in ARM_LOADS",
            load.gravity_torque
        );
    }
}

#[test]
fn only_stack_cube_stands_the_green_cube_on_the_table_from_its_first_episode() {
    use so101_core::expert::SIM_STACK_BASE_IN_WORLD;
    use so101_sim::env::{TaskEnv, TaskSettings};
    let env_of = |kind| {
        let simulation = scene::load(&PathBuf::from(DEFAULT_SCENE), true).expect("the scene loads");
        let settings = TaskSettings {
            kind,
            dense_reward: false,
        };
        TaskEnv::new(simulation, 30.0, settings, 0).expect("the scene binds")
    };
    let base_of = |env: &TaskEnv| {
        env.world()
            .task_observation()
            .stack_base
            .expect("the scene has the green cube")
            .centre
    };
    let mut stack = env_of(TaskKind::StackCube);
    let [x, y, z] = SIM_STACK_BASE_IN_WORLD;
    // Before any reset (the sim node's first episode), after a second, and after resets.
    for _ in 0..2 {
        let centre = base_of(&stack);
        assert!(
            (centre.x - x).abs() < 1e-3 && (centre.y - y).abs() < 1e-3,
            "{centre:?}"
        );
        assert!((centre.z - z).abs() < 1e-3, "{centre:?}");
        for _ in 0..30 {
            stack.step(&[0.0; JOINT_COUNT]);
        }
        let settled = base_of(&stack);
        assert!(
            (settled - centre).norm() < 1e-3,
            "it stands still: {settled:?}"
        );
        stack.reset(None);
    }
    // Every other task: parked on the floor, far from the arm.
    let bin = env_of(TaskKind::CubeToBin);
    assert!(base_of(&bin).z < 0.1, "{:?}", base_of(&bin));
}
