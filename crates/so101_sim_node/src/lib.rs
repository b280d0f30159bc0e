//! The ROS 2 front door of the simulated SO-101 (so101_sim): the topic contract, services,
//! camera topics and wall-clock pacing around the simulation core.
//!
//! Pure logic (pacing, the CLI's parsing) is apart from the I/O side (`ros_io`, `cameras`); `run`
//! joins them with so101_sim's task environment.

pub mod cameras;
pub mod cli;
pub mod pacing;
pub mod parameters;
pub mod ros_io;
pub mod run;
