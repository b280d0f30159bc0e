//! The sim node's ROS parameters: every command-line setting, read-only, and the few that take
//! effect while it runs (dense_reward, camera_rate). Names are the options' names with '_'.

use so101_core::{
    robot::{JointLimit, JOINT_COUNT},
    ros::parameters::{joint_declarations, Options, Parameters, Value},
    servo::{GAIN80, STS3215},
};
use so101_sim::{
    cameras::spec::{MAX_RATE, MIN_RATE},
    randomization::spec::{DEFAULT, HELDOUT, OFF},
};

use crate::{cli::Args, pacing::TimeMode};

/// A change the loop applies.
#[derive(Debug, Clone, PartialEq)]
pub enum Setting {
    DenseReward(bool),
    CameraRate(f64),
}

/// The node's parameters for `args`, the arm's limits as the world enforces them.
pub fn declarations(args: &Args, limits: &[JointLimit; JOINT_COUNT]) -> Parameters {
    let options = Options::of::<Args>();
    let text = |value: &dyn std::fmt::Display| Value::String(value.to_string());
    let speed = match args.speed {
        TimeMode::Scaled { speed } => speed.to_string(),
        TimeMode::Max => "max".to_owned(),
        TimeMode::Lockstep => "lockstep".to_owned(),
    };
    let cameras = args
        .camera_specs()
        .iter()
        .map(|camera| format!("{}:{}@{}", camera.name, camera.size, camera.rate))
        .collect();
    let mut declarations = vec![
        options.declare("scene", text(&args.scene.display())),
        options.declare("lite", Value::Bool(args.lite)),
        options.declare("task", Value::choice(&args.task)),
        options
            .declare("dense_reward", Value::Bool(args.dense_reward))
            .dynamic()
            .effect("Takes effect at the next control period."),
        options.declare(
            "seed",
            Value::Integer(i64::try_from(args.seed).unwrap_or(i64::MAX)),
        ),
        options.declare("rate", Value::Double(args.rate)),
        options
            .declare("servo_params", text(&args.servo_params))
            .effect(&format!(
                "\"{STS3215}\", \"{GAIN80}\" or the parameter file's path."
            )),
        options
            .declare("randomize", text(&args.randomize))
            .effect(&format!(
                "Served as \"{OFF}\", \"{DEFAULT}\", \"{HELDOUT}\" or the file's path."
            )),
        options
            .declare(
                "camera_poses",
                text(
                    &args
                        .camera_poses
                        .as_ref()
                        .map_or("", |placements| &placements.source),
                ),
            )
            .effect("Served as the file's path, empty without one."),
        options
            .declare("speed", Value::String(speed))
            .effect("\"lockstep\" under --lockstep."),
        options.declare("lockstep", Value::Bool(args.lockstep)),
        options.declare("step_on_command", Value::Bool(args.step_on_command)),
        options.declare("demo", Value::Bool(args.demo)),
        options
            .declare("cameras", Value::StringArray(cameras))
            .effect("Served as NAME:WIDTHxHEIGHT@RATE, the rate as started."),
        options.declare("camera_size", text(&args.camera_size)),
        options
            .declare("camera_rate", Value::Double(args.camera_rate))
            .dynamic()
            .float_range(MIN_RATE, MAX_RATE)
            .effect("Setting it applies to every camera from its next frame."),
        options.declare("jpeg", Value::Bool(args.jpeg)),
        options.declare("jpeg_quality", Value::Integer(i64::from(args.jpeg_quality))),
        options.declare("renderer", Value::choice(&args.renderer)),
        options.declare("camera_shadows", Value::Bool(args.camera_shadows)),
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
    use so101_core::{robot::JOINT_LIMITS, ros::parameters::documentation::assert_documented};

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

    #[test]
    fn the_servo_model_and_the_randomization_are_served_by_name() {
        let args = Args::parse_from(["so101_sim_node", "--randomize", "True"]);
        let parameters = declarations(&args, &JOINT_LIMITS);
        assert_eq!(
            parameters.get("servo_params"),
            Some(&Value::String("sts3215".into()))
        );
        assert_eq!(
            parameters.get("randomize"),
            Some(&Value::String("default".into()))
        );
    }

    #[test]
    fn every_option_is_a_parameter() {
        let parameters = declarations(&Args::parse_from(["so101_sim_node"]), &JOINT_LIMITS);
        // How long this run lasts is no setting of the simulation.
        assert_eq!(Options::of::<Args>().undeclared(&parameters), ["duration"]);
        assert_documented("so101_sim_node", &parameters);
    }
}
