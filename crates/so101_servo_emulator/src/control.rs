//! Runtime control of the emulator, one command per line: what a hand, a loose cable or a noisy
//! bus would do to the servos, so tests can provoke it on demand.
//!
//! ```text
//! move ID TICKS        set a servo's shaft (absolute ticks), as a hand does with torque off
//! silent ID on|off     the servo obeys but stops answering
//! error ID BITS        status error bits of every reply (decimal or 0x hex)
//! stall ID on|off      an obstacle blocks the shaft (position error and load build up)
//! overload ID          trip the servo's overload protection now (error 0x20, torque off)
//! drop P | corrupt P   probability (0..=1) that a reply is lost | has a flipped bit
//! delay MS             extra delay before replies (milliseconds, fractional allowed)
//! garbage N            N random bytes before the next reply
//! unplug INDEX | plug INDEX   detach / attach the servo in slot INDEX (0-based)
//! hangup SECONDS       the adapter disappears and comes back after SECONDS
//! clear | dump | quit  all faults off (obstacles too) | one JSON line with every slot | stop
//! ```

use std::{str::FromStr, time::Duration};

use crate::bus::{BusEmulator, Faults};

const USAGE_MOVE: &str = "move ID TICKS";
const USAGE_SILENT: &str = "silent ID on|off";
const USAGE_ERROR: &str = "error ID BITS";
const USAGE_STALL: &str = "stall ID on|off";
const USAGE_OVERLOAD: &str = "overload ID";

#[derive(Debug, Clone, PartialEq)]
pub enum ControlCommand {
    Move { id: u8, ticks: f64 },
    Silent { id: u8, on: bool },
    Error { id: u8, bits: u8 },
    Stall { id: u8, on: bool },
    Overload { id: u8 },
    Drop(f64),
    Corrupt(f64),
    Delay(Duration),
    Garbage(usize),
    Unplug(usize),
    Plug(usize),
    Hangup(Duration),
    Clear,
    Dump,
    Quit,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ControlError {
    #[error("empty command")]
    Empty,
    #[error("unknown command `{0}` (known: move, silent, error, stall, overload, drop, corrupt, delay, garbage, unplug, plug, hangup, clear, dump, quit)")]
    Unknown(String),
    #[error("usage: {0}")]
    Usage(&'static str),
    #[error("{what} `{value}` is not {expected}")]
    BadValue {
        what: &'static str,
        value: String,
        expected: &'static str,
    },
    #[error("no servo has id {0}")]
    NoSuchId(u8),
    #[error("no slot {index} (the bus has {slots})")]
    NoSuchSlot { index: usize, slots: usize },
}

impl FromStr for ControlCommand {
    type Err = ControlError;

    fn from_str(line: &str) -> Result<Self, ControlError> {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some((name, arguments)) = words.split_first() else {
            return Err(ControlError::Empty);
        };
        let expect = |count: usize, usage: &'static str| {
            if arguments.len() == count {
                Ok(())
            } else {
                Err(ControlError::Usage(usage))
            }
        };
        let command = match *name {
            "move" => {
                expect(2, USAGE_MOVE)?;
                Self::Move {
                    id: parse_id(arguments[0])?,
                    ticks: parse_number(arguments[1], "ticks", "a finite number")?,
                }
            }
            "silent" => {
                expect(2, USAGE_SILENT)?;
                Self::Silent {
                    id: parse_id(arguments[0])?,
                    on: parse_switch(arguments[1])?,
                }
            }
            "stall" => {
                expect(2, USAGE_STALL)?;
                Self::Stall {
                    id: parse_id(arguments[0])?,
                    on: parse_switch(arguments[1])?,
                }
            }
            "overload" => {
                expect(1, USAGE_OVERLOAD)?;
                Self::Overload {
                    id: parse_id(arguments[0])?,
                }
            }
            "error" => {
                expect(2, USAGE_ERROR)?;
                Self::Error {
                    id: parse_id(arguments[0])?,
                    bits: parse_bits(arguments[1])?,
                }
            }
            "drop" => {
                expect(1, "drop P")?;
                Self::Drop(parse_probability(arguments[0])?)
            }
            "corrupt" => {
                expect(1, "corrupt P")?;
                Self::Corrupt(parse_probability(arguments[0])?)
            }
            "delay" => {
                expect(1, "delay MS")?;
                Self::Delay(parse_duration(arguments[0], 1e-3, "delay")?)
            }
            "garbage" => {
                expect(1, "garbage N")?;
                Self::Garbage(parse_count(arguments[0], "byte count")?)
            }
            "unplug" => {
                expect(1, "unplug INDEX")?;
                Self::Unplug(parse_count(arguments[0], "slot index")?)
            }
            "plug" => {
                expect(1, "plug INDEX")?;
                Self::Plug(parse_count(arguments[0], "slot index")?)
            }
            "hangup" => {
                expect(1, "hangup SECONDS")?;
                Self::Hangup(parse_duration(arguments[0], 1.0, "hangup time")?)
            }
            "clear" => {
                expect(0, "clear")?;
                Self::Clear
            }
            "dump" => {
                expect(0, "dump")?;
                Self::Dump
            }
            "quit" => {
                expect(0, "quit")?;
                Self::Quit
            }
            other => return Err(ControlError::Unknown(other.to_owned())),
        };
        Ok(command)
    }
}

impl ControlCommand {
    /// Applies a command that changes the bus. `hangup`, `dump` and `quit` concern the pty and
    /// its caller, and do nothing here.
    pub fn apply(&self, bus: &mut BusEmulator) -> Result<(), ControlError> {
        match *self {
            Self::Move { id, ticks } => {
                for index in existing_slots(bus, id)? {
                    bus.slots[index].servo.set_actual(ticks);
                }
            }
            Self::Silent { id, on } => {
                for index in existing_slots(bus, id)? {
                    bus.slots[index].silent = on;
                }
            }
            Self::Error { id, bits } => {
                for index in existing_slots(bus, id)? {
                    bus.slots[index].servo.errors = bits;
                }
            }
            Self::Stall { id, on } => {
                for index in existing_slots(bus, id)? {
                    bus.slots[index].servo.set_stalled(on);
                }
            }
            Self::Overload { id } => {
                for index in existing_slots(bus, id)? {
                    bus.slots[index].servo.trip_overload();
                }
            }
            Self::Drop(probability) => bus.faults.drop_probability = probability,
            Self::Corrupt(probability) => bus.faults.corrupt_probability = probability,
            Self::Delay(delay) => bus.faults.extra_delay = delay,
            Self::Garbage(count) => bus.faults.garbage_bytes = count,
            Self::Unplug(index) | Self::Plug(index) => {
                let slots = bus.slots.len();
                let slot = bus
                    .slots
                    .get_mut(index)
                    .ok_or(ControlError::NoSuchSlot { index, slots })?;
                slot.plugged = matches!(self, Self::Plug(_));
            }
            Self::Clear => {
                bus.faults = Faults::default();
                for slot in &mut bus.slots {
                    slot.silent = false;
                    slot.servo.errors = 0;
                    slot.servo.set_stalled(false);
                }
            }
            Self::Hangup(_) | Self::Dump | Self::Quit => {}
        }
        Ok(())
    }
}

fn existing_slots(bus: &BusEmulator, id: u8) -> Result<Vec<usize>, ControlError> {
    let slots = bus.slots_with_id(id);
    if slots.is_empty() {
        return Err(ControlError::NoSuchId(id));
    }
    Ok(slots)
}

fn bad(what: &'static str, value: &str, expected: &'static str) -> ControlError {
    ControlError::BadValue {
        what,
        value: value.to_owned(),
        expected,
    }
}

fn parse_id(word: &str) -> Result<u8, ControlError> {
    word.parse()
        .map_err(|_| bad("id", word, "an integer 0..=255"))
}

fn parse_switch(word: &str) -> Result<bool, ControlError> {
    match word {
        "on" => Ok(true),
        "off" => Ok(false),
        other => Err(bad("switch", other, "on or off")),
    }
}

fn parse_number(
    word: &str,
    what: &'static str,
    expected: &'static str,
) -> Result<f64, ControlError> {
    word.parse::<f64>()
        .ok()
        .filter(|value| value.is_finite())
        .ok_or_else(|| bad(what, word, expected))
}

fn parse_probability(word: &str) -> Result<f64, ControlError> {
    let expected = "a probability in 0..=1";
    parse_number(word, "probability", expected)
        .ok()
        .filter(|value| (0.0..=1.0).contains(value))
        .ok_or_else(|| bad("probability", word, expected))
}

/// A non-negative number of `unit` seconds.
fn parse_duration(word: &str, unit: f64, what: &'static str) -> Result<Duration, ControlError> {
    let expected = "a non-negative number";
    parse_number(word, what, expected)
        .ok()
        .and_then(|value| Duration::try_from_secs_f64(value * unit).ok())
        .ok_or_else(|| bad(what, word, expected))
}

fn parse_count(word: &str, what: &'static str) -> Result<usize, ControlError> {
    word.parse()
        .map_err(|_| bad(what, word, "a non-negative integer"))
}

fn parse_bits(word: &str) -> Result<u8, ControlError> {
    let parsed = match word.strip_prefix("0x").or_else(|| word.strip_prefix("0X")) {
        Some(hex) => u8::from_str_radix(hex, 16),
        None => word.parse(),
    };
    parsed.map_err(|_| bad("error bits", word, "a byte (decimal or 0x hex)"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::Timing;

    fn parse(line: &str) -> Result<ControlCommand, ControlError> {
        line.parse()
    }

    #[test]
    fn every_command_parses() {
        assert_eq!(
            parse("move 3 1024.5"),
            Ok(ControlCommand::Move {
                id: 3,
                ticks: 1024.5
            })
        );
        assert_eq!(
            parse("  silent 2   on "),
            Ok(ControlCommand::Silent { id: 2, on: true })
        );
        assert_eq!(
            parse("error 1 0x24"),
            Ok(ControlCommand::Error { id: 1, bits: 0x24 })
        );
        assert_eq!(
            parse("error 1 8"),
            Ok(ControlCommand::Error { id: 1, bits: 8 })
        );
        assert_eq!(
            parse("stall 4 on"),
            Ok(ControlCommand::Stall { id: 4, on: true })
        );
        assert_eq!(
            parse("stall 4 off"),
            Ok(ControlCommand::Stall { id: 4, on: false })
        );
        assert_eq!(parse("overload 6"), Ok(ControlCommand::Overload { id: 6 }));
        assert_eq!(parse("drop 0.25"), Ok(ControlCommand::Drop(0.25)));
        assert_eq!(parse("corrupt 1"), Ok(ControlCommand::Corrupt(1.0)));
        assert_eq!(
            parse("delay 1.5"),
            Ok(ControlCommand::Delay(Duration::from_micros(1500)))
        );
        assert_eq!(parse("garbage 7"), Ok(ControlCommand::Garbage(7)));
        assert_eq!(parse("unplug 0"), Ok(ControlCommand::Unplug(0)));
        assert_eq!(parse("plug 5"), Ok(ControlCommand::Plug(5)));
        assert_eq!(
            parse("hangup 0.5"),
            Ok(ControlCommand::Hangup(Duration::from_millis(500)))
        );
        assert_eq!(parse("clear"), Ok(ControlCommand::Clear));
        assert_eq!(parse("dump"), Ok(ControlCommand::Dump));
        assert_eq!(parse("quit"), Ok(ControlCommand::Quit));
    }

    #[test]
    fn bad_lines_say_what_is_wrong() {
        assert_eq!(parse(""), Err(ControlError::Empty));
        assert_eq!(parse("jump 1"), Err(ControlError::Unknown("jump".into())));
        assert_eq!(parse("move 1"), Err(ControlError::Usage("move ID TICKS")));
        assert_eq!(parse("dump now"), Err(ControlError::Usage("dump")));
        let message = |line: &str| parse(line).unwrap_err().to_string();
        assert_eq!(
            message("drop 1.5"),
            "probability `1.5` is not a probability in 0..=1"
        );
        assert_eq!(message("silent 1 maybe"), "switch `maybe` is not on or off");
        assert_eq!(message("stall 1"), "usage: stall ID on|off");
        assert_eq!(message("overload"), "usage: overload ID");
        assert_eq!(message("move 300 5"), "id `300` is not an integer 0..=255");
        assert_eq!(message("move 1 nan"), "ticks `nan` is not a finite number");
        assert!(message("error 1 0x100").contains("0x hex"));
        assert!(message("delay -1").contains("non-negative"));
        assert!(message("garbage -1").contains("non-negative integer"));
    }

    #[test]
    fn commands_change_the_bus() {
        let mut bus = BusEmulator::with_factory_servos(&[1, 2], Timing::Instant, 0);
        parse("move 2 100").unwrap().apply(&mut bus).unwrap();
        assert_eq!(bus.slots[1].servo.actual(), 100.0);
        parse("silent 1 on").unwrap().apply(&mut bus).unwrap();
        parse("error 1 0x20").unwrap().apply(&mut bus).unwrap();
        parse("drop 0.5").unwrap().apply(&mut bus).unwrap();
        parse("unplug 1").unwrap().apply(&mut bus).unwrap();
        assert!(bus.slots[0].silent && !bus.slots[1].plugged);
        assert_eq!(bus.slots[0].servo.errors, 0x20);
        assert_eq!(bus.faults.drop_probability, 0.5);
        parse("stall 2 on").unwrap().apply(&mut bus).unwrap();
        assert!(bus.slots[1].servo.stalled());
        parse("overload 1").unwrap().apply(&mut bus).unwrap();
        assert!(bus.slots[0].servo.overload_tripped());
        assert_eq!(bus.slots[0].servo.status_errors(), 0x20);
        parse("clear").unwrap().apply(&mut bus).unwrap();
        assert!(!bus.slots[0].silent && bus.slots[0].servo.errors == 0);
        assert!(!bus.slots[1].servo.stalled(), "clear takes obstacles away");
        assert!(
            bus.slots[0].servo.overload_tripped(),
            "a tripped protection stays until torque is enabled"
        );
        assert_eq!(bus.faults, Faults::default());
        assert!(!bus.slots[1].plugged, "clear leaves the wiring alone");
        assert_eq!(
            parse("move 9 0").unwrap().apply(&mut bus),
            Err(ControlError::NoSuchId(9))
        );
        assert_eq!(
            parse("plug 2").unwrap().apply(&mut bus),
            Err(ControlError::NoSuchSlot { index: 2, slots: 2 })
        );
    }
}
