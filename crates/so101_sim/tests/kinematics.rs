//! The shared kinematic model (so101_core::kinematics) against MuJoCo on the sim's own scene: the
//! grasp point and every link frame agree for random joint positions.

use std::path::PathBuf;

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use so101_core::{
    kinematics::{self, ArmPositions, ARM_JOINTS, SIM_BASE_IN_WORLD},
    robot::{DEFAULT_SCENE, JOINT_LIMITS, JOINT_NAMES},
};
use so101_sim::{
    mujoco::{ObjectKind, Simulation},
    scene,
};

const LINKS: [&str; ARM_JOINTS] = ["shoulder", "upper_arm", "lower_arm", "wrist", "gripper"];

fn pose_arm(sim: &mut Simulation, joints: &ArmPositions) {
    for (name, value) in JOINT_NAMES.iter().zip(joints) {
        let joint = sim.id(ObjectKind::Joint, name).expect("joint in the scene");
        let address = sim.joint_qpos_address(joint);
        sim.qpos_mut()[address] = *value;
    }
    sim.forward();
}

#[test]
fn forward_kinematics_matches_mujoco_within_a_micrometre() {
    let mut sim = scene::load(&PathBuf::from(DEFAULT_SCENE), true).expect("the scene loads");
    let tip = sim
        .id(ObjectKind::Site, "gripper_tip")
        .expect("gripper_tip site");
    let base = Vector3::from(SIM_BASE_IN_WORLD);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut worst_position: f64 = 0.0;
    let mut worst_angle: f64 = 0.0;
    for _ in 0..200 {
        let joints: ArmPositions =
            std::array::from_fn(|j| rng.gen_range(JOINT_LIMITS[j].min..JOINT_LIMITS[j].max));
        pose_arm(&mut sim, &joints);

        let model = kinematics::grasp_frame(&joints);
        let mujoco_position = Vector3::from(sim.site_position(tip)) - base;
        worst_position = worst_position.max((model.translation.vector - mujoco_position).norm());
        let mujoco_rotation =
            UnitQuaternion::from_matrix(&Matrix3::from_row_slice(&sim.site_rotation(tip)));
        worst_angle = worst_angle.max(model.rotation.angle_to(&mujoco_rotation));

        for (frame, name) in kinematics::link_frames(&joints).iter().zip(LINKS) {
            let body = sim.id(ObjectKind::Body, name).expect("link body");
            let (position, [w, x, y, z]) = sim.body_pose(body);
            let mujoco = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
            let offset = (frame.translation.vector - (Vector3::from(position) - base)).norm();
            assert!(offset < 1e-6, "{name} at {joints:?}: {offset} m off");
            assert!(
                frame.rotation.angle_to(&mujoco) < 1e-5,
                "{name} at {joints:?}"
            );
        }
    }
    assert!(
        worst_position < 1e-6,
        "grasp point off by {worst_position} m"
    );
    assert!(
        worst_angle < 1e-5,
        "grasp frame turned by {worst_angle} rad"
    );
}

#[test]
fn inverse_kinematics_puts_mujocos_grasp_point_on_the_target() {
    let mut sim = scene::load(&PathBuf::from(DEFAULT_SCENE), true).expect("the scene loads");
    let tip = sim
        .id(ObjectKind::Site, "gripper_tip")
        .expect("gripper_tip site");
    let limits = kinematics::arm_limits();
    // Straight-down grasps over the sim's cube spawn area, solved from home.
    for (x, y) in [
        (0.18, -0.08),
        (0.28, -0.08),
        (0.23, 0.0),
        (0.18, 0.08),
        (0.28, 0.08),
    ] {
        let target = kinematics::TaskPose {
            position: Vector3::new(x, y, 0.017),
            pitch: std::f64::consts::FRAC_PI_2,
            roll: 0.2,
        };
        let solution = kinematics::solve(
            &target,
            &[0.0; ARM_JOINTS],
            &limits,
            &kinematics::IkOptions::default(),
        );
        assert!(solution.reached, "({x}, {y}): {solution:?}");
        pose_arm(&mut sim, &solution.joints);
        let reached = Vector3::from(sim.site_position(tip)) - Vector3::from(SIM_BASE_IN_WORLD);
        let error = (reached - target.position).norm();
        assert!(
            error <= 1e-3,
            "({x}, {y}): MuJoCo's grasp point {error} m off"
        );
    }
}
