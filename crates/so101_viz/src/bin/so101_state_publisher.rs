//! so101_state_publisher: the SO-101's /robot_description and /tf for RViz and other ROS tools.

use std::process::ExitCode;

use clap::Parser;
use so101_core::ros::logging;
use so101_viz::{cli::StatePublisherArgs as Args, state_publisher::run};

fn main() -> ExitCode {
    logging::init();
    logging::exit_code(run(Args::parse()))
}
