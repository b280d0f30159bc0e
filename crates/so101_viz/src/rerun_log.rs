//! What the stack's messages look like in Rerun: one entity tree shared by the live bridge and the
//! bag conversion.
//!
//! - `world`: z up; `world/table`, `world/bin` (static boxes), `world/cube` (pose over time, a box);
//! - `world/base/shoulder/.../gripper/moving_jaw`: the arm, one entity per link nested as the
//!   kinematic tree, each link's transform in its parent from the shared kinematic model, its
//!   meshes (when installed) or its collision boxes as static children;
//! - `joints/<joint>/position` and `joints/<joint>/command`: time series (rad);
//! - `cameras/<camera>`: the camera images;
//! - `task/reward`, `task/success` (0 or 1): time series.
//!
//! Everything is on the `sim_time` timeline (s): the stamps of the joint states and images, and
//! for unstamped topics the latest joint-state stamp seen.

use nalgebra::Isometry3;
use rerun::{RecordingStream, RecordingStreamResult};
use so101_core::kinematics::{joint_transform, BASE_LINK, LINK_NAMES, PARENT_LINKS};
use so101_core::robot::{JointPositions, JOINT_COUNT, JOINT_NAMES};

use crate::scene_geometry::{LinkGeometry, SceneGeometry};

pub const TIMELINE: &str = "sim_time";
/// Timeline of wall-clock stamps (ROS time without a simulation).
pub const WALL_TIMELINE: &str = "ros_time";
/// Stamps from this many seconds on are wall-clock time (September 2001), not sim time.
pub const WALL_CLOCK_SINCE: f64 = 1.0e9;
const ARM_COLOR: [u8; 4] = [236, 236, 228, 255];
const BOX_COLOR: [u8; 4] = [242, 140, 40, 255];
const CUBE_COLOR: [u8; 4] = [220, 40, 40, 255];
const FURNITURE_COLOR: [u8; 4] = [150, 120, 90, 255];

/// Entity path of each of the six links (in `LINK_NAMES` order), nested under `world/base` as the
/// kinematic tree: a link's transform is then relative to its parent, as /tf has it.
pub fn link_paths() -> [String; JOINT_COUNT] {
    let mut paths: [String; JOINT_COUNT] = Default::default();
    for index in 0..JOINT_COUNT {
        let parent = PARENT_LINKS[index];
        let parent_path = if parent == BASE_LINK {
            format!("world/{BASE_LINK}")
        } else {
            let position = LINK_NAMES
                .iter()
                .position(|name| *name == parent)
                .unwrap_or(0);
            paths[position].clone()
        };
        paths[index] = format!("{parent_path}/{}", LINK_NAMES[index]);
    }
    paths
}

fn transform(pose: &Isometry3<f64>) -> rerun::Transform3D {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    rerun::Transform3D::from_translation_rotation(
        [t.x as f32, t.y as f32, t.z as f32],
        rerun::Quaternion::from_xyzw([q.i as f32, q.j as f32, q.k as f32, q.w as f32]),
    )
}

fn rgba([r, g, b, a]: [u8; 4]) -> rerun::Color {
    rerun::Color::from_unmultiplied_rgba(r, g, b, a)
}

fn boxes(geometry: &LinkGeometry, color: [u8; 4]) -> rerun::Boxes3D {
    let centers = geometry.boxes.iter().map(|b| {
        let t = b.pose.translation.vector;
        [t.x as f32, t.y as f32, t.z as f32]
    });
    let half_sizes = geometry
        .boxes
        .iter()
        .map(|b| b.half_extents.map(|h| h as f32));
    let rotations = geometry.boxes.iter().map(|b| {
        let q = b.pose.rotation.quaternion();
        rerun::Quaternion::from_xyzw([q.i as f32, q.j as f32, q.k as f32, q.w as f32])
    });
    rerun::Boxes3D::from_centers_and_half_sizes(centers, half_sizes)
        .with_quaternions(rotations)
        .with_colors([rgba(color)])
        .with_fill_mode(rerun::FillMode::Solid)
}

/// Logs the stack's messages into one recording stream.
pub struct SceneLog {
    rec: RecordingStream,
    links: [String; JOINT_COUNT],
    /// The cube's half extents, drawn once its first pose arrives (no cube on a real desk).
    cube_half_extents: std::cell::Cell<Option<[f64; 3]>>,
}

impl SceneLog {
    pub fn new(rec: RecordingStream) -> Self {
        Self {
            rec,
            links: link_paths(),
            cube_half_extents: std::cell::Cell::new(None),
        }
    }

    pub fn stream(&self) -> &RecordingStream {
        &self.rec
    }

    /// The static scene: axes, furniture, the arm's base pose and every link's shapes (meshes
    /// when `meshes` and installed, else boxes), the cube's box.
    /// (The cube's box is drawn with its first pose.)
    pub fn scene(
        &self,
        scene: &SceneGeometry,
        base_in_world: &Isometry3<f64>,
        meshes: bool,
    ) -> RecordingStreamResult<()> {
        self.rec
            .log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
        self.cube_half_extents.set(scene.cube_half_extents);
        for (name, body) in &scene.furniture {
            self.rec
                .log_static(format!("world/{name}"), &transform(&body.pose))?;
            self.rec.log_static(
                format!("world/{name}/shape"),
                &boxes(&body.geometry, FURNITURE_COLOR),
            )?;
        }
        self.rec
            .log_static(format!("world/{BASE_LINK}"), &transform(base_in_world))?;
        let link_path = |name: &str| match LINK_NAMES.iter().position(|link| *link == name) {
            Some(index) => self.links[index].clone(),
            None => format!("world/{BASE_LINK}"),
        };
        for (name, geometry) in &scene.links {
            let path = link_path(name);
            if meshes && !geometry.meshes.is_empty() {
                for (index, mesh) in geometry.meshes.iter().enumerate() {
                    let mesh_path = format!("{path}/mesh_{index}");
                    match rerun::Asset3D::from_file_path(&mesh.file) {
                        Ok(asset) => {
                            self.rec
                                .log_static(mesh_path.clone(), &transform(&mesh.pose))?;
                            self.rec.log_static(
                                mesh_path,
                                &asset.with_albedo_factor(rerun::Rgba32::from_unmultiplied_rgba(
                                    ARM_COLOR[0],
                                    ARM_COLOR[1],
                                    ARM_COLOR[2],
                                    ARM_COLOR[3],
                                )),
                            )?;
                        }
                        Err(error) => {
                            tracing::warn!(file = %mesh.file.display(), %error, "mesh not logged")
                        }
                    }
                }
            } else {
                self.rec
                    .log_static(format!("{path}/shape"), &boxes(geometry, BOX_COLOR))?;
            }
        }
        Ok(())
    }

    /// Sets the time of what is logged next: a stamp in s, sim time (from 0) or, from
    /// [`WALL_CLOCK_SINCE`] on, wall-clock time since the epoch (the physical arm's driver).
    pub fn set_time(&self, seconds: f64) {
        if seconds >= WALL_CLOCK_SINCE {
            self.rec
                .set_timestamp_secs_since_epoch(WALL_TIMELINE, seconds);
        } else {
            self.rec.set_duration_secs(TIMELINE, seconds);
        }
    }

    /// Joint positions as time series and the links posed by them.
    pub fn joint_state(&self, positions: &JointPositions) -> RecordingStreamResult<()> {
        for (index, value) in positions.iter().enumerate() {
            self.rec.log(
                format!("joints/{}/position", JOINT_NAMES[index]),
                &rerun::Scalars::single(*value),
            )?;
            self.rec.log(
                self.links[index].clone(),
                &transform(&joint_transform(index, *value)),
            )?;
        }
        Ok(())
    }

    /// The commanded targets (only the joints a command names).
    pub fn joint_command(&self, targets: &[Option<f64>; JOINT_COUNT]) -> RecordingStreamResult<()> {
        for (index, target) in targets.iter().enumerate() {
            if let Some(value) = target {
                self.rec.log(
                    format!("joints/{}/command", JOINT_NAMES[index]),
                    &rerun::Scalars::single(*value),
                )?;
            }
        }
        Ok(())
    }

    /// An RGB frame, `pixels` packed rows of `width` * 3 bytes.
    pub fn image(
        &self,
        camera: &str,
        width: u32,
        height: u32,
        pixels: Vec<u8>,
    ) -> RecordingStreamResult<()> {
        self.rec.log(
            format!("cameras/{camera}"),
            &rerun::Image::from_rgb24(pixels, [width, height]),
        )
    }

    /// A JPEG or PNG frame as it was encoded (`media_type`: image/jpeg, image/png).
    pub fn encoded_image(
        &self,
        camera: &str,
        bytes: Vec<u8>,
        media_type: &'static str,
    ) -> RecordingStreamResult<()> {
        self.rec.log(
            format!("cameras/{camera}"),
            &rerun::EncodedImage::from_file_contents(bytes).with_media_type(media_type),
        )
    }

    pub fn cube(&self, pose: &Isometry3<f64>) -> RecordingStreamResult<()> {
        if let Some(half) = self.cube_half_extents.take() {
            self.rec.log_static(
                "world/cube/shape",
                &rerun::Boxes3D::from_half_sizes([half.map(|h| h as f32)])
                    .with_colors([rgba(CUBE_COLOR)])
                    .with_fill_mode(rerun::FillMode::Solid),
            )?;
        }
        self.rec.log("world/cube", &transform(pose))
    }

    pub fn reward(&self, value: f64) -> RecordingStreamResult<()> {
        self.rec.log("task/reward", &rerun::Scalars::single(value))
    }

    pub fn success(&self, success: bool) -> RecordingStreamResult<()> {
        self.rec.log(
            "task/success",
            &rerun::Scalars::single(if success { 1.0 } else { 0.0 }),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_paths_nest_as_the_kinematic_tree() {
        let paths = link_paths();
        assert_eq!(paths[0], "world/base/shoulder");
        assert_eq!(
            paths[4],
            "world/base/shoulder/upper_arm/lower_arm/wrist/gripper"
        );
        assert_eq!(
            paths[5],
            "world/base/shoulder/upper_arm/lower_arm/wrist/gripper/moving_jaw"
        );
    }
}
