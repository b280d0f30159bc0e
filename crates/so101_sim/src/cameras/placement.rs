//! Camera placements measured on a user's desk (`so101-camera-align estimate` writes them): each
//! fixed camera's pose in the arm's base frame, its vertical field of view and its frame size.
//! Read once where the option is taken; put into the compiled model before anything reads the
//! cameras, so domain randomization jitters around the real viewpoints.

use std::{collections::BTreeMap, path::Path};

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::Deserialize;
use so101_core::kinematics::BASE_LINK;

use super::spec::{is_camera_name, FrameSize, MAX_SIDE};
use crate::mujoco::{ObjectKind, Simulation};

/// Farthest a camera may sit from the arm's base (m): beyond it a file is a mistake (millimetres
/// written as metres), not a desk.
pub const MAX_DISTANCE: f64 = 10.0;

/// One camera as the file gives it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraPlacement {
    /// Metres, in the arm's base frame.
    pub position: [f64; 3],
    /// MuJoCo's camera frame (it looks along -z, +y up) in the base frame, as w, x, y, z.
    pub quaternion: [f64; 4],
    /// Vertical field of view (degrees) of the real camera's height.
    pub fovy: f64,
    pub width: u32,
    pub height: u32,
    /// How the placement was estimated (board corners, reprojection error, the real intrinsics):
    /// kept for the user, not read by the simulation.
    #[serde(default)]
    pub estimate: Option<toml::Table>,
}

impl CameraPlacement {
    pub fn size(&self) -> FrameSize {
        FrameSize {
            width: self.width,
            height: self.height,
        }
    }

    fn check(&self, name: &str) -> Result<(), String> {
        if !is_camera_name(name) {
            return Err(format!(
                "[{name}]: a camera name is letters, digits and '_'"
            ));
        }
        let distance = self.position.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !distance.is_finite() || distance > MAX_DISTANCE {
            return Err(format!(
                "[{name}] position {:?}: metres from the arm's base, within {MAX_DISTANCE} m",
                self.position
            ));
        }
        let norm = self.quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !norm.is_finite() || (norm - 1.0).abs() > 1e-3 {
            return Err(format!(
                "[{name}] quaternion {:?}: a unit quaternion w, x, y, z (norm {norm})",
                self.quaternion
            ));
        }
        if !(self.fovy > 1.0 && self.fovy < 179.0) {
            return Err(format!(
                "[{name}] fovy {}: degrees, between 1 and 179",
                self.fovy
            ));
        }
        for (side, value) in [("width", self.width), ("height", self.height)] {
            if !(1..=MAX_SIDE).contains(&value) {
                return Err(format!(
                    "[{name}] {side} {value}: pixels, from 1 to {MAX_SIDE}"
                ));
            }
        }
        Ok(())
    }

    /// The orientation as a unit quaternion (the file's, normalized).
    fn orientation(&self) -> UnitQuaternion<f64> {
        unit(self.quaternion)
    }
}

/// The cameras of one file, by name, and the file's path (what logs and parameters show).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CameraPlacements {
    pub source: String,
    pub cameras: BTreeMap<String, CameraPlacement>,
}

#[derive(Debug, thiserror::Error)]
pub enum PlacementError {
    #[error("cannot read the camera placements {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("camera placements {path}: {message}")]
    Invalid { path: String, message: String },
}

impl CameraPlacements {
    pub fn load(path: &Path) -> Result<Self, PlacementError> {
        let text = std::fs::read_to_string(path).map_err(|source| PlacementError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_toml(&text, &path.display().to_string())
    }

    /// The placements of a TOML text, one table per camera; `source` names it in errors.
    pub fn from_toml(text: &str, source: &str) -> Result<Self, PlacementError> {
        let invalid = |message: String| PlacementError::Invalid {
            path: source.to_owned(),
            message,
        };
        let cameras: BTreeMap<String, CameraPlacement> =
            toml::from_str(text).map_err(|error| invalid(error.message().to_owned()))?;
        if cameras.is_empty() {
            return Err(invalid("no camera: one [NAME] table per camera".to_owned()));
        }
        for (name, camera) in &cameras {
            camera.check(name).map_err(invalid)?;
        }
        Ok(Self {
            source: source.to_owned(),
            cameras,
        })
    }

    /// The frame size the file gives `camera`, if it places it.
    pub fn size(&self, camera: &str) -> Option<FrameSize> {
        self.cameras.get(camera).map(CameraPlacement::size)
    }

    /// Moves every camera of the file to its place in `sim`'s compiled model. A camera the scene
    /// lacks, or one that rides a moving body (the wrist camera), is refused: only a camera fixed
    /// in the world can be placed from a picture of a board on the table.
    pub fn apply(&self, sim: &mut Simulation) -> Result<(), PlacementError> {
        let invalid = |message: String| PlacementError::Invalid {
            path: self.source.clone(),
            message,
        };
        let base = sim.id(ObjectKind::Body, BASE_LINK).ok_or_else(|| {
            invalid(format!(
                "the scene has no body {BASE_LINK:?} to place cameras from"
            ))
        })?;
        sim.forward();
        let (base_position, base_orientation) = sim.body_pose(base);
        let base_to_world = Pose {
            position: Vector3::from(base_position),
            orientation: unit(base_orientation),
        };
        for (name, camera) in &self.cameras {
            let id = sim
                .id(ObjectKind::Camera, name)
                .ok_or_else(|| invalid(format!("the scene has no camera {name:?}")))?;
            if sim.camera_body(id) != 0 {
                return Err(invalid(format!(
                    "camera {name:?} rides the arm; only cameras fixed in the world can be placed"
                )));
            }
            let in_world = base_to_world.compose(&Pose {
                position: Vector3::from(camera.position),
                orientation: camera.orientation(),
            });
            let q = in_world.orientation.quaternion();
            sim.set_camera_frame(
                id,
                in_world.position.into(),
                [q.w, q.i, q.j, q.k],
                camera.fovy,
            );
        }
        sim.forward();
        Ok(())
    }
}

/// A rigid transform: child frame in parent frame.
struct Pose {
    position: Vector3<f64>,
    orientation: UnitQuaternion<f64>,
}

impl Pose {
    /// `child` (given in this pose's frame) in this pose's parent frame.
    fn compose(&self, child: &Pose) -> Pose {
        Pose {
            position: self.position + self.orientation * child.position,
            orientation: self.orientation * child.orientation,
        }
    }
}

fn unit([w, x, y, z]: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
}

#[cfg(test)]
mod tests {
    use super::*;

    const TOP: &str = r#"
[top]
position = [0.15, -0.05, 0.80]
quaternion = [0.7071067811865476, 0.0, 0.0, -0.7071067811865476]
fovy = 48.5
width = 640
height = 480

[top.estimate]
reprojection_rms_px = 0.4
"#;

    #[test]
    fn a_file_gives_each_camera_its_pose_field_of_view_and_size() {
        let placements = CameraPlacements::from_toml(TOP, "test").unwrap();
        let top = &placements.cameras["top"];
        assert_eq!(top.position, [0.15, -0.05, 0.80]);
        assert_eq!(top.fovy, 48.5);
        assert_eq!(
            placements.size("top"),
            Some(FrameSize {
                width: 640,
                height: 480
            })
        );
        assert_eq!(placements.size("front"), None);
    }

    #[test]
    fn bad_files_are_refused_naming_the_camera_and_field() {
        let cases = [
            ("", "no camera"),
            ("[top]\nposition = [0, 0, 1]\n", "missing field"),
            (&TOP.replace("0.80]", "800.0]"), "position"),
            (&TOP.replace("-0.7071067811865476]", "0.5]"), "quaternion"),
            (&TOP.replace("48.5", "0.0"), "fovy"),
            (&TOP.replace("48.5", "nan"), "fovy"),
            (&TOP.replace("640", "0"), "width"),
            (
                &TOP.replace("[top]", "[\"to p\"]")
                    .replace("[top.", "[\"to p\"."),
                "name",
            ),
            (&TOP.replace("fovy", "fov"), "unknown field"),
        ];
        for (text, expected) in cases {
            let error = CameraPlacements::from_toml(text, "cams.toml")
                .expect_err(text)
                .to_string();
            assert!(error.contains("cams.toml"), "{error}");
            assert!(error.contains(expected), "{expected:?} not in {error}");
        }
    }

    #[test]
    fn composing_poses_turns_then_shifts() {
        let quarter_turn =
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.5 * std::f64::consts::PI);
        let parent = Pose {
            position: Vector3::new(0.0, 0.0, 0.75),
            orientation: quarter_turn,
        };
        let child = Pose {
            position: Vector3::new(1.0, 0.0, 0.0),
            orientation: UnitQuaternion::identity(),
        };
        let composed = parent.compose(&child);
        assert!((composed.position - Vector3::new(0.0, 1.0, 0.75)).norm() < 1e-12);
        assert!(composed.orientation.angle_to(&quarter_turn) < 1e-12);
    }
}
