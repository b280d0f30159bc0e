//! Teleoperation of the SO-101 behind the topic contract: input sources (keyboard, gamepad, leader
//! arm, scripted expert, scripted file) behind one interface, joint and Cartesian jogging on the
//! shared kinematics, episode controls, and the node that publishes /joint_commands.
//!
//! Pure logic (motion, controls, key and pad maps; the expert's planner is so101_core::expert) is
//! apart from I/O (the node, the devices).

pub mod cli;
pub mod controls;
pub mod input;
pub mod lockstep;
pub mod motion;
pub mod node;
pub mod parameters;
