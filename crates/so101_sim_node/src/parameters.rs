//! The sim node's ROS parameters: every command-line setting, read-only, and the few that take
//! effect while it runs (dense_reward, camera_rate). Names are the options' names with '_'.

use so101_core::{
    robot::{JointLimit, JOINT_COUNT},
    ros::parameters::{joint_declarations, Declaration, Parameters, Value},
};
use so101_sim::cameras::spec::MAX_RATE;

use crate::{cli::Args, pacing::TimeMode};

/// A change the loop applies.
#[derive(Debug, Clone, PartialEq)]
pub enum Setting {
    DenseReward(bool),
    CameraRate(f64),
}

/// The node's parameters for `args`, the arm's limits as the world enforces them.
pub fn declarations(args: &Args, limits: &[JointLimit; JOINT_COUNT]) -> Parameters {
    let text = |value: &dyn std::fmt::Display| Value::String(value.to_string());
    let speed = match args.speed {
        TimeMode::Scaled { speed } => speed.to_string(),
        TimeMode::Max => "max".to_owned(),
        TimeMode::Lockstep => "lockstep".to_owned(),
    };
    let cameras = args
        .cameras
        .resolve(args.camera_size, args.camera_rate)
        .iter()
        .map(|camera| format!("{}:{}@{}", camera.name, camera.size, camera.rate))
        .collect();
    let mut declarations = vec![
        Declaration::new("scene", text(&args.scene.display()), "MJCF scene loaded."),
        Declaration::new(
            "lite",
            Value::Bool(args.lite),
            "Mesh-free visual variant of the scene.",
        ),
        Declaration::new(
            "task",
            Value::choice(&args.task),
            "Task scored on /task/reward and /task/success.",
        ),
        Declaration::new(
            "dense_reward",
            Value::Bool(args.dense_reward),
            "cube_to_bin: dense shaping (approach, grasp, lift, place) instead of the sparse reward. \
             Takes effect at the next control period.",
        )
        .dynamic(),
        Declaration::new(
            "seed",
            Value::Integer(i64::try_from(args.seed).unwrap_or(i64::MAX)),
            "Seed of the cube placements of /sim/reset.",
        ),
        Declaration::new(
            "rate",
            Value::Double(args.rate),
            "Control rate (Hz): /joint_states, /clock and the task topics per period.",
        ),
        Declaration::new(
            "speed",
            Value::String(speed),
            "Sim time relative to wall time: a factor, \"max\", or \"lockstep\" (--lockstep).",
        ),
        Declaration::new(
            "lockstep",
            Value::Bool(args.lockstep),
            "One control period per /sim/step call.",
        ),
        Declaration::new(
            "step_on_command",
            Value::Bool(args.step_on_command),
            "Lockstep: every valid command also advances one control period.",
        ),
        Declaration::new(
            "demo",
            Value::Bool(args.demo),
            "The built-in demo plays until the first external command.",
        ),
        Declaration::new(
            "cameras",
            Value::StringArray(cameras),
            "Rendered cameras as NAME:WIDTHxHEIGHT@RATE (the rate as started).",
        ),
        Declaration::new(
            "camera_size",
            text(&args.camera_size),
            "Frame size of the cameras that do not name one.",
        ),
        Declaration::new(
            "camera_rate",
            Value::Double(args.camera_rate),
            "Frames per second of sim time of every camera; setting it applies to all cameras \
             from their next frame.",
        )
        .dynamic()
        .float_range(0.1, MAX_RATE),
        Declaration::new(
            "jpeg",
            Value::Bool(args.jpeg),
            "JPEG frames are also published on /camera/NAME/image_raw/compressed.",
        ),
        Declaration::new(
            "jpeg_quality",
            Value::Integer(i64::from(args.jpeg_quality)),
            "JPEG quality, 1-100.",
        ),
        Declaration::new(
            "renderer",
            Value::choice(&args.renderer),
            "Headless OpenGL platform.",
        ),
        Declaration::new(
            "camera_shadows",
            Value::Bool(args.camera_shadows),
            "Shadows are rendered.",
        ),
    ];
    declarations.extend(joint_declarations(limits));
    Parameters::new(declarations)
}

/// The loop's reading of an accepted change (only dynamic parameters are ever accepted).
pub fn setting(name: &str, value: &Value) -> Option<Setting> {
    match name {
        "dense_reward" => value.as_bool().map(Setting::DenseReward),
        "camera_rate" => value.as_f64().map(Setting::CameraRate),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use so101_core::robot::JOINT_LIMITS;

    #[test]
    fn every_dynamic_parameter_has_a_setting_and_the_rest_are_read_only() {
        let args = Args::parse_from(["so101_sim_node", "--speed", "max", "--cameras", "top@15"]);
        let parameters = declarations(&args, &JOINT_LIMITS);
        for declaration in parameters.declarations() {
            let applied = setting(declaration.name(), declaration.value());
            assert_eq!(
                applied.is_some(),
                !declaration.read_only(),
                "{}",
                declaration.name()
            );
        }
        assert_eq!(parameters.get("speed"), Some(&Value::String("max".into())));
        assert_eq!(
            parameters.get("task"),
            Some(&Value::String("cube_to_bin".into()))
        );
        assert_eq!(
            parameters.get("cameras"),
            Some(&Value::StringArray(vec!["top:640x480@15".into()]))
        );
    }
}
