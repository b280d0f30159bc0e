//! The driver node: the control loop over the bus, its ROS side, its diagnostics.

mod control_loop;
pub mod cycle_stats;
pub mod diagnostics;
mod ros_io;

pub use control_loop::run;
