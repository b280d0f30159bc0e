//! so101_feetech_driver: the physical SO-101 behind the stack's ROS 2 topics, and its set-up tools.

use std::process::ExitCode;

use clap::Parser;
use so101_core::ros::logging;
use so101_feetech_driver::{
    cli::{Cli, Command},
    node, tools,
};

fn main() -> ExitCode {
    logging::init();
    let cli = Cli::parse();
    let result = match &cli.command {
        None => node::run(cli.run),
        Some(Command::Calibrate(args)) => tools::calibrate::run(args),
        Some(Command::SetupMotors(args)) => tools::setup_motors::run(args),
        Some(Command::Scan(args)) => tools::scan::run(args),
        Some(Command::FindPort(args)) => tools::find_port::run(args),
        Some(Command::InstallUdev(args)) => tools::udev::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            tracing::error!("{error:#}");
            ExitCode::FAILURE
        }
    }
}
