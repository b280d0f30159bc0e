//! The STS3215's position loop, one physics step at a time: the torque it puts on its joint.
//!
//! What the firmware does, as modelled (units of the joint: rad, rad/s, N m):
//! 1. A goal takes effect `latency` after it was sent.
//! 2. A reference walks to the goal no faster than the speed limit (Goal_Velocity, else the
//!    no-load speed) and, with Acceleration > 0, ramps its speed up and down (trapezoid).
//! 3. Inside the CW/CCW dead zone around the reference the motor is not driven: the H-bridge
//!    brakes it (windings shorted), which resists motion by the motor's own back-EMF damping,
//!    stall torque / no-load speed.
//! 4. Outside it, torque = Kp e - Kd qdot + Ki ∫e (P/D/I_Coefficient times the mechanics' gains),
//!    e measured from the dead zone's edge.
//! 5. The torque is limited by Torque_Limit of the stall torque and by the motor's speed-torque
//!    line (no torque in the direction of motion at the no-load speed).
//! 6. A demand above Overload_Torque for Protection_Time limits the output to Protective_Torque
//!    until the demand falls back below Overload_Torque.
//! 7. Backlash: when the torque changes direction the motor first crosses the gear's lost motion
//!    (at its no-load speed) and the joint feels nothing meanwhile.
//!
//! The joint's own inertia, friction and gravity belong to whoever integrates the motion (MuJoCo
//! in the simulation, [`super::plant`] in the emulator).

use std::collections::VecDeque;

use super::params::ServoParams;

/// The servo's memory between steps.
#[derive(Debug, Clone, PartialEq)]
pub struct ServoState {
    /// Goals sent and not yet acted on: (time it takes effect, goal).
    pending: VecDeque<(f64, f64)>,
    goal: f64,
    reference: f64,
    reference_velocity: f64,
    integral: f64,
    /// Where the motor side sits inside the backlash gap: -half..=half.
    slack: f64,
    overloaded_for: f64,
    protecting: bool,
}

/// What one step gives: the torque on the joint and what the servo's registers report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoOutput {
    /// Torque on the joint, N m.
    pub torque: f64,
    /// The torque the loop asked for before the limits, N m (what the overload watch sees).
    pub demand: f64,
    /// Whether the overload protection limits the output now.
    pub protecting: bool,
}

impl ServoState {
    /// A servo holding `position` with no motion under way.
    pub fn holding(position: f64) -> Self {
        Self {
            pending: VecDeque::new(),
            goal: position,
            reference: position,
            reference_velocity: 0.0,
            integral: 0.0,
            slack: 0.0,
            overloaded_for: 0.0,
            protecting: false,
        }
    }

    /// The goal acted on now (the latest one whose latency has passed).
    pub fn goal(&self) -> f64 {
        self.goal
    }

    pub fn reference(&self) -> f64 {
        self.reference
    }

    /// A goal sent at `time` (s, the same clock as [`ServoState::step`]'s). Goals must be sent in
    /// time order. A goal equal to the last one sent is not queued again.
    pub fn command(&mut self, params: &ServoParams, time: f64, goal: f64) {
        let last = self.pending.back().map_or(self.goal, |(_, goal)| *goal);
        if goal == last {
            return;
        }
        let due = time + params.mechanics.latency;
        self.pending.push_back((due, goal));
    }

    /// Holds `position` from now on, dropping goals in flight (torque switched on where the
    /// shaft is, or a reset).
    pub fn hold(&mut self, position: f64) {
        *self = Self::holding(position);
    }

    /// The torque over the next `dt` seconds at sim time `time`, with the joint at `position`
    /// moving at `velocity`.
    pub fn step(
        &mut self,
        params: &ServoParams,
        time: f64,
        position: f64,
        velocity: f64,
        dt: f64,
    ) -> ServoOutput {
        while let Some(&(due, goal)) = self.pending.front() {
            if due > time + 1e-12 {
                break;
            }
            self.goal = goal;
            self.pending.pop_front();
        }
        self.advance_reference(params, dt);
        let error = dead_zoned(self.reference - position, params.dead_zone());
        let demand = if error != 0.0 {
            self.integral += error * dt;
            params.kp() * error - params.kd() * velocity + params.ki() * self.integral
        } else {
            // No drive inside the dead zone, only the shorted windings' braking; the integral
            // keeps its value.
            -params.mechanics.stall_torque / params.mechanics.no_load_speed * velocity
        };
        let protecting = self.watch_overload(params, demand, dt);
        let mut ceiling = params.torque_ceiling();
        if protecting {
            ceiling = ceiling
                .min(params.mechanics.stall_torque * params.registers.protective_torque / 100.0);
        }
        let torque = demand.clamp(-ceiling, ceiling);
        let torque = limit_by_speed(torque, velocity, params.mechanics.no_load_speed);
        let torque = self.through_backlash(params, torque, dt);
        ServoOutput {
            torque,
            demand,
            protecting,
        }
    }

    fn advance_reference(&mut self, params: &ServoParams, dt: f64) {
        let speed = params.speed_limit();
        let acceleration = params.acceleration_limit();
        let remaining = self.goal - self.reference;
        if remaining == 0.0 && self.reference_velocity == 0.0 {
            return;
        }
        // The fastest speed from which the ramp still stops at the goal.
        let braking = (2.0 * acceleration * remaining.abs()).sqrt();
        let wanted = remaining.signum() * speed.min(braking).min(remaining.abs() / dt);
        let change = acceleration * dt;
        self.reference_velocity += (wanted - self.reference_velocity).clamp(-change, change);
        let next = self.reference + self.reference_velocity * dt;
        if (self.goal - next) * remaining <= 0.0 {
            // Reached (or would pass) the goal: stop on it.
            self.reference = self.goal;
            self.reference_velocity = 0.0;
        } else {
            self.reference = next;
        }
    }

    /// Whether the overload protection limits the output, after `dt` with this demand.
    fn watch_overload(&mut self, params: &ServoParams, demand: f64, dt: f64) -> bool {
        let threshold = params.mechanics.stall_torque * params.registers.overload_torque / 100.0;
        if demand.abs() > threshold {
            self.overloaded_for += dt;
            if self.overloaded_for >= params.registers.protection_time * 0.010 {
                self.protecting = true;
            }
        } else {
            self.overloaded_for = 0.0;
            self.protecting = false;
        }
        self.protecting
    }

    fn through_backlash(&mut self, params: &ServoParams, torque: f64, dt: f64) -> f64 {
        let half = params.mechanics.backlash / 2.0;
        if half <= 0.0 || torque == 0.0 {
            return torque;
        }
        let side = torque.signum() * half;
        if self.slack == side {
            return torque;
        }
        // The motor crosses the gap unloaded; the joint feels nothing until it is closed.
        let travel = params.mechanics.no_load_speed * dt;
        self.slack = if torque > 0.0 {
            (self.slack + travel).min(half)
        } else {
            (self.slack - travel).max(-half)
        };
        0.0
    }
}

/// The error the loop acts on: zero inside the dead zone, measured from its edge outside, so the
/// drive grows from zero as the error leaves it (no kick at the edge).
fn dead_zoned(error: f64, (below, above): (f64, f64)) -> f64 {
    if error > above {
        error - above
    } else if error < -below {
        error + below
    } else {
        0.0
    }
}

/// The motor's speed-torque line: driving along the motion, the torque falls to zero at the
/// no-load speed; braking against it is not limited.
fn limit_by_speed(torque: f64, velocity: f64, no_load_speed: f64) -> f64 {
    if torque * velocity <= 0.0 {
        return torque;
    }
    let left = (1.0 - velocity.abs() / no_load_speed).max(0.0);
    torque * left
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::servo::params::{ServoMechanics, ServoRegisters, RAD_PER_TICK};

    fn params() -> ServoParams {
        ServoParams::default()
    }

    #[test]
    fn the_reference_ramps_at_the_acceleration_and_stops_on_the_goal() {
        let params = params();
        let mut state = ServoState::holding(0.0);
        state.command(&params, 0.0, 1.0);
        let dt = 0.001;
        let mut peak: f64 = 0.0;
        let mut time = 0.0;
        while time < 2.0 {
            let before = state.reference_velocity;
            state.step(&params, time, state.reference, 0.0, dt);
            let rate = (state.reference_velocity - before).abs() / dt;
            assert!(rate <= params.acceleration_limit() * 1.000001 || state.reference == 1.0);
            peak = peak.max(state.reference_velocity.abs());
            time += dt;
        }
        assert_eq!(state.reference, 1.0);
        assert!(peak <= params.speed_limit() + 1e-9);
        // 254 x 100 ticks/s² = 39 rad/s²: a 1 rad move peaks at sqrt(39) = 6.2 rad/s.
        assert!(
            (peak - (params.acceleration_limit() * 1.0).sqrt()).abs() < 0.1,
            "{peak}"
        );
    }

    #[test]
    fn a_goal_takes_effect_after_the_latency() {
        let mut params = params();
        params.mechanics.latency = 0.02;
        let mut state = ServoState::holding(0.0);
        state.command(&params, 0.1, 0.5);
        state.step(&params, 0.119, 0.0, 0.0, 0.001);
        assert_eq!(state.goal(), 0.0);
        state.step(&params, 0.120, 0.0, 0.0, 0.001);
        assert_eq!(state.goal(), 0.5);
    }

    #[test]
    fn no_drive_inside_the_dead_zone_and_proportional_outside() {
        let params = ServoParams {
            registers: ServoRegisters {
                cw_dead_zone: 3.0,
                ccw_dead_zone: 3.0,
                d_coefficient: 0.0,
                // Soft enough that 3.5 ticks stay below the stall torque.
                p_coefficient: 1.0,
                ..ServoRegisters::LEROBOT_ARM
            },
            ..ServoParams::default()
        };
        let mut state = ServoState::holding(0.0);
        let inside = state.step(&params, 0.0, -2.5 * RAD_PER_TICK, 0.0, 0.001);
        assert_eq!(inside.torque, 0.0);
        // Moving inside it, the shorted windings brake: stall torque / no-load speed.
        let braking = state.step(&params, 0.0, -2.5 * RAD_PER_TICK, 0.5, 0.001);
        let back_emf = params.mechanics.stall_torque / params.mechanics.no_load_speed;
        assert!(
            (braking.torque + back_emf * 0.5).abs() < 1e-12,
            "{braking:?}"
        );
        let outside = state.step(&params, 0.0, -3.5 * RAD_PER_TICK, 0.0, 0.001);
        // Measured from the dead zone's edge: 0.5 tick of error.
        assert!((outside.torque - params.kp() * 0.5 * RAD_PER_TICK).abs() < 1e-9);
    }

    #[test]
    fn torque_is_limited_by_torque_limit_and_the_speed_torque_line() {
        let params = ServoParams {
            registers: ServoRegisters::LEROBOT_GRIPPER,
            mechanics: ServoMechanics::STS3215,
        };
        let mut state = ServoState::holding(1.0);
        let still = state.step(&params, 0.0, 0.0, 0.0, 0.001);
        assert!((still.torque - 0.5 * 3.35).abs() < 1e-9, "{still:?}");
        let half_speed = params.mechanics.no_load_speed / 2.0;
        let moving = state.step(&params, 0.0, 0.0, half_speed, 0.001);
        assert!((moving.torque - 0.25 * 3.35).abs() < 1e-9, "{moving:?}");
        let braking = state.step(&params, 0.0, 0.0, -half_speed, 0.001);
        assert!((braking.torque - 0.5 * 3.35).abs() < 1e-9, "{braking:?}");
    }

    #[test]
    fn overload_limits_the_output_after_the_protection_time_and_recovers() {
        let params = ServoParams {
            registers: ServoRegisters::LEROBOT_GRIPPER,
            ..ServoParams::default()
        };
        let mut state = ServoState::holding(1.0);
        let mut time = 0.0;
        let mut output = state.step(&params, time, 0.0, 0.0, 0.01);
        assert!(!output.protecting);
        // Protection_Time 200 x 10 ms = 2 s above 25 %.
        while time < 2.0 {
            time += 0.01;
            output = state.step(&params, time, 0.0, 0.0, 0.01);
        }
        assert!(output.protecting);
        assert!((output.torque - 0.2 * 3.35).abs() < 1e-9, "{output:?}");
        let relieved = state.step(&params, time, 1.0, 0.0, 0.01);
        assert!(!relieved.protecting);
    }

    #[test]
    fn backlash_delays_the_torque_after_a_reversal() {
        let mut params = params();
        params.mechanics.backlash = 0.01;
        let mut state = ServoState::holding(0.0);
        let dt = 0.0005;
        // Pushing up: the first steps cross half the gap, then torque flows.
        let mut silent = 0;
        while state.step(&params, 0.0, -0.1, 0.0, dt).torque == 0.0 {
            silent += 1;
        }
        let half_gap_steps = (0.005 / (params.mechanics.no_load_speed * dt)).ceil() as usize;
        assert_eq!(silent, half_gap_steps);
        // Reversed: the whole gap is crossed first.
        silent = 0;
        while state.step(&params, 0.0, 0.1, 0.0, dt).torque == 0.0 {
            silent += 1;
        }
        assert_eq!(silent, 2 * half_gap_steps);
    }
}
