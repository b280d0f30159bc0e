//! The keyboard in a terminal (crossterm, raw mode). Terminals report key presses and auto-repeat,
//! and releases only where they support the keyboard-enhancement protocol, so a key moves its axis
//! while it is held (press and repeats keep it alive for [`HOLD`]) and until it is released.

use std::{
    io::{IsTerminal, Write},
    sync::mpsc::{self, Receiver},
    time::{Duration, Instant},
};

use anyhow::{bail, Context, Result};
use crossterm::{
    event::{
        Event, KeyCode, KeyEvent, KeyEventKind, KeyModifiers, KeyboardEnhancementFlags,
        PopKeyboardEnhancementFlags, PushKeyboardEnhancementFlags,
    },
    execute, terminal,
};
use so101_core::robot::JOINT_COUNT;

use super::{Reading, Request, Source, Tick};
use crate::{controls::Control, motion::Jog};

/// How long a press (or auto-repeat) keeps its axis moving without a release report: longer than a
/// terminal's first auto-repeat delay, so a held key moves without a gap.
const HOLD: Duration = Duration::from_millis(550);

/// What a key does.
#[derive(Debug, Clone, PartialEq)]
pub enum KeyAction {
    /// Moves axis `axis` (the [`Jog`] index of the current mode) in `direction` (+1 or -1).
    Axis {
        axis: usize,
        direction: f64,
    },
    Control(Control),
}

/// The key map. The arrows drive pan and lift in joint mode, and the horizontal directions in
/// Cartesian mode (up: forward along x, left: +y); the other keys mean the same axis in both.
pub fn key_action(code: KeyCode, modifiers: KeyModifiers, cartesian: bool) -> Option<KeyAction> {
    let axis = |axis, direction| Some(KeyAction::Axis { axis, direction });
    let control = |control| Some(KeyAction::Control(control));
    if modifiers.contains(KeyModifiers::CONTROL) {
        return matches!(code, KeyCode::Char('c') | KeyCode::Char('d'))
            .then_some(KeyAction::Control(Control::Quit));
    }
    match code {
        KeyCode::Left if cartesian => axis(1, 1.0),
        KeyCode::Right if cartesian => axis(1, -1.0),
        KeyCode::Up if cartesian => axis(0, 1.0),
        KeyCode::Down if cartesian => axis(0, -1.0),
        // Positive pan turns the arm towards -y (right); positive lift lowers it.
        KeyCode::Left => axis(0, -1.0),
        KeyCode::Right => axis(0, 1.0),
        KeyCode::Up => axis(1, -1.0),
        KeyCode::Down => axis(1, 1.0),
        KeyCode::Char('+') | KeyCode::Char('=') => axis(2, 1.0),
        KeyCode::Char('-') | KeyCode::Char('_') => axis(2, -1.0),
        KeyCode::Char('v') | KeyCode::Char('V') => axis(3, 1.0),
        KeyCode::Char('b') | KeyCode::Char('B') => axis(3, -1.0),
        KeyCode::Char('g') | KeyCode::Char('G') => axis(4, 1.0),
        KeyCode::Char('h') | KeyCode::Char('H') => axis(4, -1.0),
        KeyCode::Char('5') => axis(5, -1.0),
        KeyCode::Char('6') => axis(5, 1.0),
        KeyCode::Enter => control(Control::ToggleRecording),
        KeyCode::Char('y') | KeyCode::Char('Y') => control(Control::MarkSuccess),
        KeyCode::Char('n') | KeyCode::Char('N') => control(Control::MarkFailure),
        KeyCode::Backspace => control(Control::Rerecord),
        KeyCode::Char('r') | KeyCode::Char('R') => control(Control::ResetSim),
        KeyCode::Char('m') | KeyCode::Char('M') => control(Control::ToggleMode),
        KeyCode::Char(' ') => control(Control::Halt),
        KeyCode::Esc | KeyCode::Char('q') | KeyCode::Char('Q') => control(Control::Quit),
        _ => None,
    }
}

/// The key map as shown by --help and on screen.
pub const KEY_HELP: &str = "\
keys (joint mode / Cartesian mode):
  Left/Right   shoulder_pan      / y (left = +y)
  Up/Down      shoulder_lift     / x (up = forward)
  + / -        elbow_flex        / z (up / down)
  V / B        wrist_flex        / pitch
  G / H        wrist_roll        / roll
  5 / 6        gripper close / open (both modes)
  Enter start/stop recording, Y success, N failure, Backspace re-record,
  R reset the sim, M joint <-> Cartesian, Space stop moving, Q or Esc quit";

/// Which axes are held, and until when.
#[derive(Debug, Default)]
pub struct HeldKeys {
    /// (axis, direction, key, held until)
    held: Vec<(usize, f64, KeyCode, Instant)>,
}

impl HeldKeys {
    pub fn press(&mut self, axis: usize, direction: f64, key: KeyCode, now: Instant) {
        self.held.retain(|(_, _, held, _)| *held != key);
        self.held.push((axis, direction, key, now + HOLD));
    }

    pub fn release(&mut self, key: KeyCode) {
        self.held.retain(|(_, _, held, _)| *held != key);
    }

    pub fn clear(&mut self) {
        self.held.clear();
    }

    /// The jog of the keys still held at `now`.
    pub fn jog(&mut self, now: Instant) -> Jog {
        self.held.retain(|(_, _, _, until)| *until > now);
        let mut jog = Jog::STILL;
        for (axis, direction, _, _) in &self.held {
            jog.axes[*axis] = (jog.axes[*axis] + direction).clamp(-1.0, 1.0);
        }
        jog
    }
}

/// The keyboard of the terminal on standard input.
pub struct Keyboard {
    events: Receiver<std::io::Result<Event>>,
    held: HeldKeys,
    enhanced: bool,
    lost: bool,
}

impl Keyboard {
    /// Puts the terminal in raw mode (restored on drop) and starts reading keys.
    pub fn open() -> Result<Self> {
        if !std::io::stdin().is_terminal() {
            bail!("the keyboard source needs a terminal on standard input");
        }
        terminal::enable_raw_mode().context("cannot put the terminal in raw mode")?;
        let enhanced = matches!(terminal::supports_keyboard_enhancement(), Ok(true));
        if enhanced {
            let _ = execute!(
                std::io::stdout(),
                PushKeyboardEnhancementFlags(KeyboardEnhancementFlags::REPORT_EVENT_TYPES)
            );
        }
        let (sender, events) = mpsc::channel();
        let spawned = std::thread::Builder::new()
            .name("keyboard".into())
            .spawn(move || loop {
                let event = crossterm::event::read();
                let failed = event.is_err();
                if sender.send(event).is_err() || failed {
                    break;
                }
            });
        if let Err(error) = spawned {
            let _ = terminal::disable_raw_mode();
            return Err(error).context("cannot start the keyboard thread");
        }
        let mut stdout = std::io::stdout();
        let _ = write!(stdout, "{}\r\n", KEY_HELP.replace('\n', "\r\n"));
        let _ = stdout.flush();
        Ok(Self {
            events,
            held: HeldKeys::default(),
            enhanced,
            lost: false,
        })
    }

    fn handle(
        &mut self,
        key: KeyEvent,
        cartesian: bool,
        now: Instant,
        controls: &mut Vec<Control>,
    ) {
        let Some(action) = key_action(key.code, key.modifiers, cartesian) else {
            return;
        };
        match (action, key.kind) {
            (KeyAction::Axis { .. }, KeyEventKind::Release) => self.held.release(key.code),
            (KeyAction::Axis { axis, direction }, _) => {
                self.held.press(axis, direction, key.code, now)
            }
            (KeyAction::Control(control), KeyEventKind::Press) => {
                if matches!(control, Control::Halt | Control::ToggleMode) {
                    self.held.clear();
                }
                controls.push(control);
            }
            (KeyAction::Control(_), _) => {}
        }
    }
}

impl Source for Keyboard {
    fn read(&mut self, tick: &Tick) -> Reading {
        let now = Instant::now();
        let mut controls = Vec::new();
        loop {
            match self.events.try_recv() {
                Ok(Ok(Event::Key(key))) => self.handle(key, tick.cartesian, now, &mut controls),
                Ok(Ok(_)) => {}
                Ok(Err(_)) | Err(mpsc::TryRecvError::Disconnected) => {
                    // The terminal went away: hold, and let the operator's Ctrl-C (a signal) end it.
                    if !self.lost {
                        tracing::warn!("the terminal closed: holding the arm where it is");
                        self.lost = true;
                    }
                    return Reading::lost();
                }
                Err(mpsc::TryRecvError::Empty) => break,
            }
        }
        Reading {
            request: Request::Jog(self.held.jog(now)),
            controls,
        }
    }
}

impl Drop for Keyboard {
    fn drop(&mut self) {
        if self.enhanced {
            let _ = execute!(std::io::stdout(), PopKeyboardEnhancementFlags);
        }
        let _ = terminal::disable_raw_mode();
    }
}

/// Every axis index a key can move must exist in a [`Jog`].
const _: () = assert!(JOINT_COUNT == 6);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_documented_keys_move_their_axes() {
        let none = KeyModifiers::NONE;
        let expect = [
            (KeyCode::Left, 0, -1.0),
            (KeyCode::Right, 0, 1.0),
            (KeyCode::Up, 1, -1.0),
            (KeyCode::Down, 1, 1.0),
            (KeyCode::Char('+'), 2, 1.0),
            (KeyCode::Char('-'), 2, -1.0),
            (KeyCode::Char('v'), 3, 1.0),
            (KeyCode::Char('b'), 3, -1.0),
            (KeyCode::Char('g'), 4, 1.0),
            (KeyCode::Char('h'), 4, -1.0),
            (KeyCode::Char('5'), 5, -1.0),
            (KeyCode::Char('6'), 5, 1.0),
        ];
        for (code, axis, direction) in expect {
            assert_eq!(
                key_action(code, none, false),
                Some(KeyAction::Axis { axis, direction }),
                "{code:?}"
            );
        }
        for (code, axis, direction) in [
            (KeyCode::Up, 0, 1.0),
            (KeyCode::Down, 0, -1.0),
            (KeyCode::Left, 1, 1.0),
            (KeyCode::Right, 1, -1.0),
            (KeyCode::Char('+'), 2, 1.0),
        ] {
            assert_eq!(
                key_action(code, none, true),
                Some(KeyAction::Axis { axis, direction }),
                "{code:?}"
            );
        }
        assert_eq!(
            key_action(KeyCode::Enter, none, false),
            Some(KeyAction::Control(Control::ToggleRecording))
        );
        assert_eq!(
            key_action(KeyCode::Char('c'), KeyModifiers::CONTROL, true),
            Some(KeyAction::Control(Control::Quit))
        );
        assert_eq!(key_action(KeyCode::Char('z'), none, false), None);
    }

    #[test]
    fn a_held_key_moves_until_released_or_its_hold_runs_out() {
        let start = Instant::now();
        let mut held = HeldKeys::default();
        held.press(0, 1.0, KeyCode::Right, start);
        held.press(5, -1.0, KeyCode::Char('5'), start);
        assert_eq!(
            held.jog(start + Duration::from_millis(100)).axes,
            [1.0, 0.0, 0.0, 0.0, 0.0, -1.0]
        );
        held.release(KeyCode::Char('5'));
        assert_eq!(
            held.jog(start + Duration::from_millis(200)).axes,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        );
        // An auto-repeat renews the hold.
        held.press(0, 1.0, KeyCode::Right, start + Duration::from_millis(500));
        assert_eq!(held.jog(start + Duration::from_millis(900)).axes[0], 1.0);
        assert!(held.jog(start + Duration::from_millis(1100)).is_still());
        // Opposite keys cancel.
        held.press(2, 1.0, KeyCode::Char('+'), start);
        held.press(2, -1.0, KeyCode::Char('-'), start);
        assert!(held.jog(start).is_still());
    }
}
