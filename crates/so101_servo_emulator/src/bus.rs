//! The servos on one bus: instruction semantics (protocol 0), injected faults and the timing of
//! the half-duplex wire. Pure: the pty loop feeds it packets and writes back what it returns.
//!
//! A broadcast PING is answered by every plugged servo that can answer, in ascending id order, one
//! status packet after the other, each after its own Return_Delay_Time (how real firmware keeps
//! them apart is not documented; Dynamixel servos answer a broadcast ping in id order, and
//! LeRobot's `broadcast_ping` accepts any order within its timeout).
//!
//! Not modelled: a broadcast READ (nobody answers), and collisions: two plugged servos with the
//! same id both answer a unicast request, one after the other.

use std::{path::Path, time::Duration};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use so101_core::robot::JOINT_NAMES;

use so101_feetech_driver::{
    calibration::ArmCalibration,
    protocol::{
        decode_instruction, encode_status, registers as reg, timing, Instruction, ServoErrors,
        StatusPacket, BROADCAST_ID, MAX_PACKET_LEN,
    },
};

use crate::{error::EmulatorError, servo::ServoModel};

/// Status packet bytes that are not data: header, id, length, error, checksum.
const STATUS_FRAMING: usize = 6;
/// Return_Delay_Time counts in units of 2 us.
const RETURN_DELAY_UNIT: Duration = Duration::from_micros(2);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Timing {
    /// Replies are due as soon as the request is read.
    Instant,
    /// Replies are due when the request, each servo's return delay and the replies would have
    /// passed over a half-duplex wire at `baud`.
    Realistic { baud: u32 },
}

/// Injected faults; all off by default.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Faults {
    /// Probability that a status packet is lost.
    pub drop_probability: f64,
    /// Probability that one bit of a status packet is flipped (after its length byte, so the
    /// frame still parses and fails its checksum, as line noise on the data does).
    pub corrupt_probability: f64,
    /// Added before replies, as a slow USB adapter does.
    pub extra_delay: Duration,
    /// Random bytes sent before the next reply, once.
    pub garbage_bytes: usize,
}

/// One place on the bus: a servo that may be unplugged, or plugged but unable to answer.
#[derive(Debug, Clone)]
pub struct SlotState {
    pub servo: ServoModel,
    pub plugged: bool,
    /// Obeys writes but never answers.
    pub silent: bool,
}

/// What to send back for one request, and when (time since the emulator started).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Response {
    /// Empty when nobody answers.
    pub bytes: Vec<u8>,
    pub due: Duration,
}

/// One slot as `dump` shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SlotSnapshot {
    pub index: usize,
    pub id: u8,
    pub plugged: bool,
    pub silent: bool,
    pub torque_enable: i32,
    pub goal_position: i32,
    pub present_position: i32,
    pub actual: f64,
    pub homing_offset: i32,
    pub min_position_limit: i32,
    pub max_position_limit: i32,
    pub lock: i32,
    pub return_delay_time: i32,
    pub torque_limit: i32,
    pub max_torque_limit: i32,
    pub protection_current: i32,
    pub overload_torque: i32,
    pub operating_mode: i32,
    pub acceleration: i32,
    pub p: i32,
    pub d: i32,
    pub i: i32,
    /// Injected error bits (`error ID BITS`).
    pub errors: u8,
    /// An obstacle blocks the shaft (`stall ID on`).
    pub stalled: bool,
    /// The overload protection tripped (status error 0x20 until torque is enabled again).
    pub overload: bool,
}

/// What survives a power cycle: each slot's flash and where its shaft rests.
#[derive(Debug, Serialize, Deserialize)]
struct SavedState {
    slots: Vec<SavedSlot>,
}

#[derive(Debug, Serialize, Deserialize)]
struct SavedSlot {
    eprom: Vec<u8>,
    actual: f64,
}

#[derive(Debug)]
pub struct BusEmulator {
    pub slots: Vec<SlotState>,
    pub faults: Faults,
    timing: Timing,
    rng: ChaCha8Rng,
    /// When the wire falls silent after the last request and its replies.
    bus_free_at: Duration,
    /// When the physics was last advanced.
    last_advance: Duration,
}

impl BusEmulator {
    pub fn new(slots: Vec<SlotState>, timing: Timing, seed: u64) -> Self {
        Self {
            slots,
            faults: Faults::default(),
            timing,
            rng: ChaCha8Rng::seed_from_u64(seed),
            bus_free_at: Duration::ZERO,
            last_advance: Duration::ZERO,
        }
    }

    /// Factory servos with these ids, all plugged, shafts at mid-range.
    pub fn with_factory_servos(ids: &[u8], timing: Timing, seed: u64) -> Self {
        let slots = ids
            .iter()
            .map(|id| SlotState {
                servo: ServoModel::factory(*id),
                plugged: true,
                silent: false,
            })
            .collect();
        Self::new(slots, timing, seed)
    }

    /// The six servos of an arm calibrated and configured by LeRobot, in joint order, all plugged,
    /// shafts at mid-range (see `ServoModel::calibrated`).
    pub fn with_calibrated_arm(calibration: &ArmCalibration, timing: Timing, seed: u64) -> Self {
        let slots = calibrated_servos(calibration)
            .into_iter()
            .map(|servo| SlotState {
                servo,
                plugged: true,
                silent: false,
            })
            .collect();
        Self::new(slots, timing, seed)
    }

    /// Lets time pass up to `now` for every plugged servo.
    pub fn advance_to(&mut self, now: Duration) {
        let dt = now.saturating_sub(self.last_advance);
        self.last_advance = self.last_advance.max(now);
        for slot in self.slots.iter_mut().filter(|slot| slot.plugged) {
            slot.servo.advance(dt);
        }
    }

    /// Executes one instruction packet that arrived at `now`. Malformed packets are ignored, as
    /// real servos ignore them.
    pub fn handle(&mut self, now: Duration, packet: &[u8]) -> Response {
        self.advance_to(now);
        let replies = match decode_instruction(packet) {
            Ok((id, instruction)) => self.execute(id, &instruction),
            Err(error) => {
                tracing::debug!(%error, "ignoring a malformed instruction");
                Vec::new()
            }
        };
        self.schedule(now, packet.len(), replies)
    }

    /// Whether EPROM bytes reached some servo's flash since the last call (save the state file).
    pub fn take_save_needed(&mut self) -> bool {
        // Every flag is taken, not just the first set one.
        let mut needed = false;
        for slot in &mut self.slots {
            needed |= slot.servo.take_eprom_dirty();
        }
        needed
    }

    /// Indices of the slots whose servo has `id` (plugged or not).
    pub fn slots_with_id(&self, id: u8) -> Vec<usize> {
        (0..self.slots.len())
            .filter(|index| self.slots[*index].servo.id() == id)
            .collect()
    }

    pub fn snapshot(&self) -> Vec<SlotSnapshot> {
        self.slots
            .iter()
            .enumerate()
            .map(|(index, slot)| {
                let servo = &slot.servo;
                SlotSnapshot {
                    index,
                    id: servo.id(),
                    plugged: slot.plugged,
                    silent: slot.silent,
                    torque_enable: servo.register(reg::TORQUE_ENABLE),
                    goal_position: servo.register(reg::GOAL_POSITION),
                    present_position: servo.register(reg::PRESENT_POSITION),
                    actual: servo.actual(),
                    homing_offset: servo.register(reg::HOMING_OFFSET),
                    min_position_limit: servo.register(reg::MIN_POSITION_LIMIT),
                    max_position_limit: servo.register(reg::MAX_POSITION_LIMIT),
                    lock: servo.register(reg::LOCK),
                    return_delay_time: servo.register(reg::RETURN_DELAY_TIME),
                    torque_limit: servo.register(reg::TORQUE_LIMIT),
                    max_torque_limit: servo.register(reg::MAX_TORQUE_LIMIT),
                    protection_current: servo.register(reg::PROTECTION_CURRENT),
                    overload_torque: servo.register(reg::OVERLOAD_TORQUE),
                    operating_mode: servo.register(reg::OPERATING_MODE),
                    acceleration: servo.register(reg::ACCELERATION),
                    p: servo.register(reg::P_COEFFICIENT),
                    d: servo.register(reg::D_COEFFICIENT),
                    i: servo.register(reg::I_COEFFICIENT),
                    errors: servo.errors,
                    stalled: servo.stalled(),
                    overload: servo.overload_tripped(),
                }
            })
            .collect()
    }

    /// Writes every slot's flash and shaft position as JSON (through a temporary file, so a crash
    /// never leaves half a file).
    pub fn save_state(&self, path: &Path) -> Result<(), EmulatorError> {
        let state = SavedState {
            slots: self
                .slots
                .iter()
                .map(|slot| SavedSlot {
                    eprom: slot.servo.eprom().to_vec(),
                    actual: slot.servo.actual(),
                })
                .collect(),
        };
        let error = |reason: String| EmulatorError::SaveState {
            path: path.to_owned(),
            reason,
        };
        let text = serde_json::to_string_pretty(&state).map_err(|e| error(e.to_string()))?;
        let mut temporary = path.as_os_str().to_owned();
        temporary.push(".tmp");
        std::fs::write(&temporary, text).map_err(|e| error(e.to_string()))?;
        std::fs::rename(&temporary, path).map_err(|e| error(e.to_string()))
    }

    /// Powers the servos up from a state file; `Ok(false)` when there is none yet. Slots beyond
    /// those in the file keep their factory state.
    pub fn load_state(&mut self, path: &Path) -> Result<bool, EmulatorError> {
        let error = |reason: String| EmulatorError::StateFile {
            path: path.to_owned(),
            reason,
        };
        let text = match std::fs::read_to_string(path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(false),
            Err(e) => return Err(error(e.to_string())),
        };
        let state: SavedState = serde_json::from_str(&text).map_err(|e| error(e.to_string()))?;
        if state.slots.len() != self.slots.len() {
            tracing::warn!(
                path = %path.display(),
                saved = state.slots.len(),
                slots = self.slots.len(),
                "state file has a different number of slots; restoring those that match"
            );
        }
        for (slot, saved) in self.slots.iter_mut().zip(&state.slots) {
            slot.servo.restore(&saved.eprom, saved.actual);
        }
        Ok(true)
    }

    /// Status packets to send, each with the answering servo's Return_Delay_Time.
    fn execute(&mut self, id: u8, instruction: &Instruction) -> Vec<(StatusPacket, u8)> {
        let broadcast = id == BROADCAST_ID;
        match instruction {
            Instruction::Ping if !broadcast => self.answer(id, |_| Vec::new()),
            Instruction::Ping => self.answer_broadcast_ping(),
            Instruction::Read { address, length } if !broadcast && *length > 0 => {
                self.answer(id, |servo| read_what_fits(servo, *address, *length))
            }
            Instruction::Write { address, data } => {
                self.write_and_answer(id, |servo| servo.write(*address, data))
            }
            Instruction::RegWrite { address, data } => {
                self.write_and_answer(id, |servo| servo.stage(*address, data))
            }
            Instruction::Action => self.write_and_answer(id, ServoModel::action),
            Instruction::SyncRead {
                address,
                length,
                ids,
            } if broadcast && *length > 0 => ids
                .iter()
                .flat_map(|id| self.answer(*id, |servo| read_what_fits(servo, *address, *length)))
                .collect(),
            Instruction::SyncWrite {
                address, entries, ..
            } if broadcast => {
                for (id, data) in entries {
                    for index in self.addressed(*id) {
                        self.slots[index].servo.write(*address, data);
                    }
                }
                Vec::new()
            }
            _ => Vec::new(),
        }
    }

    /// Plugged slots that obey a request to `id` (every plugged one for broadcast).
    fn addressed(&self, id: u8) -> Vec<usize> {
        (0..self.slots.len())
            .filter(|index| {
                let slot = &self.slots[*index];
                slot.plugged && (id == BROADCAST_ID || slot.servo.id() == id)
            })
            .collect()
    }

    /// A status packet from each addressed servo that can answer, with `parameters(servo)`.
    fn answer(
        &self,
        id: u8,
        parameters: impl Fn(&ServoModel) -> Vec<u8>,
    ) -> Vec<(StatusPacket, u8)> {
        self.addressed(id)
            .into_iter()
            .filter(|index| !self.slots[*index].silent)
            .map(|index| self.status(index, id, parameters(&self.slots[index].servo)))
            .collect()
    }

    /// Every plugged servo that can answer, in ascending id order (bus order among equal ids),
    /// each with its own id.
    fn answer_broadcast_ping(&self) -> Vec<(StatusPacket, u8)> {
        let mut answering: Vec<usize> = self
            .addressed(BROADCAST_ID)
            .into_iter()
            .filter(|index| !self.slots[*index].silent)
            .collect();
        answering.sort_by_key(|index| self.slots[*index].servo.id());
        answering
            .into_iter()
            .map(|index| self.status(index, self.slots[index].servo.id(), Vec::new()))
            .collect()
    }

    /// Applies `apply` to each addressed servo; those with Response_Status_Level >= 1 answer a
    /// unicast request. The answer carries the id the request was sent to: after a write of ID
    /// the servo still answers as the one that was asked.
    fn write_and_answer(
        &mut self,
        id: u8,
        apply: impl Fn(&mut ServoModel),
    ) -> Vec<(StatusPacket, u8)> {
        let targets = self.addressed(id);
        for index in &targets {
            apply(&mut self.slots[*index].servo);
        }
        if id == BROADCAST_ID {
            return Vec::new();
        }
        targets
            .into_iter()
            .filter(|index| {
                let slot = &self.slots[*index];
                !slot.silent && slot.servo.register(reg::RESPONSE_STATUS_LEVEL) >= 1
            })
            .map(|index| self.status(index, id, Vec::new()))
            .collect()
    }

    fn status(&self, index: usize, id: u8, parameters: Vec<u8>) -> (StatusPacket, u8) {
        let servo = &self.slots[index].servo;
        let delay = servo.register(reg::RETURN_DELAY_TIME).clamp(0, 255) as u8;
        let status = StatusPacket {
            id,
            errors: ServoErrors(servo.status_errors()),
            parameters,
        };
        (status, delay)
    }

    /// Turns the status packets into bytes (applying faults) and decides when they are due.
    fn schedule(
        &mut self,
        now: Duration,
        request_len: usize,
        replies: Vec<(StatusPacket, u8)>,
    ) -> Response {
        let mut wire_at = now.max(self.bus_free_at) + self.wire_time(request_len);
        let mut bytes = Vec::new();
        for (status, return_delay) in replies {
            if self.chance(self.faults.drop_probability) {
                continue;
            }
            // Only ids the protocol allows reach here, so encoding cannot fail; skip if it does.
            let Ok(mut packet) = encode_status(&status) else {
                continue;
            };
            if self.chance(self.faults.corrupt_probability) {
                let index = self.rng.gen_range(4..packet.len());
                packet[index] ^= 1 << self.rng.gen_range(0..8);
            }
            if bytes.is_empty() && self.faults.garbage_bytes > 0 {
                let garbage: Vec<u8> = (0..std::mem::take(&mut self.faults.garbage_bytes))
                    .map(|_| self.rng.gen())
                    .collect();
                wire_at += self.wire_time(garbage.len());
                bytes.extend(garbage);
            }
            wire_at += self.return_delay(return_delay) + self.wire_time(packet.len());
            bytes.extend(packet);
        }
        if !bytes.is_empty() {
            wire_at += self.faults.extra_delay;
        }
        self.bus_free_at = wire_at;
        Response {
            bytes,
            due: wire_at,
        }
    }

    fn chance(&mut self, probability: f64) -> bool {
        probability > 0.0 && self.rng.gen::<f64>() < probability
    }

    fn wire_time(&self, bytes: usize) -> Duration {
        match self.timing {
            Timing::Instant => Duration::ZERO,
            Timing::Realistic { baud } => timing::wire_time(baud, bytes),
        }
    }

    fn return_delay(&self, register: u8) -> Duration {
        match self.timing {
            Timing::Instant => Duration::ZERO,
            Timing::Realistic { .. } => RETURN_DELAY_UNIT * u32::from(register),
        }
    }
}

/// The servos of a calibrated arm, in joint order (the last one is the gripper).
pub fn calibrated_servos(calibration: &ArmCalibration) -> Vec<ServoModel> {
    calibration
        .motors
        .iter()
        .zip(JOINT_NAMES)
        .map(|(motor, name)| ServoModel::calibrated(motor, name == "gripper"))
        .collect()
}

/// The bytes a READ of `length` at `address` returns, cut at the table's end and at what fits in
/// the longest packet.
fn read_what_fits(servo: &ServoModel, address: u8, length: u8) -> Vec<u8> {
    let mut data = servo.read(address, length);
    data.truncate(MAX_PACKET_LEN - STATUS_FRAMING);
    data
}

#[cfg(test)]
mod tests {
    use super::*;
    use so101_feetech_driver::protocol::{decode_status, encode_instruction, PacketReader};

    fn bus(timing: Timing) -> BusEmulator {
        BusEmulator::with_factory_servos(&[1, 2, 3, 4, 5, 6], timing, 7)
    }

    fn request(id: u8, instruction: Instruction) -> Vec<u8> {
        encode_instruction(id, &instruction).unwrap()
    }

    fn statuses(bytes: &[u8]) -> Vec<StatusPacket> {
        let mut reader = PacketReader::new();
        reader.push(bytes);
        std::iter::from_fn(|| reader.next_status())
            .map(|status| status.unwrap())
            .collect()
    }

    fn write(id: u8, address: u8, data: &[u8]) -> Vec<u8> {
        request(
            id,
            Instruction::Write {
                address,
                data: data.to_vec(),
            },
        )
    }

    #[test]
    fn ping_read_and_write_answer_like_the_servo() {
        let mut bus = bus(Timing::Instant);
        let ping = bus.handle(Duration::ZERO, &request(3, Instruction::Ping));
        assert_eq!(decode_status(&ping.bytes).unwrap().id, 3);
        let read = bus.handle(
            Duration::ZERO,
            &request(
                2,
                Instruction::Read {
                    address: 3,
                    length: 2,
                },
            ),
        );
        assert_eq!(
            decode_status(&read.bytes).unwrap().parameters,
            777u16.to_le_bytes()
        );
        let written = bus.handle(Duration::ZERO, &write(1, 41, &[254]));
        assert!(decode_status(&written.bytes).unwrap().parameters.is_empty());
        assert!(bus
            .handle(Duration::ZERO, &request(9, Instruction::Ping))
            .bytes
            .is_empty());
        let broadcast = bus.handle(Duration::ZERO, &write(BROADCAST_ID, 41, &[7]));
        assert!(broadcast.bytes.is_empty());
        assert!(bus
            .slots
            .iter()
            .all(|slot| slot.servo.register(reg::ACCELERATION) == 7));
    }

    #[test]
    fn response_status_level_zero_silences_write_replies_only() {
        let mut bus = bus(Timing::Instant);
        // The new level applies at once: even the write that sets it goes unanswered.
        assert!(bus
            .handle(Duration::ZERO, &write(1, 8, &[0]))
            .bytes
            .is_empty());
        assert!(bus
            .handle(Duration::ZERO, &write(1, 41, &[1]))
            .bytes
            .is_empty());
        assert!(!bus
            .handle(Duration::ZERO, &request(1, Instruction::Ping))
            .bytes
            .is_empty());
    }

    #[test]
    fn action_applies_what_reg_write_staged() {
        let mut bus = bus(Timing::Instant);
        let staged = request(
            4,
            Instruction::RegWrite {
                address: 41,
                data: vec![99],
            },
        );
        assert!(!bus.handle(Duration::ZERO, &staged).bytes.is_empty());
        assert_eq!(bus.slots[3].servo.register(reg::ACCELERATION), 0);
        let action = bus.handle(Duration::ZERO, &request(BROADCAST_ID, Instruction::Action));
        assert!(action.bytes.is_empty());
        assert_eq!(bus.slots[3].servo.register(reg::ACCELERATION), 99);
    }

    #[test]
    fn sync_read_answers_in_request_order_without_absent_or_silent_servos() {
        let mut bus = bus(Timing::Instant);
        bus.slots[1].silent = true;
        bus.slots[4].plugged = false;
        let sync_read = request(
            BROADCAST_ID,
            Instruction::SyncRead {
                address: 56,
                length: 2,
                ids: vec![6, 1, 2, 9, 5, 3],
            },
        );
        let ids: Vec<u8> = statuses(&bus.handle(Duration::ZERO, &sync_read).bytes)
            .iter()
            .map(|status| status.id)
            .collect();
        assert_eq!(ids, [6, 1, 3]);
    }

    #[test]
    fn sync_write_and_sync_read_of_six_take_880_us_at_one_megabaud() {
        let mut bus = bus(Timing::Realistic { baud: 1_000_000 });
        bus.handle(Duration::ZERO, &write(BROADCAST_ID, 7, &[0]));
        let start = bus.bus_free_at;
        let entries = (1..=6).map(|id| (id, vec![0x00, 0x08])).collect();
        let sync_write = request(
            BROADCAST_ID,
            Instruction::SyncWrite {
                address: 42,
                length: 2,
                entries,
            },
        );
        let written = bus.handle(start, &sync_write);
        assert!(written.bytes.is_empty());
        assert_eq!(written.due, start + Duration::from_micros(260));
        let sync_read = request(
            BROADCAST_ID,
            Instruction::SyncRead {
                address: 56,
                length: 2,
                ids: vec![1, 2, 3, 4, 5, 6],
            },
        );
        let read = bus.handle(start, &sync_read);
        assert_eq!(read.bytes.len(), 48);
        assert_eq!(read.due, start + Duration::from_micros(880));
    }

    #[test]
    fn return_delay_time_is_waited_per_answering_servo() {
        let mut bus = bus(Timing::Realistic { baud: 1_000_000 });
        let ping = bus.handle(Duration::ZERO, &request(1, Instruction::Ping));
        // 6-byte request, 500 us factory delay, 6-byte reply.
        assert_eq!(ping.due, Duration::from_micros(60 + 500 + 60));
    }

    #[test]
    fn broadcast_ping_is_answered_by_every_servo_in_id_order_one_after_the_other() {
        let mut bus = BusEmulator::with_factory_servos(
            &[3, 1, 6, 2, 5, 4],
            Timing::Realistic { baud: 1_000_000 },
            7,
        );
        bus.slots[4].silent = true; // id 5
        bus.slots[5].plugged = false; // id 4
        bus.slots[2].servo.errors = ServoErrors::OVERHEAT; // id 6
        let ping = request(BROADCAST_ID, Instruction::Ping);
        let response = bus.handle(Duration::ZERO, &ping);
        let answers = statuses(&response.bytes);
        let ids: Vec<u8> = answers.iter().map(|status| status.id).collect();
        assert_eq!(ids, [1, 2, 3, 6]);
        assert!(answers.iter().all(|status| status.parameters.is_empty()));
        assert_eq!(answers[3].errors, ServoErrors(ServoErrors::OVERHEAT));
        // The 6-byte request, then per servo its return delay (factory 500 us) and its status.
        assert_eq!(response.due, Duration::from_micros(60 + 4 * (500 + 60)));
        // LeRobot's Return_Delay_Time 0: back to back.
        bus.handle(response.due, &write(BROADCAST_ID, 7, &[0]));
        let start = bus.bus_free_at;
        assert_eq!(
            bus.handle(start, &ping).due,
            start + Duration::from_micros(60 + 4 * 60)
        );
    }

    #[test]
    fn a_negative_present_position_is_read_with_the_sign_at_bit_15() {
        let mut bus = bus(Timing::Instant);
        bus.slots[0].servo.set_actual(30.0);
        bus.handle(Duration::ZERO, &write(1, 31, &[100, 0]));
        let read = request(
            1,
            Instruction::Read {
                address: 56,
                length: 2,
            },
        );
        let status = decode_status(&bus.handle(Duration::ZERO, &read).bytes).unwrap();
        assert_eq!(status.parameters, [70, 0x80]);
    }

    #[test]
    fn an_overloaded_servo_reports_it_and_reads_torque_off() {
        let mut bus = bus(Timing::Instant);
        bus.handle(Duration::ZERO, &write(2, 35, &[10])); // Protection_Time 100 ms
        bus.handle(Duration::ZERO, &write(2, 40, &[1]));
        bus.slots[1].servo.set_stalled(true);
        bus.handle(Duration::ZERO, &write(2, 42, &[0x00, 0x0C])); // goal 3072, blocked at 2048
        let torque = request(
            2,
            Instruction::Read {
                address: 40,
                length: 1,
            },
        );
        let before = decode_status(&bus.handle(Duration::from_millis(90), &torque).bytes).unwrap();
        assert_eq!(
            (before.errors, before.parameters),
            (ServoErrors(0), vec![1])
        );
        let after = decode_status(&bus.handle(Duration::from_millis(120), &torque).bytes).unwrap();
        assert_eq!(after.errors, ServoErrors(ServoErrors::OVERLOAD));
        assert_eq!(after.parameters, [0]);
        let snapshot = &bus.snapshot()[1];
        assert!(snapshot.overload && snapshot.stalled && snapshot.torque_enable == 0);
        // Torque enabled again: the error is gone.
        let enabled = bus.handle(Duration::from_millis(130), &write(2, 40, &[1]));
        assert_eq!(
            decode_status(&enabled.bytes).unwrap().errors,
            ServoErrors(0)
        );
    }

    #[test]
    fn a_calibrated_arm_has_the_files_ids_in_joint_order() {
        let calibration = ArmCalibration::from_json(
            include_str!("../../../assets/emulated_arm/so101_calibration.json"),
            Path::new("so101_calibration.json"),
        )
        .unwrap();
        let bus = BusEmulator::with_calibrated_arm(&calibration, Timing::Instant, 0);
        let snapshot = bus.snapshot();
        for (slot, motor) in snapshot.iter().zip(&calibration.motors) {
            assert_eq!(slot.id, motor.id);
            assert_eq!(slot.homing_offset, motor.homing_offset);
            assert_eq!(slot.min_position_limit, motor.range_min);
            assert_eq!(slot.max_position_limit, motor.range_max);
            assert_eq!(
                slot.present_position,
                (motor.range_min + motor.range_max) / 2
            );
            assert_eq!(slot.return_delay_time, 0);
        }
        assert_eq!(snapshot[5].max_torque_limit, 500);
        assert_eq!(snapshot[0].max_torque_limit, 1000);
    }

    #[test]
    fn faults_drop_corrupt_and_prefix_garbage() {
        let mut bus = bus(Timing::Instant);
        let ping = request(1, Instruction::Ping);
        bus.faults.drop_probability = 1.0;
        assert!(bus.handle(Duration::ZERO, &ping).bytes.is_empty());
        bus.faults = Faults {
            corrupt_probability: 1.0,
            ..Faults::default()
        };
        let corrupted = bus.handle(Duration::ZERO, &ping).bytes;
        assert_eq!(corrupted.len(), 6);
        assert!(decode_status(&corrupted).is_err());
        bus.faults = Faults {
            garbage_bytes: 5,
            extra_delay: Duration::from_millis(3),
            ..Faults::default()
        };
        let response = bus.handle(Duration::from_secs(1), &ping);
        assert_eq!(response.bytes.len(), 11);
        assert_eq!(response.due, Duration::from_millis(1003));
        assert_eq!(bus.handle(Duration::from_secs(2), &ping).bytes.len(), 6);
        bus.slots[0].servo.errors = ServoErrors::OVERLOAD;
        let status = decode_status(&bus.handle(Duration::from_secs(3), &ping).bytes).unwrap();
        assert_eq!(status.errors, ServoErrors(ServoErrors::OVERLOAD));
    }

    #[test]
    fn garbage_and_odd_requests_never_panic() {
        let mut bus = bus(Timing::Realistic { baud: 1_000_000 });
        for packet in [
            vec![],
            vec![0xFF, 0xFF, 1, 2, 0x77, 0x85],
            request(
                1,
                Instruction::Read {
                    address: 250,
                    length: 255,
                },
            ),
            request(
                1,
                Instruction::Read {
                    address: 0,
                    length: 0,
                },
            ),
            write(1, 255, &[1, 2, 3]),
        ] {
            bus.handle(Duration::ZERO, &packet);
        }
        let long = bus.handle(
            Duration::ZERO,
            &request(
                1,
                Instruction::Read {
                    address: 250,
                    length: 255,
                },
            ),
        );
        assert_eq!(decode_status(&long.bytes).unwrap().parameters.len(), 6);
    }

    #[test]
    fn state_round_trips_through_a_file_and_only_unlocked_eprom_is_saved() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        let mut bus = bus(Timing::Instant);
        bus.handle(Duration::ZERO, &write(2, 31, &[10, 0]));
        assert!(!bus.take_save_needed(), "Lock is 1: nothing to persist");
        bus.handle(Duration::ZERO, &write(3, 55, &[0]));
        bus.handle(Duration::ZERO, &write(3, 31, &[20, 0]));
        assert!(bus.take_save_needed());
        bus.slots[3].servo.set_actual(100.0);
        bus.save_state(&path).unwrap();

        let mut restored =
            BusEmulator::with_factory_servos(&[1, 2, 3, 4, 5, 6], Timing::Instant, 1);
        assert!(restored.load_state(&path).unwrap());
        assert_eq!(restored.slots[1].servo.register(reg::HOMING_OFFSET), 0);
        assert_eq!(restored.slots[2].servo.register(reg::HOMING_OFFSET), 20);
        assert_eq!(restored.slots[3].servo.actual(), 100.0);
        assert!(!restored
            .load_state(&dir.path().join("absent.json"))
            .unwrap());
        std::fs::write(&path, "not json").unwrap();
        assert!(matches!(
            restored.load_state(&path),
            Err(EmulatorError::StateFile { .. })
        ));
    }
}
