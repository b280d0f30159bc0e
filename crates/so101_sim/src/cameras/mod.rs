//! Simulated cameras: which ones (spec), when (schedule), their pinhole model (intrinsics), and how
//! frames are rendered off the physics thread (rig).

pub mod intrinsics;
pub mod rig;
pub mod schedule;
pub mod spec;
