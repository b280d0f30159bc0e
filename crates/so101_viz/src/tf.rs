//! /tf and /tf_static from joint positions, with the shared kinematic model: what
//! robot_state_publisher does for a URDF.

use nalgebra::Isometry3;
use so101_core::kinematics::{joint_transform, BASE_LINK, GRASP_POINT, LINK_NAMES, PARENT_LINKS};
use so101_core::robot::JointPositions;
use so101_msgs::builtin_interfaces::Time;
use so101_msgs::geometry_msgs::{Quaternion, Transform, TransformStamped, Vector3};
use so101_msgs::std_msgs::Header;
use so101_msgs::tf2_msgs::TFMessage;

use crate::urdf::GRASP_LINK;

/// Frame names, optionally prefixed (`left/shoulder`) so two arms can share one tf tree.
#[derive(Debug, Clone, Default)]
pub struct Frames {
    prefix: String,
}

impl Frames {
    pub fn new(prefix: &str) -> Self {
        let prefix = prefix.trim_matches('/');
        Self {
            prefix: if prefix.is_empty() {
                String::new()
            } else {
                format!("{prefix}/")
            },
        }
    }

    pub fn name(&self, link: &str) -> String {
        format!("{}{link}", self.prefix)
    }
}

/// One transform: `child`'s pose in `parent`.
pub fn transform_stamped(
    parent: String,
    child: String,
    pose: &Isometry3<f64>,
    stamp: Time,
) -> TransformStamped {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    TransformStamped {
        header: Header {
            stamp,
            frame_id: parent,
        },
        child_frame_id: child,
        transform: Transform {
            translation: Vector3 {
                x: t.x,
                y: t.y,
                z: t.z,
            },
            rotation: Quaternion {
                x: q.i,
                y: q.j,
                z: q.k,
                w: q.w,
            },
        },
    }
}

/// The six joints' transforms (each link in its parent) at `positions`, stamped `stamp`.
pub fn joint_transforms(frames: &Frames, positions: &JointPositions, stamp: Time) -> TFMessage {
    TFMessage {
        transforms: (0..LINK_NAMES.len())
            .map(|index| {
                transform_stamped(
                    frames.name(PARENT_LINKS[index]),
                    frames.name(LINK_NAMES[index]),
                    &joint_transform(index, positions[index]),
                    stamp,
                )
            })
            .collect(),
    }
}

/// The fixed transforms: the base in `world_frame` (where the arm is mounted) and the grasp point
/// in the gripper.
pub fn static_transforms(
    frames: &Frames,
    world_frame: &str,
    base_in_world: &Isometry3<f64>,
) -> TFMessage {
    let grasp = Isometry3::translation(GRASP_POINT[0], GRASP_POINT[1], GRASP_POINT[2]);
    TFMessage {
        transforms: vec![
            transform_stamped(
                world_frame.to_owned(),
                frames.name(BASE_LINK),
                base_in_world,
                Time::default(),
            ),
            transform_stamped(
                frames.name("gripper"),
                frames.name(GRASP_LINK),
                &grasp,
                Time::default(),
            ),
        ],
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion};
    use so101_core::kinematics::{grasp_frame, link_frames};

    use super::*;

    fn isometry(transform: &Transform) -> Isometry3<f64> {
        let (t, q) = (transform.translation, transform.rotation);
        Isometry3::from_parts(
            Translation3::new(t.x, t.y, t.z),
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z)),
        )
    }

    #[test]
    fn chaining_the_transforms_gives_the_model_link_frames_and_grasp_point() {
        let positions = [0.3, -0.7, 0.9, 0.4, -1.2, 0.5];
        let frames = Frames::new("left");
        let message = joint_transforms(&frames, &positions, Time::default());
        let statics = static_transforms(&frames, "world", &Isometry3::identity());
        let mut chain = Isometry3::identity();
        let arm: [f64; 5] = std::array::from_fn(|i| positions[i]);
        let model = link_frames(&arm);
        for (index, transform) in message.transforms.iter().take(5).enumerate() {
            assert_eq!(
                transform.child_frame_id,
                format!("left/{}", LINK_NAMES[index])
            );
            chain *= isometry(&transform.transform);
            assert!((chain.translation.vector - model[index].translation.vector).norm() < 1e-12);
            assert!(chain.rotation.angle_to(&model[index].rotation) < 1e-9);
        }
        let grasp = chain * isometry(&statics.transforms[1].transform);
        assert!((grasp.translation.vector - grasp_frame(&arm).translation.vector).norm() < 1e-12);
        assert_eq!(message.transforms[5].header.frame_id, "left/gripper");
    }
}
