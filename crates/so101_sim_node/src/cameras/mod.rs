//! Simulated cameras: which ones (spec), when (schedule), what CameraInfo says (intrinsics), how
//! frames are rendered off the physics thread (rig) and published (publish).

pub mod intrinsics;
pub mod publish;
pub mod rig;
pub mod schedule;
pub mod spec;
