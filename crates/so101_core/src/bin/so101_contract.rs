//! Prints the topic contract's facts (joint names and limits, topics, services, cameras) for the
//! Python package: `so101_contract --python > python/src/so101/contract.py`.

use clap::Parser;

/// Prints the facts that the Rust nodes and the Python package share, as the Python module
/// so101.contract (the committed python/src/so101/contract.py must equal it; a test checks).
#[derive(Parser)]
#[command(version)]
struct Cli {
    /// Print the Python module (the only format so far).
    #[arg(long)]
    python: bool,
}

fn main() {
    let cli = Cli::parse();
    if cli.python {
        print!("{}", so101_core::contract::python_module());
    } else {
        eprintln!("nothing to print: pass --python (see --help)");
        std::process::exit(2);
    }
}
