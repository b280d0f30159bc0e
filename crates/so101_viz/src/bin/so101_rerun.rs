//! so101_rerun: the SO-101 stack in the Rerun viewer, live or from episode bags.

use std::process::ExitCode;

use clap::Parser;
use so101_core::ros::logging;
use so101_viz::{app::run, cli::RerunArgs as Args};

fn main() -> ExitCode {
    logging::init();
    logging::exit_code(run(Args::parse()))
}
