//! teleop_node: drive the SO-101 (sim or real) from a gamepad, the keyboard, a leader arm or the
//! scripted expert, in joint or Cartesian space (see docs/teleop_interface.md).

use std::process::ExitCode;

use clap::Parser;
use so101_core::ros::logging;
use teleop_node::{cli::Args, node};

fn main() -> ExitCode {
    logging::init();
    logging::exit_code(node::run(Args::parse()))
}
