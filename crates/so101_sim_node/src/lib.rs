//! The SO-101 arm and its cube-to-bin scene in MuJoCo, behind the ROS 2 topic contract.
//!
//! Pure logic (task scoring, cube placement, pacing, the demo script, the lite scene transform) is
//! apart from the two I/O sides: MuJoCo (`mujoco`, `world`) and ROS (`ros_io`); `run` joins them.

pub mod cameras;
pub mod cli;
pub mod demo;
pub mod mujoco;
pub mod offscreen;
pub mod pacing;
pub mod placement;
pub mod ros_io;
pub mod run;
pub mod scene;
pub mod task;
pub mod world;
