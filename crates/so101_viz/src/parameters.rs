//! The ROS parameters of the visualization nodes: their command-line settings (read-only), the
//! URDF as `robot_description` (where robot_state_publisher keeps it, for RViz and MoveIt), and
//! the bridge's image rate, which may change while it runs.

use so101_core::ros::parameters::{Declaration, Parameters, Value};

use crate::{
    app::{LiveArgs, SceneArgs},
    state_publisher,
};

fn point(point: Option<[f64; 3]>) -> Value {
    Value::DoubleArray(point.map(|xyz| xyz.to_vec()).unwrap_or_default())
}

/// so101_state_publisher's parameters; `urdf` is the description it publishes.
pub fn state_publisher(args: &state_publisher::Args, meshes: bool, urdf: &str) -> Parameters {
    Parameters::new([
        Declaration::new(
            "robot_description",
            Value::String(urdf.to_owned()),
            "The arm's URDF, as published on /robot_description.",
        ),
        Declaration::new(
            "scene",
            Value::String(args.scene.display().to_string()),
            "MJCF scene the arm's shapes are read from.",
        ),
        Declaration::new(
            "meshes",
            Value::Bool(meshes),
            "Links drawn with the scene's meshes.",
        ),
        Declaration::new(
            "mesh_uri",
            Value::choice(&args.mesh_uri),
            "How the URDF names mesh files: package:// (any machine with the package) or file://.",
        ),
        Declaration::new(
            "world_frame",
            Value::String(args.world_frame.clone()),
            "Parent frame of the arm's base.",
        ),
        Declaration::new(
            "base_xyz",
            point(args.base_xyz),
            "Base position in the world frame, m (empty: the scene's).",
        ),
        Declaration::new(
            "frame_prefix",
            Value::String(args.frame_prefix.clone()),
            "Prefix of the arm's frame names.",
        ),
    ])
}

/// The Rerun bridge's parameters.
pub fn bridge(live: &LiveArgs, scene: &SceneArgs) -> Parameters {
    let sink = match (&live.save, &live.connect) {
        (Some(path), _) => format!("save {}", path.display()),
        (None, Some(url)) => format!("connect {url}"),
        (None, None) => "spawn".to_owned(),
    };
    Parameters::new([
        Declaration::new(
            "scene",
            Value::String(scene.scene.display().to_string()),
            "MJCF scene the shapes are read from.",
        ),
        Declaration::new(
            "no_meshes",
            Value::Bool(scene.no_meshes),
            "Arm drawn with boxes.",
        ),
        Declaration::new(
            "base_xyz",
            point(scene.base_xyz),
            "Base position in the world, m.",
        ),
        Declaration::new(
            "image_rate",
            Value::Double(scene.image_rate),
            "Camera images logged per second of sim time, per camera (0: every image). Takes \
             effect at the next image.",
        )
        .dynamic()
        .float_range(0.0, 1000.0),
        Declaration::new(
            "cameras",
            Value::StringArray(live.cameras.clone()),
            "Cameras shown.",
        ),
        Declaration::new("sink", Value::String(sink), "Where the recording goes."),
    ])
}
