//! Visualization of the SO-101 stack, in one place so the other nodes stay light:
//! - `so101_rerun`: the stack's topics (live) or episode bags (offline) in Rerun;
//! - `so101_state_publisher`: /robot_description (URDF) and /tf from joint states for RViz and
//!   other ROS tools.
//!
//! Both draw the arm from the shared kinematic model (`so101_core::kinematics`) and the shapes of
//! the project's MJCF scene.

pub mod app;
pub mod bag;
pub mod bridge;
pub mod cli;
pub mod live;
pub mod parameters;
pub mod rerun_log;
pub mod scene_geometry;
pub mod state_publisher;
pub mod tf;
pub mod urdf;
