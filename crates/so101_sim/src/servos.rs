//! The arm's actuators: the scene's gain-80 position servos, or the STS3215 model
//! (so101_core::servo) computing each joint's torque at every physics step.

use so101_core::{
    robot::{JointPositions, JOINT_COUNT},
    servo::{ArmServoParams, ServoModelChoice, ServoState},
};

use crate::mujoco::Simulation;

/// The simulation's servos and their memory.
#[derive(Debug, Clone)]
pub struct ArmServos {
    choice: ServoModelChoice,
    states: Vec<ServoState>,
}

impl ArmServos {
    /// Sets the model's actuators (`actuator`) and joint friction (`dof`) up for `choice`: the
    /// STS3215 model drives torque directly and brings its own gearbox friction and armature.
    pub fn install(
        choice: ServoModelChoice,
        sim: &mut Simulation,
        actuator: &[usize; JOINT_COUNT],
        dof: &[usize; JOINT_COUNT],
    ) -> Self {
        if let ServoModelChoice::Sts3215(params) = &choice {
            for joint in 0..JOINT_COUNT {
                let servo = &params.0[joint];
                sim.set_actuator_direct(actuator[joint]);
                sim.set_actuator_force_limit(actuator[joint], servo.mechanics.stall_torque);
                sim.set_dof_friction(
                    dof[joint],
                    servo.mechanics.damping,
                    servo.mechanics.friction,
                    servo.mechanics.armature,
                );
            }
        }
        Self {
            choice,
            states: vec![ServoState::holding(0.0); JOINT_COUNT],
        }
    }

    pub fn choice(&self) -> &ServoModelChoice {
        &self.choice
    }

    /// The STS3215 parameters in use, if that model drives the arm.
    pub fn params(&self) -> Option<&ArmServoParams> {
        match &self.choice {
            ServoModelChoice::Sts3215(params) => Some(params),
            ServoModelChoice::Gain80 => None,
        }
    }

    /// Every servo holds `positions`, nothing in flight (a reset).
    pub fn hold(&mut self, positions: &JointPositions) {
        for (state, position) in self.states.iter_mut().zip(positions) {
            state.hold(*position);
        }
    }

    /// The targets of a control period sent at episode time `time`.
    pub fn command(&mut self, time: f64, targets: &JointPositions) {
        if let ServoModelChoice::Sts3215(params) = &self.choice {
            for ((state, servo), target) in self.states.iter_mut().zip(&params.0).zip(targets) {
                state.command(servo, time, *target);
            }
        }
    }

    /// The controls of the next physics step at episode time `time`: the targets themselves for
    /// the position servos, the STS3215's torques otherwise.
    pub fn controls(
        &mut self,
        time: f64,
        targets: &JointPositions,
        position: &JointPositions,
        velocity: &JointPositions,
        dt: f64,
    ) -> JointPositions {
        match &self.choice {
            ServoModelChoice::Gain80 => *targets,
            ServoModelChoice::Sts3215(params) => {
                let mut torques = [0.0; JOINT_COUNT];
                for joint in 0..JOINT_COUNT {
                    torques[joint] = self.states[joint]
                        .step(&params.0[joint], time, position[joint], velocity[joint], dt)
                        .torque;
                }
                torques
            }
        }
    }

    /// Whether controls must be recomputed at every physics step.
    pub fn per_step(&self) -> bool {
        matches!(self.choice, ServoModelChoice::Sts3215(_))
    }
}
