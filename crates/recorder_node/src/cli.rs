//! Command-line options of recorder_node.

use std::{path::PathBuf, time::Duration};

use so101_core::ros::NodeArgs;

/// Records the stack's topics into rosbag2-compatible MCAP bags, one bag directory per episode
/// (`<output>/episode_NNNNNN/` with .mcap file(s) and metadata.yaml). Episodes are started and
/// stopped by /episode/events (std_msgs/String: start, stop, success, failure, discard, rerecord,
/// discard_last) and by the services /recorder/start, /recorder/stop, /recorder/discard
/// (std_srvs/Trigger) and /recorder/mark_success (std_srvs/SetBool), or by --start.
#[derive(Debug, clap::Parser)]
#[command(version)]
pub struct Args {
    /// Directory that receives one bag directory per episode.
    #[arg(long, default_value = "bags")]
    pub output: PathBuf,
    /// Topics to record instead of the default set (comma-separated; relative names are in the
    /// namespace).
    #[arg(long, value_delimiter = ',')]
    pub topics: Vec<String>,
    /// Record every topic whose type the recorder knows.
    #[arg(long)]
    pub all: bool,
    /// Record topics whose whole name matches this regular expression (repeatable).
    #[arg(long = "regex")]
    pub patterns: Vec<String>,
    /// Leave out topics whose whole name matches this regular expression.
    #[arg(long)]
    pub exclude: Option<String>,
    /// MCAP chunk compression.
    #[arg(long, value_enum, default_value = "none")]
    pub compression: CompressionArg,
    /// MCAP chunk size in bytes: smaller chunks lose less in a crash, bigger ones compress better.
    #[arg(long, default_value_t = 1 << 20, value_parser = clap::value_parser!(u64).range(1024..=1 << 30))]
    pub chunk_size: u64,
    /// Seconds after which an open chunk is written out even when not full (the most a kill -9
    /// can lose).
    #[arg(long, default_value_t = 1.0, value_parser = parse_seconds)]
    pub max_chunk_age: f64,
    /// Start a new .mcap file in the episode once the current one reaches this many MB.
    #[arg(long, value_parser = parse_positive)]
    pub split_size_mb: Option<f64>,
    /// Start a new .mcap file in the episode after this many seconds.
    #[arg(long, value_parser = parse_seconds)]
    pub split_duration: Option<f64>,
    /// Task text of episodes whose start event does not give one (LeRobot's task description).
    #[arg(long, default_value = "")]
    pub task: String,
    /// Name of episode directories before their number.
    #[arg(long, default_value = so101_core::episode_bag::DEFAULT_PREFIX)]
    pub prefix: String,
    /// Start recording an episode at once (stopped by SIGINT, /recorder/stop or a stop event).
    #[arg(long)]
    pub start: bool,
    /// Most MB of messages waiting for the writer; beyond, messages are dropped and counted.
    #[arg(long, default_value_t = 512.0, value_parser = parse_positive)]
    pub queue_mb: f64,
    /// Exit cleanly after this many seconds.
    #[arg(long, value_parser = parse_seconds)]
    pub duration: Option<f64>,
    #[command(flatten)]
    pub node: NodeArgs,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CompressionArg {
    None,
    Zstd,
    Lz4,
}

impl CompressionArg {
    pub fn to_mcap(self) -> Option<mcap::Compression> {
        match self {
            Self::None => None,
            Self::Zstd => Some(mcap::Compression::Zstd),
            Self::Lz4 => Some(mcap::Compression::Lz4),
        }
    }
}

pub fn seconds(value: f64) -> Duration {
    Duration::from_secs_f64(value)
}

fn parse_seconds(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(value) if value.is_finite() && value > 0.0 && value <= 1e7 => Ok(value),
        _ => Err(format!("{text:?} is not a number of seconds above 0")),
    }
}

fn parse_positive(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(value) if value.is_finite() && value > 0.0 && value <= 1e9 => Ok(value),
        _ => Err(format!("{text:?} is not a number above 0")),
    }
}
