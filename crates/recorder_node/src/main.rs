//! recorder_node: records the stack's topics into rosbag2-compatible MCAP bags, episode by episode.

use std::process::ExitCode;

use clap::Parser;
use recorder_node::{cli::Args, node};
use so101_core::ros::logging;

fn main() -> ExitCode {
    logging::init();
    match node::run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            tracing::error!("{error:#}");
            ExitCode::FAILURE
        }
    }
}
