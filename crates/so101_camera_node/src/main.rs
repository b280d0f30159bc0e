//! so101_camera_node: real cameras as ROS image topics (docs/real_arm.md).

use std::process::ExitCode;

use clap::Parser;
use so101_camera_node::{cli::Args, node};
use so101_core::ros::logging;

fn main() -> ExitCode {
    logging::init();
    logging::exit_code(node::run(Args::parse()))
}
