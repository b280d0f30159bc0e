//! The ROS parameters of the visualization nodes: their command-line settings (read-only), the
//! URDF as `robot_description` (where robot_state_publisher keeps it, for RViz and MoveIt), and
//! the bridge's image rate, which may change while it runs.

use so101_core::ros::parameters::{Declaration, Options, Parameters, Value};

use crate::cli::{LiveArgs, RerunArgs, SceneArgs, StatePublisherArgs, MAX_IMAGE_RATE};

fn point(point: Option<[f64; 3]>) -> Value {
    Value::DoubleArray(point.map(|xyz| xyz.to_vec()).unwrap_or_default())
}

/// so101_state_publisher's parameters; `urdf` is the description it publishes.
pub fn state_publisher(args: &StatePublisherArgs, meshes: bool, urdf: &str) -> Parameters {
    let options = Options::of::<StatePublisherArgs>();
    Parameters::new([
        Declaration::new(
            "robot_description",
            Value::String(urdf.to_owned()),
            "The arm's URDF, as published on /robot_description.",
        ),
        options.declare("scene", Value::String(args.scene.display().to_string())),
        // What the node draws with, the option's negation resolved against the installed meshes.
        Declaration::new(
            "meshes",
            Value::Bool(meshes),
            "Links drawn with the scene's meshes (not --no-meshes, and the meshes installed).",
        ),
        options.declare("mesh_uri", Value::choice(&args.mesh_uri)),
        options.declare("world_frame", Value::String(args.world_frame.clone())),
        options
            .declare("base_xyz", point(args.base_xyz))
            .effect("Empty: the scene's."),
        options.declare("frame_prefix", Value::String(args.frame_prefix.clone())),
    ])
}

/// The Rerun bridge's parameters (so101_rerun live).
pub fn bridge(live: &LiveArgs, scene: &SceneArgs) -> Parameters {
    let options = Options::of_subcommand::<RerunArgs>("live");
    let sink = match (&live.save, &live.connect) {
        (Some(path), _) => format!("save {}", path.display()),
        (None, Some(url)) => format!("connect {url}"),
        (None, None) => "spawn".to_owned(),
    };
    Parameters::new([
        options.declare("scene", Value::String(scene.scene.display().to_string())),
        options.declare("no_meshes", Value::Bool(scene.no_meshes)),
        options
            .declare("base_xyz", point(scene.base_xyz))
            .effect("Empty: the scene's."),
        options
            .declare("image_rate", Value::Double(scene.image_rate))
            .dynamic()
            .float_range(0.0, MAX_IMAGE_RATE)
            .effect("Takes effect at the next image."),
        options.declare("cameras", Value::StringArray(live.cameras.clone())),
        // One parameter for the three exclusive sink options.
        Declaration::new(
            "sink",
            Value::String(sink),
            "Where the recording goes: save FILE, connect URL or spawn (--save, --connect, --spawn).",
        ),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use so101_core::ros::parameters::documentation::assert_documented;

    #[test]
    fn every_option_of_the_state_publisher_is_a_parameter() {
        let args = StatePublisherArgs::parse_from(["so101_state_publisher"]);
        let parameters = state_publisher(&args, false, "<robot/>");
        // no_meshes is served resolved, as `meshes`; printing the URDF and a run's length are
        // no settings of the node.
        assert_eq!(
            Options::of::<StatePublisherArgs>().undeclared(&parameters),
            ["no_meshes", "print_urdf", "duration"]
        );
        assert_documented("so101_state_publisher", &parameters);
    }

    #[test]
    fn every_option_of_the_bridge_is_a_parameter() {
        let args = RerunArgs::parse_from(["so101_rerun", "live", "--spawn"]);
        let crate::cli::Command::Live(live) = &args.command else {
            panic!("not live");
        };
        let parameters = bridge(live, &args.scene);
        assert_eq!(
            Options::of_subcommand::<RerunArgs>("live").undeclared(&parameters),
            ["save", "connect", "spawn", "duration"]
        );
        assert_documented("so101_rerun_bridge (so101_rerun live)", &parameters);
    }
}
