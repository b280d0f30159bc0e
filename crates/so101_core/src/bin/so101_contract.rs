//! Prints the topic contract's facts (joint names and limits, topics, services, cameras) for the
//! Python package: `so101_contract --python > python/src/so101/contract.py`.

use clap::Parser;

/// Prints the facts that the Rust nodes and the Python package share, as the Python module
/// so101.contract (the committed python/src/so101/contract.py must equal it; a test checks).
#[derive(Parser)]
#[command(version)]
struct Cli {
    /// Print the Python module.
    #[arg(long)]
    python: bool,
    /// Print the definition of an interface the stack defines (e.g.
    /// control_msgs/action/FollowJointTrajectory, trajectory_msgs/msg/JointTrajectory).
    #[arg(long, value_name = "NAME")]
    interface: Option<String>,
}

fn main() {
    let cli = Cli::parse();
    if cli.python {
        print!("{}", so101_core::contract::python_module());
    } else if let Some(name) = cli.interface {
        match so101_msgs::interface_definition(&name) {
            Some(definition) => print!("{definition}"),
            None => {
                eprintln!("so101_contract: no interface {name:?} defined here");
                std::process::exit(2);
            }
        }
    } else {
        eprintln!("nothing to print: pass --python or --interface NAME (see --help)");
        std::process::exit(2);
    }
}
