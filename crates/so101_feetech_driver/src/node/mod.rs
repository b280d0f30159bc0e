//! The driver node: the control loop over the bus, its ROS side, its diagnostics.

mod control_loop;
pub mod controller;
pub mod cycle_stats;
pub mod diagnostics;
pub mod emergency;
pub mod parameters;
mod ros_io;

pub use control_loop::run;
