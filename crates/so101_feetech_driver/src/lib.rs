//! The physical SO-101 over the Feetech STS3215 servo bus.
//!
//! Pure logic, tested without a bus: `protocol` (packets, control table, timing), `calibration`
//! (LeRobot files, ticks <-> rad), `safety` (goal clamping, step limit, watchdog), `fuzzing` (the
//! fuzz targets' bodies over status packets and calibration files). I/O: `bus`
//! (transactions over a serial port), `arm` (the six servos), `node` (the ROS 2 driver), `tools`
//! (calibrate, setup-motors, scan). The servo-bus emulator, for work without an arm, is its own
//! crate, `so101_servo_emulator`, built on this one; the integration tests under tests/ use it.

pub mod args;
pub mod arm;
pub mod bus;
pub mod calibration;
pub mod cli;
pub mod fuzzing;
pub mod node;
pub mod protocol;
pub mod safety;
pub mod tools;
