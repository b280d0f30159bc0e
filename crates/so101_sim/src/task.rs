//! Reward and success of the tasks (the ones the Gymnasium SO-100 environments offered),
//! computed from a few geometric facts about the scene. Pure: the physics side fills in
//! [`TaskObservation`]. The tasks' facts (names, ids, episode lengths) are so101_core::task's.

use nalgebra::{Matrix3, Vector3};

pub use so101_core::task::TaskKind;

/// Tip-to-cube-centre distance under which the gripper counts as touching the cube (m): half the
/// 3 cm cube plus 1.5 cm for the finger pads.
pub const TOUCH_DISTANCE: f64 = 0.03;
/// How far from its resting height a placed cube's centre may be (m): down on the table, not
/// still falling from the jaws nor leaning on an edge.
pub const PLACED_HEIGHT_TOLERANCE: f64 = 0.003;
/// Height above its resting height at which a grasped cube counts as fully lifted (m).
pub const LIFT_HEIGHT: f64 = 0.05;

/// A box-shaped region (the inside of the bin), as a centre, rotation and half extents.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrientedBox {
    pub center: Vector3<f64>,
    pub rotation: Matrix3<f64>,
    pub half_extents: Vector3<f64>,
}

impl OrientedBox {
    /// A region nothing is in.
    pub const EMPTY: Self = Self {
        center: Vector3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY),
        rotation: Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        half_extents: Vector3::new(0.0, 0.0, 0.0),
    };

    pub fn contains(&self, point: &Vector3<f64>) -> bool {
        let local = self.rotation.transpose() * (point - self.center);
        (0..3).all(|axis| local[axis].abs() <= self.half_extents[axis])
    }
}

/// stack_cube's green cube at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StackBase {
    pub centre: Vector3<f64>,
    /// Height of its centre when it stands on the table.
    pub rest_height: f64,
    /// Half its edge.
    pub half_edge: f64,
}

/// What the tasks need to know about the scene at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskObservation {
    pub gripper_tip: Vector3<f64>,
    pub cube: Vector3<f64>,
    /// Height of the cube centre when it rests on the table.
    pub cube_rest_height: f64,
    pub bin_goal: Vector3<f64>,
    pub bin_inside: OrientedBox,
    /// place_cube's pad: where a placed cube's centre rests.
    pub place_pad: OrientedBox,
    /// push_cube's round target: its centre on the table, and its radius.
    pub push_target: Vector3<f64>,
    pub push_target_radius: f64,
    /// stack_cube's green cube (none in a scene without it).
    pub stack_base: Option<StackBase>,
    /// The fixed jaw touches the cube.
    pub fixed_jaw_contact: bool,
    /// The moving jaw touches the cube.
    pub moving_jaw_contact: bool,
}

impl TaskObservation {
    fn tip_to_cube(&self) -> f64 {
        (self.gripper_tip - self.cube).norm()
    }

    pub fn touching(&self) -> bool {
        self.fixed_jaw_contact || self.moving_jaw_contact || self.tip_to_cube() < TOUCH_DISTANCE
    }

    pub fn grasped(&self) -> bool {
        self.fixed_jaw_contact && self.moving_jaw_contact
    }

    pub fn cube_in_bin(&self) -> bool {
        self.bin_inside.contains(&self.cube)
    }

    /// How far the cube is lifted, 0 to 1 ([`LIFT_HEIGHT`] above its rest), while grasped.
    fn lift(&self) -> f64 {
        if self.grasped() {
            ((self.cube.z - self.cube_rest_height) / LIFT_HEIGHT).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// The cube let go on the pad: its centre over the pad, down at its resting height (not
    /// falling, not tipped onto an edge), no jaw touching it.
    pub fn placed(&self) -> bool {
        self.place_pad.contains(&self.cube) && self.resting_let_go(self.cube_rest_height)
    }

    /// Down at its resting height on the table (not lifted, not tipped onto an edge), no jaw
    /// touching it.
    fn resting_let_go(&self, rest_height: f64) -> bool {
        (self.cube.z - rest_height).abs() < PLACED_HEIGHT_TOLERANCE
            && !self.fixed_jaw_contact
            && !self.moving_jaw_contact
    }

    /// Horizontal distance from the cube's centre to push_cube's target.
    fn cube_to_push_target(&self) -> f64 {
        (self.cube - self.push_target).xy().norm()
    }

    /// The cube on the table with its centre inside push_cube's target, no jaw touching it.
    pub fn on_push_target(&self) -> bool {
        self.cube_to_push_target() < self.push_target_radius
            && self.resting_let_go(self.cube_rest_height)
    }

    /// The cube resting on the green cube (which stands on the table), no jaw touching it: its
    /// centre over the green cube's top face, whichever way either is turned (within the face's
    /// inscribed circle), so it stays there; at the height of a cube lying on it.
    pub fn stacked(&self) -> bool {
        let Some(base) = self.stack_base else {
            return false;
        };
        let base_standing = (base.centre.z - base.rest_height).abs() < PLACED_HEIGHT_TOLERANCE;
        let over_base = (self.cube - base.centre).xy().norm() < base.half_edge;
        base_standing
            && over_base
            && self.resting_let_go(self.cube_rest_height + 2.0 * base.half_edge)
    }

    /// The cube held in both jaws, [`LIFT_HEIGHT`] above its rest: lift_cube's success.
    pub fn lifted(&self) -> bool {
        self.lift() >= 1.0
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskOutcome {
    pub reward: f64,
    pub success: bool,
}

/// Scores one instant of the episode.
pub fn evaluate(kind: TaskKind, dense_shaping: bool, observation: &TaskObservation) -> TaskOutcome {
    match kind {
        TaskKind::TouchCube => TaskOutcome {
            reward: -observation.tip_to_cube(),
            success: observation.touching(),
        },
        TaskKind::TouchCubeSparse => {
            let success = observation.touching();
            TaskOutcome {
                reward: f64::from(u8::from(success)),
                success,
            }
        }
        TaskKind::CubeToBin => goal_outcome(observation.cube_in_bin(), dense_shaping, || {
            staged_shaping(observation, observation.bin_goal)
        }),
        TaskKind::PlaceCube => goal_outcome(observation.placed(), dense_shaping, || {
            staged_shaping(observation, observation.place_pad.center)
        }),
        TaskKind::LiftCube => goal_outcome(observation.lifted(), dense_shaping, || {
            approach_grasp_lift(observation)
        }),
        TaskKind::StackCube => goal_outcome(observation.stacked(), dense_shaping, || {
            observation
                .stack_base
                .map_or(0.0, |base| staged_shaping(observation, base.centre))
        }),
        TaskKind::PushCube => goal_outcome(observation.on_push_target(), dense_shaping, || {
            push_shaping(observation)
        }),
    }
}

/// push_cube's shaping in [0, 0.8]: the gripper at the cube (up to 0.2), the cube near the
/// target (up to 0.6).
fn push_shaping(observation: &TaskObservation) -> f64 {
    let approach = 1.0 - (10.0 * observation.tip_to_cube()).tanh();
    let near = 1.0 - (10.0 * observation.cube_to_push_target()).tanh();
    0.2 * approach + 0.6 * near
}

/// A goal task's outcome: 1 once the goal holds; before it, 0, or with `dense_shaping` the
/// task's shaping (below 1).
fn goal_outcome(success: bool, dense_shaping: bool, shaping: impl FnOnce() -> f64) -> TaskOutcome {
    let reward = match (success, dense_shaping) {
        (true, _) => 1.0,
        (false, false) => 0.0,
        (false, true) => shaping(),
    };
    TaskOutcome { reward, success }
}

/// The first three stages of the staged shaping, each worth up to 0.2: approach the cube, grasp
/// it, lift it.
fn approach_grasp_lift(observation: &TaskObservation) -> f64 {
    let approach = 1.0 - (10.0 * observation.tip_to_cube()).tanh();
    0.2 * (approach + f64::from(u8::from(observation.grasped())) + observation.lift())
}

/// Staged shaping in [0, 0.8]: approach the cube, grasp it, lift it, carry it over `goal`. Each
/// stage adds up to 0.2, so any unfinished episode scores below success (1.0).
fn staged_shaping(observation: &TaskObservation, goal: Vector3<f64>) -> f64 {
    let place = if observation.lift() > 0.0 {
        let horizontal = (observation.cube - goal).xy().norm();
        1.0 - (10.0 * horizontal).tanh()
    } else {
        0.0
    };
    approach_grasp_lift(observation) + 0.2 * place
}

#[cfg(test)]
mod tests {
    use super::*;

    fn observation() -> TaskObservation {
        TaskObservation {
            gripper_tip: Vector3::new(0.0, 0.0, 0.3),
            cube: Vector3::new(0.2, 0.0, 0.015),
            cube_rest_height: 0.015,
            bin_goal: Vector3::new(0.0, 0.25, 0.02),
            bin_inside: OrientedBox {
                center: Vector3::new(0.0, 0.25, 0.04),
                rotation: Matrix3::identity(),
                half_extents: Vector3::new(0.05, 0.05, 0.04),
            },
            place_pad: OrientedBox {
                center: Vector3::new(0.2, 0.18, 0.015),
                rotation: Matrix3::identity(),
                half_extents: Vector3::new(0.025, 0.025, 0.015),
            },
            push_target: Vector3::new(0.26, 0.13, 0.0),
            push_target_radius: 0.03,
            stack_base: Some(StackBase {
                centre: Vector3::new(0.2, 0.18, 0.015),
                rest_height: 0.015,
                half_edge: 0.015,
            }),
            fixed_jaw_contact: false,
            moving_jaw_contact: false,
        }
    }

    #[test]
    fn touch_cube_dense_reward_is_minus_the_distance() {
        let far = observation();
        let outcome = evaluate(TaskKind::TouchCube, false, &far);
        assert!((outcome.reward + (0.04f64 + 0.285 * 0.285).sqrt()).abs() < 1e-12);
        assert!(!outcome.success);
        let near = TaskObservation {
            gripper_tip: Vector3::new(0.2, 0.0, 0.03),
            ..far
        };
        let outcome = evaluate(TaskKind::TouchCube, false, &near);
        assert!(outcome.success && outcome.reward > -TOUCH_DISTANCE);
    }

    #[test]
    fn touch_cube_sparse_counts_contact_or_proximity() {
        let mut obs = observation();
        assert_eq!(
            evaluate(TaskKind::TouchCubeSparse, false, &obs),
            TaskOutcome {
                reward: 0.0,
                success: false
            }
        );
        obs.moving_jaw_contact = true;
        assert_eq!(
            evaluate(TaskKind::TouchCubeSparse, false, &obs),
            TaskOutcome {
                reward: 1.0,
                success: true
            }
        );
    }

    #[test]
    fn cube_to_bin_succeeds_only_inside_the_bin() {
        let mut obs = observation();
        assert_eq!(
            evaluate(TaskKind::CubeToBin, false, &obs),
            TaskOutcome {
                reward: 0.0,
                success: false
            }
        );
        obs.cube = Vector3::new(0.01, 0.24, 0.015);
        assert_eq!(
            evaluate(TaskKind::CubeToBin, false, &obs),
            TaskOutcome {
                reward: 1.0,
                success: true
            }
        );
        assert_eq!(evaluate(TaskKind::CubeToBin, true, &obs).reward, 1.0);
        // Just outside a wall, or above the rim, is not in.
        obs.cube = Vector3::new(0.06, 0.25, 0.02);
        assert!(!evaluate(TaskKind::CubeToBin, false, &obs).success);
        obs.cube = Vector3::new(0.0, 0.25, 0.09);
        assert!(!evaluate(TaskKind::CubeToBin, false, &obs).success);
    }

    #[test]
    fn lift_cube_succeeds_only_held_in_both_jaws_high_enough() {
        let mut obs = observation();
        obs.gripper_tip = obs.cube;
        obs.cube.z += LIFT_HEIGHT;
        // Lifted but not held (thrown, or resting on something): no success.
        obs.fixed_jaw_contact = true;
        assert!(!evaluate(TaskKind::LiftCube, false, &obs).success);
        obs.moving_jaw_contact = true;
        assert_eq!(
            evaluate(TaskKind::LiftCube, true, &obs),
            TaskOutcome {
                reward: 1.0,
                success: true
            }
        );
        // Held, 1 cm short: the dense reward grows with the height, below success.
        obs.cube.z -= 0.01;
        let short = evaluate(TaskKind::LiftCube, true, &obs);
        obs.cube.z -= 0.02;
        let lower = evaluate(TaskKind::LiftCube, true, &obs);
        assert!(!short.success && lower.reward < short.reward && short.reward < 0.6 + 1e-12);
        assert_eq!(evaluate(TaskKind::LiftCube, false, &obs).reward, 0.0);
    }

    #[test]
    fn place_cube_succeeds_only_let_go_on_the_pad() {
        let mut obs = observation();
        assert!(!evaluate(TaskKind::PlaceCube, false, &obs).success);
        obs.cube = Vector3::new(0.21, 0.17, 0.015);
        obs.fixed_jaw_contact = true;
        obs.moving_jaw_contact = true;
        // Still held: not placed.
        assert!(!evaluate(TaskKind::PlaceCube, false, &obs).success);
        obs.fixed_jaw_contact = false;
        obs.moving_jaw_contact = false;
        assert_eq!(
            evaluate(TaskKind::PlaceCube, true, &obs),
            TaskOutcome {
                reward: 1.0,
                success: true
            }
        );
        // A scene without a pad: nowhere is placed.
        let padless = TaskObservation {
            place_pad: OrientedBox::EMPTY,
            ..obs
        };
        assert!(!evaluate(TaskKind::PlaceCube, false, &padless).success);
        // Beside the pad, or dropped from above it (still falling, 5 mm up): no.
        obs.cube = Vector3::new(0.25, 0.18, 0.015);
        assert!(!evaluate(TaskKind::PlaceCube, false, &obs).success);
        obs.cube = Vector3::new(0.2, 0.18, 0.02);
        assert!(!evaluate(TaskKind::PlaceCube, false, &obs).success);
    }

    #[test]
    fn push_cube_succeeds_only_resting_on_the_target_let_go() {
        let mut obs = observation();
        assert!(!evaluate(TaskKind::PushCube, false, &obs).success);
        // 2.5 cm from the target's centre, inside its 3 cm radius.
        obs.cube = Vector3::new(0.26, 0.155, 0.015);
        assert_eq!(
            evaluate(TaskKind::PushCube, true, &obs),
            TaskOutcome {
                reward: 1.0,
                success: true
            }
        );
        // Still pushed by a jaw, lifted off the table, or just outside: no.
        obs.fixed_jaw_contact = true;
        assert!(!evaluate(TaskKind::PushCube, false, &obs).success);
        obs.fixed_jaw_contact = false;
        obs.cube.z += 0.01;
        assert!(!evaluate(TaskKind::PushCube, false, &obs).success);
        obs.cube = Vector3::new(0.26, 0.165, 0.015);
        assert!(!evaluate(TaskKind::PushCube, false, &obs).success);
        // The shaping grows as the cube nears the target, below success.
        let near = evaluate(TaskKind::PushCube, true, &obs).reward;
        obs.cube = Vector3::new(0.23, 0.0, 0.015);
        let far = evaluate(TaskKind::PushCube, true, &obs).reward;
        assert!(far < near && near < 0.8, "{far} {near}");
    }

    #[test]
    fn stack_cube_succeeds_only_let_go_on_top_of_the_standing_green_cube() {
        let mut obs = observation();
        assert!(!evaluate(TaskKind::StackCube, false, &obs).success);
        // On top: the red cube's centre one edge above the green one's, 1 cm off its axis.
        obs.cube = Vector3::new(0.21, 0.18, 0.045);
        assert_eq!(
            evaluate(TaskKind::StackCube, true, &obs),
            TaskOutcome {
                reward: 1.0,
                success: true
            }
        );
        // Held there, still falling onto it, or on top of a green cube knocked onto its edge: no.
        obs.moving_jaw_contact = true;
        assert!(!evaluate(TaskKind::StackCube, false, &obs).success);
        obs.moving_jaw_contact = false;
        obs.cube.z = 0.052;
        assert!(!evaluate(TaskKind::StackCube, false, &obs).success);
        obs.cube.z = 0.045;
        let standing = obs.stack_base;
        obs.stack_base = standing.map(|base| StackBase {
            centre: base.centre + Vector3::new(0.0, 0.0, 0.006),
            ..base
        });
        assert!(!evaluate(TaskKind::StackCube, false, &obs).success);
        // At the height of a stack but with its centre past the green cube's edge (tipping off),
        // beside it on the table, or in a scene without the green cube: no.
        obs.stack_base = standing;
        obs.cube = Vector3::new(0.2, 0.197, 0.045);
        assert!(!evaluate(TaskKind::StackCube, false, &obs).success);
        obs.cube = Vector3::new(0.2, 0.215, 0.015);
        assert!(!evaluate(TaskKind::StackCube, false, &obs).success);
        obs.cube = Vector3::new(0.21, 0.18, 0.045);
        obs.stack_base = None;
        assert!(!evaluate(TaskKind::StackCube, false, &obs).success);
    }

    #[test]
    fn rotated_bin_box_is_respected() {
        let rotation =
            *nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2)
                .matrix();
        let region = OrientedBox {
            center: Vector3::zeros(),
            rotation,
            half_extents: Vector3::new(0.1, 0.01, 0.1),
        };
        assert!(region.contains(&Vector3::new(0.0, 0.09, 0.0)));
        assert!(!region.contains(&Vector3::new(0.09, 0.0, 0.0)));
    }

    #[test]
    fn dense_shaping_grows_through_the_stages_and_stays_below_success() {
        let mut obs = observation();
        let start = evaluate(TaskKind::CubeToBin, true, &obs).reward;
        obs.gripper_tip = obs.cube;
        let touching = evaluate(TaskKind::CubeToBin, true, &obs).reward;
        obs.fixed_jaw_contact = true;
        obs.moving_jaw_contact = true;
        let grasped = evaluate(TaskKind::CubeToBin, true, &obs).reward;
        obs.cube.z += LIFT_HEIGHT;
        obs.gripper_tip = obs.cube;
        let lifted = evaluate(TaskKind::CubeToBin, true, &obs).reward;
        obs.cube = Vector3::new(obs.bin_goal.x, obs.bin_goal.y, 0.2);
        obs.gripper_tip = obs.cube;
        let over_bin = evaluate(TaskKind::CubeToBin, true, &obs).reward;
        assert!(
            start < touching && touching < grasped && grasped < lifted && lifted < over_bin,
            "{start} {touching} {grasped} {lifted} {over_bin}"
        );
        assert!(over_bin < 0.8 + 1e-12);
    }
}
