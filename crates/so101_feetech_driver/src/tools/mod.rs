//! Set-up tools of the binary: calibration, motor ids and baud, bus scan, finding the adapter's
//! port, the udev rule. Each tool's command-line options (`*Args`) live with it, the ones it shares
//! with the node in `args`; `cli` composes them. Each keeps its procedure (talking to the bus)
//! apart from the terminal prompts, so tests drive the procedure against the emulator
//! (so101_servo_emulator, in tests/).

pub mod calibrate;
pub mod find_port;
pub mod scan;
pub mod setup_motors;
pub mod udev;

use std::io::{BufRead, Write};

/// Prints `prompt` and waits for Enter; an error when stdin is closed (no user to answer).
pub fn wait_for_enter(prompt: &str) -> anyhow::Result<()> {
    print!("{prompt} [Enter] ");
    std::io::stdout().flush()?;
    let mut line = String::new();
    if std::io::stdin().lock().read_line(&mut line)? == 0 {
        anyhow::bail!("standard input closed while waiting for Enter: run this in a terminal");
    }
    Ok(())
}
