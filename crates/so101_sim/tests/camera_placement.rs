//! Camera placements put into the project's scene: a placed camera stands where the file says, in
//! the arm's base frame, and one that cannot be placed is refused by name.

use std::path::PathBuf;

use so101_core::robot::DEFAULT_SCENE;
use so101_sim::{
    cameras::placement::CameraPlacements,
    mujoco::{ObjectKind, Simulation},
    scene,
};

fn scene() -> Simulation {
    scene::load(&PathBuf::from(DEFAULT_SCENE), true).expect("the scene loads")
}

/// A quarter turn about the base's z: the camera's x along the base's y.
const PLACED_TOP: &str = r#"
[top]
position = [0.1, 0.2, 0.5]
quaternion = [0.7071067811865476, 0.0, 0.0, 0.7071067811865476]
fovy = 40.0
width = 320
height = 240
"#;

#[test]
fn a_placed_camera_stands_where_the_file_says_in_the_base_frame() {
    let mut sim = scene();
    let top = sim.id(ObjectKind::Camera, "top").unwrap();
    let base = sim.id(ObjectKind::Body, "base").unwrap();
    CameraPlacements::from_toml(PLACED_TOP, "test")
        .unwrap()
        .apply(&mut sim)
        .unwrap();
    let (base_position, _) = sim.body_pose(base);
    let (position, fovy) = sim.camera_pose(top);
    let expected = [
        base_position[0] + 0.1,
        base_position[1] + 0.2,
        base_position[2] + 0.5,
    ];
    for axis in 0..3 {
        assert!(
            (position[axis] - expected[axis]).abs() < 1e-12,
            "{position:?} {expected:?}"
        );
    }
    assert_eq!(fovy, 40.0);
    // The camera's x axis (the first column of its rotation) along the base's (the world's) +y.
    let rotation = sim.camera_rotation(top);
    let x_axis = [rotation[0], rotation[3], rotation[6]];
    assert!((x_axis[1] - 1.0).abs() < 1e-9, "{x_axis:?}");
}

#[test]
fn a_camera_on_the_arm_or_missing_from_the_scene_is_refused_by_name() {
    for (name, expected) in [("wrist", "rides the arm"), ("side", "no camera \"side\"")] {
        let text = PLACED_TOP.replace("[top]", &format!("[{name}]"));
        let error = CameraPlacements::from_toml(&text, "cams.toml")
            .unwrap()
            .apply(&mut scene())
            .unwrap_err()
            .to_string();
        assert!(error.contains(expected), "{error}");
        assert!(error.contains("cams.toml"), "{error}");
    }
}
