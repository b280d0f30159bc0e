//! One joint of the arm on its own, driven by its servo: what the servo-bus emulator moves and
//! what `so101-sysid fit` replays. The link's inertia and gravity load are taken as fixed per
//! joint (the arm near its home pose, the other joints holding), which is how the identification
//! excites it: one joint at a time.

use super::{
    model::{ServoOutput, ServoState},
    params::ServoParams,
};

/// Step of the plant's integration, s (the simulation's physics step is 2 ms; 1 ms keeps a stiff
/// servo stable with the explicit torque).
pub const PLANT_STEP: f64 = 0.001;

/// The load a joint's servo drives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLoad {
    /// Inertia of the links beyond the joint about its axis, kg m² (the rotor's armature is the
    /// servo's).
    pub inertia: f64,
    /// The torque the servo must give to hold the joint at its zero against gravity, N m (as
    /// MuJoCo's bias force); it falls with cos(q).
    pub gravity_torque: f64,
}

/// The loads of the SO-101's joints at the home pose, in contract order, from the project's MJCF
/// (mass matrix diagonal less the armature, and gravity; so101_sim's tests check them).
pub const ARM_LOADS: [JointLoad; 6] = [
    JointLoad {
        inertia: 0.0153,
        gravity_torque: 0.0,
    },
    JointLoad {
        inertia: 0.0163,
        gravity_torque: -0.539,
    },
    JointLoad {
        inertia: 0.0086,
        gravity_torque: -0.453,
    },
    JointLoad {
        inertia: 0.001,
        gravity_torque: -0.117,
    },
    JointLoad {
        inertia: 4.1e-05,
        gravity_torque: 0.0,
    },
    JointLoad {
        inertia: 1.6e-05,
        gravity_torque: 0.0035,
    },
];

/// A joint and its servo, integrated in [`PLANT_STEP`]s.
#[derive(Debug, Clone, PartialEq)]
pub struct JointPlant {
    pub params: ServoParams,
    pub load: JointLoad,
    pub servo: ServoState,
    /// Joint position (rad) and velocity (rad/s).
    pub position: f64,
    pub velocity: f64,
    /// Sim time of the plant, s.
    pub time: f64,
    pub last: ServoOutput,
}

impl JointPlant {
    /// At rest at `position`, the servo holding it.
    pub fn at_rest(params: ServoParams, load: JointLoad, position: f64) -> Self {
        Self {
            params,
            load,
            servo: ServoState::holding(position),
            position,
            velocity: 0.0,
            time: 0.0,
            last: ServoOutput {
                torque: 0.0,
                demand: 0.0,
                protecting: false,
            },
        }
    }

    /// A goal sent now.
    pub fn command(&mut self, goal: f64) {
        self.servo.command(&self.params, self.time, goal);
    }

    /// Lets `seconds` pass (whole plant steps; a remainder is carried by the caller's clock).
    /// `driven`: torque on; off, the servo exerts nothing and forgets its goals.
    pub fn advance(&mut self, seconds: f64, driven: bool) {
        let steps = (seconds / PLANT_STEP).round() as u64;
        for _ in 0..steps {
            self.step(driven);
        }
    }

    /// One plant step: semi-implicit Euler, dry friction as a stick when the drive cannot break it.
    pub fn step(&mut self, driven: bool) {
        let dt = PLANT_STEP;
        let torque = if driven {
            self.last = self
                .servo
                .step(&self.params, self.time, self.position, self.velocity, dt);
            self.last.torque
        } else {
            self.servo.hold(self.position);
            0.0
        };
        let mechanics = &self.params.mechanics;
        let inertia = self.load.inertia + mechanics.armature;
        let gravity = -self.load.gravity_torque * self.position.cos();
        let applied = torque + gravity;
        let mut velocity =
            (self.velocity * inertia + applied * dt) / (inertia + mechanics.damping * dt);
        // Dry friction: it removes up to friction x dt of momentum, never reverses the motion.
        let friction_impulse = mechanics.friction * dt / inertia;
        if velocity.abs() <= friction_impulse {
            velocity = 0.0;
        } else {
            velocity -= velocity.signum() * friction_impulse;
        }
        self.velocity = velocity;
        self.position += velocity * dt;
        self.time += dt;
    }
}

/// Replays `commands` (time, goal; time-ordered) on a plant starting at rest at `start`, and gives
/// the position at each of `samples` (time-ordered, s).
pub fn replay(
    params: ServoParams,
    load: JointLoad,
    start: f64,
    commands: &[(f64, f64)],
    samples: &[f64],
) -> Vec<f64> {
    let mut plant = JointPlant::at_rest(params, load, start);
    let mut next_command = 0;
    let mut positions = Vec::with_capacity(samples.len());
    for &sample in samples {
        while plant.time + 0.5 * PLANT_STEP <= sample {
            while next_command < commands.len() && commands[next_command].0 <= plant.time + 1e-9 {
                plant.command(commands[next_command].1);
                next_command += 1;
            }
            plant.step(true);
        }
        positions.push(plant.position);
    }
    positions
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_is_reached_and_held_within_the_dead_zone() {
        let params = ServoParams::default();
        let load = ARM_LOADS[2];
        let mut plant = JointPlant::at_rest(params, load, 0.0);
        plant.command(0.3);
        plant.advance(1.0, true);
        let (below, above) = params.dead_zone();
        assert!(
            (plant.position - 0.3).abs() <= below.max(above) + 1e-3,
            "{}",
            plant.position
        );
        assert!(plant.velocity.abs() < 1e-3);
    }

    #[test]
    fn a_softer_gain_sags_further_under_gravity() {
        let load = JointLoad {
            inertia: 0.005,
            gravity_torque: 0.5,
        };
        let sag = |gain_per_p: f64| {
            let mut params = ServoParams::default();
            params.mechanics.gain_per_p = gain_per_p;
            params.mechanics.friction = 0.0;
            let mut plant = JointPlant::at_rest(params, load, 0.0);
            plant.advance(2.0, true);
            -plant.position
        };
        let stiff = sag(60.0);
        let soft = sag(6.0);
        // Steady state: the dead zone (1 tick) plus Kp e = gravity: 0.5 / (6 x 16) = 5.2 mrad
        // for the soft one, 0.5 mrad for the stiff one.
        let (_, dead_zone) = ServoParams::default().dead_zone();
        assert!((soft - dead_zone - 0.5 / 96.0).abs() < 0.3e-3, "{soft}");
        assert!((stiff - dead_zone - 0.5 / 960.0).abs() < 0.1e-3, "{stiff}");
    }

    #[test]
    fn replay_samples_the_motion_at_the_given_times() {
        let params = ServoParams::default();
        let positions = replay(
            params,
            ARM_LOADS[0],
            0.0,
            &[(0.1, 0.5)],
            &[0.05, 0.1, 0.5, 1.0],
        );
        assert_eq!(positions[0], 0.0);
        assert!(positions[2] > 0.3);
        assert!((positions[3] - 0.5).abs() < 3e-3);
    }
}
