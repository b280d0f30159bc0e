//! A faithful STS3215 servo-bus emulator on a pseudo-terminal: it stands in for the USB-serial
//! adapter and the daisy-chained servos, so the driver is tested and benchmarked without hardware.
//! The wire protocol, the control table and LeRobot calibration are so101_feetech_driver's; the
//! binary `so101_servo_emulator` serves the bus on a pty, and the driver's integration tests use
//! this library (a dev-dependency: the driver itself depends on nothing here).
//!
//! - `servo`: one servo's control table and shaft physics (pure).
//! - `dynamics`: the shaft moved by the STS3215 model of so101_core::servo (pure).
//! - `bus`: the servos on one bus, instruction semantics, faults and wire timing (pure).
//! - `fuzzing`: the fuzz target's body over instruction packets (pure).
//! - `control`: the runtime control commands (`move 1 2048`, `drop 0.1`, `dump`, ...) (pure).
//! - `in_process`: the bus as an in-process transport (the driver's `Connector`), for the driver's
//!   tests (I/O-free).
//! - `pty`: serving the bus on a pty, with hangups and a symlink that survives them (I/O).
//! - `error`: what starting the emulator or persisting its state can fail with.

pub mod bus;
pub mod control;
pub mod dynamics;
pub mod error;
pub mod fuzzing;
pub mod in_process;
pub mod pty;
pub mod servo;

pub use bus::{BusEmulator, Faults, Response, SlotSnapshot, SlotState, Timing};
pub use control::{ControlCommand, ControlError};
pub use error::EmulatorError;
pub use in_process::{GoalAudit, InProcessBus, InProcessTransport};
pub use pty::{Emulator, EmulatorConfig};
pub use servo::ServoModel;
