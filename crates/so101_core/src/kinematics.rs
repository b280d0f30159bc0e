//! Forward and inverse kinematics of the SO-101 arm (the five arm joints; the gripper does not move
//! the grasp point).
//!
//! Frames are MuJoCo body frames of the project's scene (assets/so101_cube_to_bin.xml): each link's
//! frame sits at a fixed offset from its parent's and turns about its own z axis by its joint angle.
//! Everything here is in the arm's base frame (the `base` body: the mounting plate, z up, the arm
//! pointing along +x at zero); the sim scene puts the base at (0, 0, 0.75) in its world.
//!
//! The task space of the 5-DoF arm has five coordinates: the grasp point's position, the approach
//! direction's pitch below the horizontal (pi/2: pointing straight down), and the roll of the jaws
//! about the approach direction (0: the jaws open horizontally, across the arm's vertical plane).
//! Pitch and roll are measured against the arm's azimuth (the direction from the base to the grasp
//! point), so they stay defined when the gripper points straight down.

use nalgebra::{Isometry3, Matrix5, Translation3, UnitQuaternion, Vector3, Vector5};

use crate::robot::{JointLimit, JOINT_COUNT, JOINT_LIMITS};

/// Joints that move the grasp point: shoulder_pan .. wrist_roll.
pub const ARM_JOINTS: usize = 5;

/// Positions of the five arm joints, in contract order.
pub type ArmPositions = [f64; ARM_JOINTS];

/// One link: where its frame sits in its parent's frame (translation in m, rotation as w, x, y, z).
struct LinkOffset {
    translation: [f64; 3],
    rotation: [f64; 4],
}

/// shoulder (pan), upper_arm (lift), lower_arm (elbow), wrist (flex), gripper (roll). The numbers
/// are the scene's, as written there (MuJoCo normalises the quaternions, and so does `offset`).
#[allow(clippy::approx_constant)]
const CHAIN: [LinkOffset; ARM_JOINTS] = [
    LinkOffset {
        translation: [0.0388353, -8.97657e-09, 0.0624],
        rotation: [0.0, 0.0, -1.0, 0.0],
    },
    LinkOffset {
        translation: [-0.0303992, -0.0182778, -0.0542],
        rotation: [0.5, -0.5, -0.5, -0.5],
    },
    LinkOffset {
        translation: [-0.11257, -0.028, 0.0],
        rotation: [0.707107, 0.0, 0.0, 0.707107],
    },
    LinkOffset {
        translation: [-0.1349, 0.0052, 0.0],
        rotation: [0.707107, 0.0, 0.0, -0.707107],
    },
    LinkOffset {
        translation: [0.0, -0.0611, 0.0181],
        rotation: [0.0172091, -0.0172091, 0.706897, 0.706897],
    },
];

/// The moving jaw in the gripper frame (it turns about its own z axis by the gripper joint). The
/// scene's rounded numbers, as for `CHAIN`.
#[allow(clippy::approx_constant)]
const MOVING_JAW: LinkOffset = LinkOffset {
    translation: [0.0202, 0.0188, -0.0234],
    rotation: [0.707107, 0.707107, 0.0, 0.0],
};

/// The links the six joints move, in contract order (the scene's body names); `BASE_LINK` is the
/// first joint's parent.
pub const LINK_NAMES: [&str; JOINT_COUNT] = [
    "shoulder",
    "upper_arm",
    "lower_arm",
    "wrist",
    "gripper",
    "moving_jaw",
];
pub const BASE_LINK: &str = "base";
/// The parent link of each joint: the chain's previous link, except the moving jaw, which hangs
/// off the gripper like the wrist roll's link.
pub const PARENT_LINKS: [&str; JOINT_COUNT] = [
    BASE_LINK,
    "shoulder",
    "upper_arm",
    "lower_arm",
    "wrist",
    "gripper",
];

/// The grasp point (the scene's `gripper_tip` site: the centre of a 3 cm cube held between the
/// jaw pads) in the gripper frame. The fingers point along the gripper frame's -z and the jaws
/// open along its x.
pub const GRASP_POINT: [f64; 3] = [0.007, -0.0002, -0.092];

/// Where the sim scene puts the arm's base in its world frame.
pub const SIM_BASE_IN_WORLD: [f64; 3] = [0.0, 0.0, 0.75];

fn offset(link: &LinkOffset) -> Isometry3<f64> {
    let [w, x, y, z] = link.rotation;
    Isometry3::from_parts(
        Translation3::from(Vector3::from(link.translation)),
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z)),
    )
}

/// Where joint `index`'s link sits in its parent link (`PARENT_LINKS`) at angle 0; every joint
/// turns its link about that link's own z axis.
pub fn joint_origin(index: usize) -> Isometry3<f64> {
    offset(CHAIN.get(index).unwrap_or(&MOVING_JAW))
}

/// Joint `index`'s link in its parent link at `angle` (rad).
pub fn joint_transform(index: usize, angle: f64) -> Isometry3<f64> {
    let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angle);
    joint_origin(index) * Isometry3::from_parts(Translation3::identity(), turn)
}

/// The frame of every arm link (shoulder, upper_arm, lower_arm, wrist, gripper) in the base frame.
pub fn link_frames(joints: &ArmPositions) -> [Isometry3<f64>; ARM_JOINTS] {
    let mut frame = Isometry3::identity();
    std::array::from_fn(|index| {
        frame *= joint_transform(index, joints[index]);
        frame
    })
}

/// The grasp point's frame: the gripper frame moved to the grasp point.
pub fn grasp_frame(joints: &ArmPositions) -> Isometry3<f64> {
    let gripper = link_frames(joints)[ARM_JOINTS - 1];
    gripper * Translation3::from(Vector3::from(GRASP_POINT))
}

/// A pose in the task space of the arm (base frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskPose {
    /// Grasp point, m.
    pub position: Vector3<f64>,
    /// Approach direction below the horizontal, rad (pi/2: straight down).
    pub pitch: f64,
    /// Jaw axis about the approach direction, rad (0: across the arm's vertical plane).
    pub roll: f64,
}

impl TaskPose {
    /// The difference `self - other`, angles wrapped to (-pi, pi].
    pub fn difference(&self, other: &TaskPose) -> Vector5<f64> {
        let d = self.position - other.position;
        Vector5::new(
            d.x,
            d.y,
            d.z,
            wrap_angle(self.pitch - other.pitch),
            wrap_angle(self.roll - other.roll),
        )
    }
}

/// `angle` in (-pi, pi].
pub fn wrap_angle(angle: f64) -> f64 {
    let wrapped = angle.rem_euclid(std::f64::consts::TAU);
    if wrapped > std::f64::consts::PI {
        wrapped - std::f64::consts::TAU
    } else {
        wrapped
    }
}

/// Azimuth of a base-frame point around the base's z axis.
pub fn azimuth(position: &Vector3<f64>) -> f64 {
    position.y.atan2(position.x)
}

/// The task pose of a joint configuration.
pub fn task_pose(joints: &ArmPositions) -> TaskPose {
    let frames = link_frames(joints);
    let grasp = frames[ARM_JOINTS - 1] * Translation3::from(Vector3::from(GRASP_POINT));
    let approach = grasp.rotation * -Vector3::z();
    let jaw_axis = grasp.rotation * Vector3::x();
    // The wrist_flex axis (as the lift and elbow axes) is horizontal and perpendicular to the arm's
    // vertical plane whatever the other joints do: the reference for pitch and roll, defined even
    // where the grasp point is above the base.
    let across = frames[3].rotation * Vector3::z();
    let forward = across.cross(&Vector3::z());
    let pitch = (-approach.z).atan2(approach.dot(&forward));
    let third = approach.cross(&across);
    let roll = jaw_axis.dot(&third).atan2(jaw_axis.dot(&across));
    TaskPose {
        position: grasp.translation.vector,
        pitch,
        roll,
    }
}

/// Direction the arm's vertical plane faces (rad about the base's z, 0 along +x): the plane turns
/// with shoulder_pan (positive pan turns it towards -y).
pub fn heading(joints: &ArmPositions) -> f64 {
    let across = link_frames(joints)[3].rotation * Vector3::z();
    (-across.x).atan2(across.y)
}

/// How the inverse kinematics iterates.
#[derive(Debug, Clone, Copy)]
pub struct IkOptions {
    pub max_iterations: usize,
    /// Damping of the least-squares step (m): larger is steadier near singularities, slower.
    pub damping: f64,
    /// Metres of task error one radian of pitch or roll error counts as.
    pub angle_weight: f64,
    /// Reached when the position error is below this (m) ...
    pub position_tolerance: f64,
    /// ... and the pitch and roll errors below this (rad).
    pub angle_tolerance: f64,
}

impl Default for IkOptions {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            damping: 0.005,
            angle_weight: 0.05,
            position_tolerance: 1e-4,
            angle_tolerance: 1e-3,
        }
    }
}

/// The result of [`solve`]: always within the joint limits; `reached` says whether it is the
/// target pose or only the nearest pose found (an unreachable target, or one past a limit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkSolution {
    pub joints: ArmPositions,
    pub reached: bool,
    /// Distance of the solution's grasp point from the target, m.
    pub position_error: f64,
    /// Largest of the pitch and roll errors, rad.
    pub angle_error: f64,
}

/// The arm joints' limits (the first five of the contract's).
pub fn arm_limits() -> [JointLimit; ARM_JOINTS] {
    std::array::from_fn(|joint| JOINT_LIMITS[joint])
}

/// Joint positions that put the grasp point at `target`, starting from `seed` (the current joints:
/// the solution stays near them). Damped least squares on the task error with a numerical
/// Jacobian; every iterate is clamped into `limits`, and a step is taken only when it lowers the
/// error, so the result never leaves the limits and degrades to the nearest reachable pose near
/// singularities and out of reach.
pub fn solve(
    target: &TaskPose,
    seed: &ArmPositions,
    limits: &[JointLimit; ARM_JOINTS],
    options: &IkOptions,
) -> IkSolution {
    let weights = Vector5::new(1.0, 1.0, 1.0, options.angle_weight, options.angle_weight);
    let weighted_error = |joints: &ArmPositions| {
        target
            .difference(&task_pose(joints))
            .component_mul(&weights)
    };
    let mut joints: ArmPositions = std::array::from_fn(|j| limits[j].clamp(seed[j]));
    let mut error = weighted_error(&joints);
    for _ in 0..options.max_iterations {
        if converged(&target.difference(&task_pose(&joints)), options) {
            break;
        }
        let jacobian = weighted_jacobian(&joints, &weights);
        let damping = options.damping * options.damping;
        let Some(inverse) =
            (jacobian * jacobian.transpose() + Matrix5::identity() * damping).try_inverse()
        else {
            break;
        };
        let step = jacobian.transpose() * inverse * error;
        // Halve the step until it helps (a clamped or too long step can make things worse).
        let mut scale = 1.0;
        let mut improved = false;
        while scale > 1e-3 {
            let candidate: ArmPositions =
                std::array::from_fn(|j| limits[j].clamp(joints[j] + scale * step[j]));
            let candidate_error = weighted_error(&candidate);
            if candidate_error.norm() < error.norm() {
                joints = candidate;
                error = candidate_error;
                improved = true;
                break;
            }
            scale *= 0.5;
        }
        if !improved {
            break;
        }
    }
    let difference = target.difference(&task_pose(&joints));
    IkSolution {
        joints,
        reached: converged(&difference, options),
        position_error: Vector3::new(difference[0], difference[1], difference[2]).norm(),
        angle_error: difference[3].abs().max(difference[4].abs()),
    }
}

fn converged(difference: &Vector5<f64>, options: &IkOptions) -> bool {
    Vector3::new(difference[0], difference[1], difference[2]).norm() <= options.position_tolerance
        && difference[3].abs() <= options.angle_tolerance
        && difference[4].abs() <= options.angle_tolerance
}

/// d(weighted task pose)/d(joints) by central differences.
fn weighted_jacobian(joints: &ArmPositions, weights: &Vector5<f64>) -> Matrix5<f64> {
    const STEP: f64 = 1e-6;
    let mut jacobian = Matrix5::zeros();
    for joint in 0..ARM_JOINTS {
        let mut plus = *joints;
        let mut minus = *joints;
        plus[joint] += STEP;
        minus[joint] -= STEP;
        let column = task_pose(&plus)
            .difference(&task_pose(&minus))
            .component_mul(weights)
            / (2.0 * STEP);
        jacobian.set_column(joint, &column);
    }
    jacobian
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_joints(rng: &mut impl Rng, margin: f64) -> ArmPositions {
        let limits = arm_limits();
        std::array::from_fn(|j| rng.gen_range(limits[j].min + margin..limits[j].max - margin))
    }

    #[test]
    fn at_zero_the_arm_reaches_forward_level() {
        let pose = task_pose(&[0.0; ARM_JOINTS]);
        assert!(
            pose.position.x > 0.3 && pose.position.y.abs() < 0.01,
            "{pose:?}"
        );
        assert!(pose.pitch.abs() < 1e-9, "{pose:?}");
        assert_eq!(heading(&[0.0; ARM_JOINTS]), 0.0);
        assert!((heading(&[0.4, 0.3, -0.2, 0.1, 1.0]) + 0.4).abs() < 1e-9);
    }

    #[test]
    fn positive_pan_turns_the_arm_towards_minus_y() {
        let reach = [0.0, 0.8, 0.8, 0.0, 0.0];
        let mut turned = reach;
        turned[0] = 0.5;
        let (straight, turned) = (task_pose(&reach), task_pose(&turned));
        assert!(straight.position.x > 0.1, "{straight:?}");
        assert!(turned.position.y < straight.position.y - 0.03, "{turned:?}");
    }

    #[test]
    fn ik_round_trips_within_a_tenth_of_a_millimetre_from_a_nearby_seed() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let limits = arm_limits();
        let mut worst: f64 = 0.0;
        for _ in 0..300 {
            let truth = random_joints(&mut rng, 0.2);
            let target = task_pose(&truth);
            let seed: ArmPositions =
                std::array::from_fn(|j| limits[j].clamp(truth[j] + rng.gen_range(-0.15..0.15)));
            let solution = solve(&target, &seed, &limits, &IkOptions::default());
            assert!(solution.reached, "{truth:?} from {seed:?}: {solution:?}");
            let achieved = task_pose(&solution.joints);
            worst = worst.max((achieved.position - target.position).norm());
        }
        assert!(worst <= 1e-4, "worst round-trip error {worst} m");
    }

    #[test]
    fn ik_reaches_table_top_grasps_from_home() {
        // Straight-down grasps of a cube on the table, where the sim spawns it (base frame).
        let limits = arm_limits();
        for (x, y) in [(0.18, -0.08), (0.23, 0.0), (0.25, 0.06), (0.2, 0.08)] {
            let target = TaskPose {
                position: Vector3::new(x, y, 0.017),
                pitch: std::f64::consts::FRAC_PI_2,
                roll: 0.3,
            };
            let solution = solve(&target, &[0.0; ARM_JOINTS], &limits, &IkOptions::default());
            assert!(solution.reached, "({x}, {y}): {solution:?}");
        }
    }

    #[test]
    fn unreachable_targets_give_the_nearest_pose_inside_the_limits() {
        let limits = arm_limits();
        let far = TaskPose {
            position: Vector3::new(1.0, 0.0, 0.1),
            pitch: 0.0,
            roll: 0.0,
        };
        let solution = solve(
            &far,
            &[0.0, 0.5, 0.5, 0.0, 0.0],
            &limits,
            &IkOptions::default(),
        );
        assert!(!solution.reached);
        assert!(solution.position_error > 0.5);
        for (value, limit) in solution.joints.iter().zip(limits) {
            assert!(limit.contains(*value), "{solution:?}");
        }
        // Stretched out towards it: the grasp point is farther than at the seed.
        assert!(task_pose(&solution.joints).position.x > 0.3, "{solution:?}");
    }

    #[test]
    fn angles_wrap_into_minus_pi_pi() {
        use std::f64::consts::PI;
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-0.5) + 0.5).abs() < 1e-12);
        assert!((wrap_angle(2.0 * PI + 0.25) - 0.25).abs() < 1e-12);
    }
}
