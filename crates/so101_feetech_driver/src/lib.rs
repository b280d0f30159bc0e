//! The physical SO-101 over the Feetech STS3215 servo bus.
//!
//! `protocol` is the pure wire protocol (packets, checksums, the control table, timing); it does
//! no I/O, so it is tested without a bus.

pub mod protocol;
