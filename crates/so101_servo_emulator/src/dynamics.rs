//! A servo whose shaft moves as the STS3215 model says (so101_core::servo): the position loop of
//! the servo's own registers driving the joint it sits in (the link's inertia and gravity, the
//! gearbox's friction). The alternative to the first-order approach of [`crate::servo`].

use so101_core::servo::{
    JointLoad, JointPlant, ServoMechanics, ServoParams, ServoRegisters, RAD_PER_TICK,
};

/// The shaft of one servo under the model, in the joint's radians around `zero` (ticks).
#[derive(Debug, Clone)]
pub struct ShaftDynamics {
    plant: JointPlant,
    /// Time handed to `advance` not yet simulated (less than one plant step).
    carry: f64,
}

impl ShaftDynamics {
    pub fn new(mechanics: ServoMechanics, load: JointLoad) -> Self {
        let params = ServoParams {
            registers: ServoRegisters::default(),
            mechanics,
        };
        Self {
            plant: JointPlant::at_rest(params, load, 0.0),
            carry: 0.0,
        }
    }

    pub fn mechanics(&self) -> &ServoMechanics {
        &self.plant.params.mechanics
    }

    /// The shaft was put at `actual` ticks from outside (a hand, a restore): at rest there, the
    /// servo holding it.
    pub fn place(&mut self, actual: f64, zero: f64) {
        let position = (actual - zero) * RAD_PER_TICK;
        self.plant.position = position;
        self.plant.velocity = 0.0;
        self.plant.servo.hold(position);
    }

    /// Lets `seconds` pass with the servo's `registers`, its goal at `target` ticks, driven or
    /// not (torque off). Returns where the shaft is, in ticks.
    pub fn advance(
        &mut self,
        registers: ServoRegisters,
        zero: f64,
        target: f64,
        seconds: f64,
        driven: bool,
    ) -> f64 {
        self.plant.params.registers = registers;
        self.plant.command((target - zero) * RAD_PER_TICK);
        self.carry += seconds;
        let steps = (self.carry / so101_core::servo::plant::PLANT_STEP).floor();
        self.carry -= steps * so101_core::servo::plant::PLANT_STEP;
        for _ in 0..steps as u64 {
            self.plant.step(driven);
        }
        zero + self.plant.position / RAD_PER_TICK
    }

    /// Shaft speed, ticks/s.
    pub fn velocity(&self) -> f64 {
        self.plant.velocity / RAD_PER_TICK
    }

    /// The torque the loop asks for, as a fraction of the stall torque (Present_Load's meaning).
    pub fn demand_fraction(&self) -> f64 {
        self.plant.last.demand / self.plant.params.mechanics.stall_torque
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use so101_core::servo::ARM_LOADS;

    #[test]
    fn the_shaft_follows_the_goal_with_the_registers_speed_limit() {
        let mut shaft = ShaftDynamics::new(ServoMechanics::STS3215, ARM_LOADS[0]);
        shaft.place(2048.0, 2048.0);
        let slow = ServoRegisters {
            goal_velocity: 400.0,
            ..ServoRegisters::LEROBOT_ARM
        };
        let mut actual = 2048.0;
        for _ in 0..50 {
            actual = shaft.advance(slow, 2048.0, 3048.0, 0.01, true);
        }
        // 0.5 s at no more than 400 ticks/s.
        assert!(
            actual > 2048.0 + 150.0 && actual <= 2048.0 + 200.0 + 1.0,
            "{actual}"
        );
        for _ in 0..300 {
            actual = shaft.advance(slow, 2048.0, 3048.0, 0.01, true);
        }
        assert!((actual - 3048.0).abs() < 2.0, "{actual}");
    }
}
