//! What every SO-101 node shares: the robot model, its kinematics and command validation (pure
//! logic), and the ROS 2 plumbing (context from the environment, QoS presets, names under a
//! namespace, sim clock, shutdown, logging mirrored to /rosout).

#[cfg(feature = "bag")]
pub mod bag_read;
pub mod cli_values;
pub mod command;
pub mod contract;
pub mod ee_action;
pub mod episode_bag;
pub mod expert;
pub mod fuzzing;
pub mod kinematics;
pub mod robot;
#[cfg(feature = "ros")]
pub mod ros;
pub mod servo;
pub mod task;
pub mod trajectory;
