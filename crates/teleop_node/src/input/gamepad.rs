//! Gamepads through gilrs, whose SDL mapping database gives Xbox, PlayStation, 8BitDo and Logitech
//! pads one standard layout. The first connected pad drives; when it disconnects the arm holds,
//! and the next pad to connect takes over.

use std::time::{Duration, Instant};

use gilrs::{Axis, Button, EventType, GamepadId, Gilrs};

use super::{Reading, Request, Source, Tick};
use crate::{controls::Control, motion::Jog};

/// The analog state the mapping reads (sticks -1..1 with up positive, triggers 0..1, d-pad -1/0/1).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PadState {
    pub left_x: f64,
    pub left_y: f64,
    pub right_x: f64,
    pub right_y: f64,
    pub dpad_y: f64,
    pub left_trigger: f64,
    pub right_trigger: f64,
}

/// Stick and trigger travel below this is ignored; above it the speed grows linearly from 0 at
/// the dead zone's edge to full at full deflection.
pub fn apply_deadzone(value: f64, deadzone: f64) -> f64 {
    let magnitude = value.abs().min(1.0);
    // A broken axis reading (NaN) counts as centred.
    if value.is_nan() || magnitude <= deadzone {
        0.0
    } else {
        value.signum() * (magnitude - deadzone) / (1.0 - deadzone)
    }
}

/// The jog of a pad state. Joint mode: left stick pan (x) and lift (y), right stick elbow (y) and
/// wrist roll (x), d-pad up/down wrist flex. Cartesian mode: left stick x (up: forward) and y
/// (left: +y), right stick z (y) and roll (x), d-pad pitch. Triggers: gripper (right opens, left
/// closes) in both.
pub fn pad_jog(state: &PadState, cartesian: bool, deadzone: f64) -> Jog {
    let dz = |value: f64| apply_deadzone(value, deadzone);
    let gripper = dz(state.right_trigger) - dz(state.left_trigger);
    let axes = if cartesian {
        [
            dz(state.left_y),
            -dz(state.left_x),
            dz(state.right_y),
            state.dpad_y,
            dz(state.right_x),
            gripper,
        ]
    } else {
        [
            dz(state.left_x),
            -dz(state.left_y),
            dz(state.right_y),
            state.dpad_y,
            dz(state.right_x),
            gripper,
        ]
    };
    Jog { axes }
}

/// What a button press does.
pub fn button_control(button: Button) -> Option<Control> {
    match button {
        Button::Start => Some(Control::ToggleRecording),
        Button::South => Some(Control::MarkSuccess),
        Button::East => Some(Control::MarkFailure),
        Button::West => Some(Control::Rerecord),
        Button::North => Some(Control::ResetSim),
        Button::Select => Some(Control::ToggleMode),
        Button::Mode => Some(Control::Halt),
        _ => None,
    }
}

/// How often to try again when gilrs cannot start (no input subsystem yet).
const RETRY: Duration = Duration::from_secs(2);

pub struct Gamepad {
    gilrs: Option<Gilrs>,
    next_try: Instant,
    active: Option<GamepadId>,
    deadzone: f64,
    announced_missing: bool,
}

impl Gamepad {
    pub fn open(deadzone: f64) -> Self {
        let mut gamepad = Self {
            gilrs: None,
            next_try: Instant::now(),
            active: None,
            deadzone,
            announced_missing: false,
        };
        gamepad.connect();
        gamepad
    }

    fn connect(&mut self) {
        if self.gilrs.is_some() || Instant::now() < self.next_try {
            return;
        }
        self.next_try = Instant::now() + RETRY;
        match Gilrs::new() {
            Ok(gilrs) => self.gilrs = Some(gilrs),
            Err(error) => {
                if !self.announced_missing {
                    tracing::warn!(%error, "no gamepad input yet; trying again every 2 s");
                    self.announced_missing = true;
                }
            }
        }
    }

    fn state(gilrs: &Gilrs, id: GamepadId) -> PadState {
        let pad = gilrs.gamepad(id);
        let axis = |axis| f64::from(pad.value(axis));
        let trigger = |button| {
            pad.button_data(button)
                .map_or(0.0, |data| f64::from(data.value()))
        };
        let dpad_y = f64::from(u8::from(pad.is_pressed(Button::DPadUp)))
            - f64::from(u8::from(pad.is_pressed(Button::DPadDown)));
        PadState {
            left_x: axis(Axis::LeftStickX),
            left_y: axis(Axis::LeftStickY),
            right_x: axis(Axis::RightStickX),
            right_y: axis(Axis::RightStickY),
            dpad_y,
            left_trigger: trigger(Button::LeftTrigger2),
            right_trigger: trigger(Button::RightTrigger2),
        }
    }
}

impl Source for Gamepad {
    fn read(&mut self, tick: &Tick) -> Reading {
        self.connect();
        let Some(gilrs) = &mut self.gilrs else {
            return Reading::lost();
        };
        let mut controls = Vec::new();
        while let Some(event) = gilrs.next_event() {
            match event.event {
                EventType::Connected if self.active.is_none() => {
                    tracing::info!(
                        gamepad = gilrs.gamepad(event.id).name(),
                        "gamepad connected"
                    );
                    self.active = Some(event.id);
                }
                EventType::Disconnected if self.active == Some(event.id) => {
                    tracing::warn!("the gamepad disconnected: holding the arm where it is");
                    self.active = None;
                }
                EventType::ButtonPressed(button, _) if self.active == Some(event.id) => {
                    controls.extend(button_control(button));
                }
                _ => {}
            }
        }
        if self.active.is_none() {
            // A pad that was already plugged in when gilrs started sends no Connected event.
            self.active = gilrs.gamepads().next().map(|(id, pad)| {
                tracing::info!(gamepad = pad.name(), "gamepad connected");
                id
            });
        }
        match self.active {
            Some(id) => Reading {
                request: Request::Jog(pad_jog(
                    &Self::state(gilrs, id),
                    tick.cartesian,
                    self.deadzone,
                )),
                controls,
            },
            None => Reading::lost(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dead_zone_swallows_drift_and_scales_the_rest() {
        assert_eq!(apply_deadzone(0.08, 0.1), 0.0);
        assert_eq!(apply_deadzone(-0.1, 0.1), 0.0);
        assert!((apply_deadzone(0.55, 0.1) - 0.5).abs() < 1e-12);
        assert_eq!(apply_deadzone(-1.0, 0.1), -1.0);
        assert_eq!(apply_deadzone(1.7, 0.1), 1.0);
        assert_eq!(apply_deadzone(f64::NAN, 0.1), 0.0);
    }

    #[test]
    fn sticks_triggers_and_dpad_map_to_the_documented_axes() {
        let state = PadState {
            left_x: 1.0,
            left_y: 0.5,
            right_x: -1.0,
            right_y: 1.0,
            dpad_y: 1.0,
            left_trigger: 0.0,
            right_trigger: 1.0,
        };
        let joint = pad_jog(&state, false, 0.0);
        assert_eq!(joint.axes, [1.0, -0.5, 1.0, 1.0, -1.0, 1.0]);
        let cartesian = pad_jog(&state, true, 0.0);
        assert_eq!(cartesian.axes, [0.5, -1.0, 1.0, 1.0, -1.0, 1.0]);
        assert!(pad_jog(
            &PadState {
                left_x: 0.05,
                ..PadState::default()
            },
            false,
            0.1
        )
        .is_still());
    }

    #[test]
    fn buttons_give_the_episode_controls() {
        assert_eq!(
            button_control(Button::Start),
            Some(Control::ToggleRecording)
        );
        assert_eq!(button_control(Button::South), Some(Control::MarkSuccess));
        assert_eq!(button_control(Button::East), Some(Control::MarkFailure));
        assert_eq!(button_control(Button::North), Some(Control::ResetSim));
        assert_eq!(button_control(Button::DPadLeft), None);
    }
}
