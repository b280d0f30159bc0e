//! Options the driver node and the set-up tools share: where the bus is (`PortArgs`) and which
//! calibration file (`CalibrationArgs`), with their value parsers. `cli` flattens them into the
//! node's options; each tool flattens them into its own (`tools::*::*Args`).

use std::{
    path::{Path, PathBuf},
    time::Duration,
};

use crate::{
    bus::BusConfig,
    calibration::{lerobot_calibration_dir, lerobot_calibration_path, ArmRole},
    protocol::registers::BAUD_RATES,
};

/// Where the bus is.
#[derive(Debug, Clone, clap::Args)]
pub struct PortArgs {
    /// Serial port of the servo bus adapter (or the emulator's pty / symlink).
    #[arg(long, default_value = "/dev/ttyACM0")]
    pub port: PathBuf,
    /// Baud rate of the bus (one the STS3215 supports).
    #[arg(long, default_value_t = 1_000_000, value_parser = parse_baud)]
    pub baud: u32,
    /// Extra attempts after a transaction got no valid answer (0 to 10).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(0..=10))]
    pub retries: u32,
    /// Milliseconds allowed for the adapter and the OS on top of the wire time of a transaction
    /// (default 10 on a serial adapter, 100 on a pseudo-terminal such as the emulator's, whose
    /// answers wait for the OS to run a process: tens of ms on a busy machine).
    #[arg(long, value_parser = parse_positive_ms)]
    pub bus_slack_ms: Option<f64>,
}

/// The slack for a USB serial adapter: its latency timer and the OS.
pub const ADAPTER_SLACK_MS: f64 = 10.0;
/// The slack for a pseudo-terminal: the peer is a process, and a loaded machine leaves it waiting
/// for a core for tens of ms (the emulator missed 3 x 10.6 ms beside a training run).
pub const PSEUDO_TERMINAL_SLACK_MS: f64 = 100.0;

impl PortArgs {
    pub fn bus_config(&self) -> BusConfig {
        BusConfig {
            baud: self.baud,
            retries: self.retries,
            slack: Duration::from_secs_f64(self.bus_slack_ms() / 1000.0),
            ..BusConfig::default()
        }
    }

    /// The slack in ms: the one given, else the default for what the port is.
    pub fn bus_slack_ms(&self) -> f64 {
        self.bus_slack_ms
            .unwrap_or_else(|| default_slack_ms(is_pseudo_terminal(&self.port)))
    }
}

pub fn default_slack_ms(pseudo_terminal: bool) -> f64 {
    if pseudo_terminal {
        PSEUDO_TERMINAL_SLACK_MS
    } else {
        ADAPTER_SLACK_MS
    }
}

/// Whether `port` is (a link to) the follower side of a pseudo-terminal, /dev/pts/N.
pub fn is_pseudo_terminal(port: &Path) -> bool {
    std::fs::canonicalize(port).is_ok_and(|path| path.starts_with("/dev/pts"))
}

/// Which calibration file.
#[derive(Debug, Clone, clap::Args)]
pub struct CalibrationArgs {
    /// Robot id as in LeRobot's --robot.id: names the calibration file in LeRobot's calibration
    /// directory ($HF_LEROBOT_CALIBRATION or ~/.cache/huggingface/lerobot/calibration).
    #[arg(long, default_value = "so101")]
    pub robot_id: String,
    /// Calibration file to use instead of LeRobot's location.
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// A leader arm (teleoperators/so_leader/ in LeRobot's layout; torque stays off).
    #[arg(long)]
    pub leader: bool,
}

impl CalibrationArgs {
    pub fn role(&self) -> ArmRole {
        if self.leader {
            ArmRole::Leader
        } else {
            ArmRole::Follower
        }
    }

    pub fn path(&self) -> PathBuf {
        self.calibration.clone().unwrap_or_else(|| {
            let base = lerobot_calibration_dir(|name| std::env::var(name).ok());
            lerobot_calibration_path(&base, self.role(), &self.robot_id)
        })
    }
}

fn parse_baud(text: &str) -> Result<u32, String> {
    let rates = BAUD_RATES.map(|(_, baud)| baud);
    match text.parse::<u32>() {
        Ok(baud) if rates.contains(&baud) => Ok(baud),
        _ => Err(format!(
            "{text:?} is not a baud rate both LeRobot and Feetech give the STS3215 ({rates:?})"
        )),
    }
}

/// A number above 0 (also the node's --max-step).
pub(crate) fn parse_positive(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(value) if value.is_finite() && value > 0.0 => Ok(value),
        _ => Err(format!("{text:?} is not a number above 0")),
    }
}

fn parse_positive_ms(text: &str) -> Result<f64, String> {
    parse_positive(text).and_then(|ms| {
        if ms <= 10_000.0 {
            Ok(ms)
        } else {
            Err(format!("{text:?} ms is more than 10 s"))
        }
    })
}
