//! The Feetech STS3215 as it moves: one model of its position loop, parameterised by the register
//! values the driver writes and by the mechanics the registers do not tell (docs/sim_to_real.md
//! gives each number's source). The simulation's actuators, the servo-bus emulator and the
//! identification (`so101-sysid`) all use it.

pub mod identify;
pub mod model;
pub mod params;
pub mod plant;

pub use model::{ServoOutput, ServoState};
pub use params::{
    ArmServoParams, ServoMechanics, ServoModelChoice, ServoModelSpec, ServoParams,
    ServoParamsError, ServoRegisters, DEFAULT_SERVO_MODEL, GAIN80, RAD_PER_TICK, SERVO_MODELS,
    STS3215, TICKS_PER_REVOLUTION,
};
pub use plant::{JointLoad, JointPlant, ARM_LOADS};
