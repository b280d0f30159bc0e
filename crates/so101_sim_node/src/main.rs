//! so101_sim_node: the SO-101 arm and its cube-to-bin scene in MuJoCo, behind the same ROS 2 topic
//! contract as the physical arm (see docs/sim_node_interface.md).

use std::process::ExitCode;

use clap::Parser;
use so101_core::ros::logging;
use so101_sim_node::{cli::Args, run};

fn main() -> ExitCode {
    logging::init();
    let args = Args::parse();
    match run::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            tracing::error!("{error:#}");
            ExitCode::FAILURE
        }
    }
}
