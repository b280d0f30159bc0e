//! Simulated cameras: which ones (spec), when (schedule), their pinhole model (intrinsics), where
//! a user's real ones stand (placement), what stands behind the scene (backgrounds), and how
//! frames are rendered off the physics thread (rig).

pub mod backgrounds;
pub mod fuzzing;
pub mod intrinsics;
pub mod placement;
pub mod rig;
pub mod schedule;
pub mod spec;
