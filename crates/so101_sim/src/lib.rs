//! The simulated SO-101 and its tasks, without any ROS: MuJoCo (through the raw bindings private
//! to `mujoco`), the scene and its lite variant, the world (joints, cube, task observation),
//! rewards and success, cube placement, the seeded task environment both front doors step, and
//! offscreen camera rendering. so101_sim_node puts it behind the ROS 2 topic contract, the
//! `so101_native` Python extension behind Gymnasium.
//!
//! `unsafe` lives in `mujoco` and `offscreen` only (the workspace denies it elsewhere).

pub mod cameras;
pub mod demo;
pub mod env;
pub mod mujoco;
pub mod offscreen;
pub mod placement;
pub mod provenance;
pub mod randomization;
pub mod scene;
pub mod servos;
pub mod task;
pub mod timing;
pub mod world;
