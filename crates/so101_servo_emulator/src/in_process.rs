//! The emulated bus as an in-process transport: the driver's state machine runs against the same
//! servo models as on the pty, without a pty or a serving thread, so its tests are fast and
//! deterministic. Faults a pty cannot time to the request are injected here: replies held back
//! past the driver's timeout (late), a position misread once, the adapter unplugged mid-write.
//! Every goal written is audited against where the servo was at that moment.

use std::{
    collections::VecDeque,
    io::{self, Write},
    sync::{Arc, Mutex, MutexGuard, PoisonError},
    time::{Duration, Instant},
};

use so101_feetech_driver::{
    bus::{Connector, Transport},
    protocol::{
        decode_instruction, encode_status, registers as reg, Instruction, PacketReader,
        StatusPacket,
    },
};

use crate::bus::BusEmulator;

/// Largest distance between a goal and the servo's position when it was written, over all goal
/// writes to servos with torque on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GoalAudit {
    pub goal_writes: u64,
    pub max_jump_ticks: i32,
}

/// A handle on the emulated servos and their adapter; cloned handles share them.
#[derive(Clone)]
pub struct InProcessBus {
    shared: Arc<Mutex<State>>,
}

struct State {
    bus: BusEmulator,
    epoch: Instant,
    /// Reply bytes on their way back, each due at a time since `epoch`.
    pending: VecDeque<(Duration, Vec<u8>)>,
    plugged: bool,
    /// Bumped by every unplug: handles opened before it fail from then on, as a closed tty does.
    session: u64,
    /// The next `count` replies arrive `by` later than the wire would deliver them.
    late: Option<(usize, Duration)>,
    /// The next position reply of servo `id` reads these ticks instead of the truth.
    glitch: Option<(u8, i32)>,
    /// The adapter is pulled out while the packet after this many more is being written.
    unplug_after: Option<usize>,
    /// The next `count` unicast requests to servo `id` are lost on the wire (it never hears them).
    lost_requests: Option<(u8, usize)>,
    audit: GoalAudit,
}

fn lock(shared: &Mutex<State>) -> MutexGuard<'_, State> {
    shared.lock().unwrap_or_else(PoisonError::into_inner)
}

impl InProcessBus {
    pub fn new(bus: BusEmulator) -> Self {
        Self {
            shared: Arc::new(Mutex::new(State {
                bus,
                epoch: Instant::now(),
                pending: VecDeque::new(),
                plugged: true,
                session: 0,
                late: None,
                glitch: None,
                unplug_after: None,
                lost_requests: None,
                audit: GoalAudit::default(),
            })),
        }
    }

    /// Opens the adapter, as opening the serial port does; fails while it is unplugged.
    pub fn open(&self) -> io::Result<InProcessTransport> {
        let state = lock(&self.shared);
        if !state.plugged {
            return Err(io::Error::new(
                io::ErrorKind::NotFound,
                "the emulated adapter is unplugged",
            ));
        }
        Ok(InProcessTransport {
            shared: Arc::clone(&self.shared),
            session: state.session,
            reader: PacketReader::new(),
        })
    }

    /// The servos, with their physics brought up to now (faults, snapshots, swapping an arm).
    pub fn with_bus<R>(&self, apply: impl FnOnce(&mut BusEmulator) -> R) -> R {
        let mut state = lock(&self.shared);
        let now = state.epoch.elapsed();
        state.bus.advance_to(now);
        apply(&mut state.bus)
    }

    /// The adapter disappears: open handles fail, replies in flight are lost.
    pub fn unplug_adapter(&self) {
        let mut state = lock(&self.shared);
        state.plugged = false;
        state.session += 1;
        state.pending.clear();
    }

    pub fn plug_adapter(&self) {
        lock(&self.shared).plugged = true;
    }

    /// The next `count` replies arrive `by` later than due.
    pub fn hold_back_replies(&self, count: usize, by: Duration) {
        lock(&self.shared).late = Some((count, by));
    }

    /// The next Present_Position reply of servo `id` reads `ticks`, once.
    pub fn glitch_next_position(&self, id: u8, ticks: i32) {
        lock(&self.shared).glitch = Some((id, ticks));
    }

    /// The next `count` requests addressed to servo `id` alone never reach it (line noise); a
    /// broadcast still does.
    pub fn lose_requests_to(&self, id: u8, count: usize) {
        lock(&self.shared).lost_requests = Some((id, count));
    }

    /// The adapter is pulled out in the middle of the packet after the next `packets` ones: that
    /// packet never arrives and its write fails.
    pub fn unplug_during_write(&self, packets: usize) {
        lock(&self.shared).unplug_after = Some(packets);
    }

    pub fn goal_audit(&self) -> GoalAudit {
        lock(&self.shared).audit
    }
}

impl Connector for InProcessBus {
    type Transport = InProcessTransport;

    fn open(&mut self) -> io::Result<InProcessTransport> {
        InProcessBus::open(self)
    }

    fn describe(&self) -> String {
        "in-process emulator".to_owned()
    }
}

/// One open handle on the emulated adapter.
pub struct InProcessTransport {
    shared: Arc<Mutex<State>>,
    session: u64,
    reader: PacketReader,
}

fn unplugged() -> io::Error {
    io::Error::new(
        io::ErrorKind::BrokenPipe,
        "the emulated adapter was unplugged",
    )
}

impl State {
    fn check(&self, session: u64) -> io::Result<()> {
        if self.plugged && self.session == session {
            Ok(())
        } else {
            Err(unplugged())
        }
    }

    /// One instruction packet arrives at the servos.
    fn receive(&mut self, packet: &[u8]) {
        if let (Some((lost_id, count)), Ok((id, _))) =
            (self.lost_requests.as_mut(), decode_instruction(packet))
        {
            if id == *lost_id && *count > 0 {
                *count -= 1;
                return;
            }
        }
        let now = self.epoch.elapsed();
        self.bus.advance_to(now);
        self.audit_goals(packet);
        let mut response = self.bus.handle(now, packet);
        if response.bytes.is_empty() {
            return;
        }
        if let Some((id, ticks)) = self.glitch {
            if let Some(bytes) = misread_position(packet, &response.bytes, id, ticks) {
                response.bytes = bytes;
                self.glitch = None;
            }
        }
        if let Some((count, by)) = self.late.as_mut() {
            response.due += *by;
            *count -= 1;
            if *count == 0 {
                self.late = None;
            }
        }
        self.pending.push_back((response.due, response.bytes));
    }

    fn audit_goals(&mut self, packet: &[u8]) {
        let goal = reg::GOAL_POSITION;
        let entries: Vec<(u8, Vec<u8>)> = match decode_instruction(packet) {
            Ok((
                _,
                Instruction::SyncWrite {
                    address, entries, ..
                },
            )) if address == goal.address => entries,
            Ok((id, Instruction::Write { address, data })) if address == goal.address => {
                vec![(id, data)]
            }
            _ => return,
        };
        for (id, data) in entries {
            let Ok(value) = goal.decode(data.get(..2).unwrap_or_default()) else {
                continue;
            };
            for index in self.bus.slots_with_id(id) {
                let servo = &self.bus.slots[index].servo;
                if servo.register(reg::TORQUE_ENABLE) == 0 {
                    continue;
                }
                let jump = (value - servo.register(reg::PRESENT_POSITION)).abs();
                self.audit.goal_writes += 1;
                self.audit.max_jump_ticks = self.audit.max_jump_ticks.max(jump);
            }
        }
    }
}

/// The reply bytes with servo `id`'s Present_Position replaced by `ticks`, if `request` read it.
fn misread_position(request: &[u8], reply: &[u8], id: u8, ticks: i32) -> Option<Vec<u8>> {
    let address = match decode_instruction(request).ok()?.1 {
        Instruction::SyncRead { address, .. } | Instruction::Read { address, .. } => address,
        _ => return None,
    };
    if address != reg::PRESENT_POSITION.address {
        return None;
    }
    let mut reader = PacketReader::new();
    reader.push(reply);
    let mut bytes = Vec::with_capacity(reply.len());
    let mut changed = false;
    while let Some(status) = reader.next_status() {
        let mut status: StatusPacket = status.ok()?;
        if status.id == id && status.parameters.len() >= 2 {
            let value = reg::PRESENT_POSITION.encode(ticks).ok()?;
            status.parameters[..2].copy_from_slice(&value);
            changed = true;
        }
        bytes.extend(encode_status(&status).ok()?);
    }
    changed.then_some(bytes)
}

impl Transport for InProcessTransport {
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        let mut state = lock(&self.shared);
        state.check(self.session)?;
        match state.unplug_after {
            Some(0) => {
                state.unplug_after = None;
                state.plugged = false;
                state.session += 1;
                state.pending.clear();
                return Err(unplugged());
            }
            Some(count) => state.unplug_after = Some(count - 1),
            None => {}
        }
        self.reader.push(bytes);
        while let Some(frame) = self.reader.next_frame() {
            if let Ok(packet) = frame {
                state.receive(&packet);
            }
        }
        Ok(())
    }

    fn read_until(&mut self, buffer: &mut [u8], deadline: Instant) -> io::Result<usize> {
        loop {
            let wake = {
                let mut state = lock(&self.shared);
                state.check(self.session)?;
                let now = state.epoch.elapsed();
                // Bytes arrive in the order they are due, whatever order they were sent in.
                let next = (0..state.pending.len()).min_by_key(|index| state.pending[*index].0);
                match next {
                    Some(index) if state.pending[index].0 <= now => {
                        let bytes = &mut state.pending[index].1;
                        let count = bytes.len().min(buffer.len());
                        buffer[..count].copy_from_slice(&bytes[..count]);
                        bytes.drain(..count);
                        if bytes.is_empty() {
                            state.pending.remove(index);
                        }
                        return Ok(count);
                    }
                    Some(index) => (state.epoch + state.pending[index].0).min(deadline),
                    None => deadline,
                }
            };
            let now = Instant::now();
            if now >= deadline {
                return Ok(0);
            }
            std::thread::sleep(wake.saturating_duration_since(now));
        }
    }

    fn emergency_writer(&self) -> Option<Box<dyn Write + Send>> {
        Some(Box::new(InProcessTransport {
            shared: Arc::clone(&self.shared),
            session: self.session,
            reader: PacketReader::new(),
        }))
    }
}

impl Write for InProcessTransport {
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        Transport::write_all(self, bytes)?;
        Ok(bytes.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use so101_feetech_driver::bus::{BusConfig, ServoBus};

    use crate::Timing;

    fn servos() -> InProcessBus {
        InProcessBus::new(BusEmulator::with_factory_servos(
            &[1, 2, 3, 4, 5, 6],
            Timing::Instant,
            1,
        ))
    }

    fn bus_on(servos: &InProcessBus) -> ServoBus<InProcessTransport> {
        ServoBus::new(
            servos.open().unwrap(),
            BusConfig {
                slack: Duration::from_millis(5),
                ..BusConfig::default()
            },
        )
    }

    #[test]
    fn a_late_reply_to_a_retried_read_is_never_the_answer_to_the_next_one() {
        let servos = servos();
        servos.with_bus(|bus| {
            bus.slots[0]
                .servo
                .set_register(reg::HOMING_OFFSET, 123)
                .unwrap()
        });
        let mut bus = bus_on(&servos);
        // The first answer comes 30 ms late: after the timeout, before the next request's answer.
        servos.hold_back_replies(1, Duration::from_millis(30));
        assert_eq!(bus.read(1, reg::MODEL_NUMBER).unwrap(), 777);
        std::thread::sleep(Duration::from_millis(40));
        assert_eq!(bus.read(1, reg::HOMING_OFFSET).unwrap(), 123);
        assert_eq!(bus.read(1, reg::MODEL_NUMBER).unwrap(), 777);
        assert_eq!(bus.stats().stale_replies, 1);
        assert_eq!(bus.stats().retries, 1);
    }

    #[test]
    fn a_late_position_is_discarded_in_the_next_sync_read() {
        let servos = servos();
        let mut bus = bus_on(&servos);
        let ids = [1, 2, 3];
        servos.hold_back_replies(1, Duration::from_millis(30));
        // All three answers of the first attempt are late; the retry gets fresh ones.
        let first = bus.sync_read_register(reg::PRESENT_POSITION, &ids).unwrap();
        servos.with_bus(|bus| bus.slots[1].servo.set_actual(1000.0));
        std::thread::sleep(Duration::from_millis(40));
        let second = bus.sync_read_register(reg::PRESENT_POSITION, &ids).unwrap();
        assert_eq!(first, [2048, 2048, 2048]);
        assert_eq!(
            second,
            [2048, 1000, 2048],
            "not the late answer of the first"
        );
        assert_eq!(bus.stats().stale_replies, 3);
    }

    #[test]
    fn a_late_write_acknowledgement_is_never_taken_for_the_next_write() {
        let servos = servos();
        let mut bus = bus_on(&servos);
        servos.hold_back_replies(1, Duration::from_millis(30));
        bus.write(2, reg::ACCELERATION, 10).unwrap();
        // The first attempt's acknowledgement is still on its way. Servo 2 falls silent: the next
        // write must not pass on that acknowledgement.
        servos.with_bus(|bus| bus.slots[1].silent = true);
        std::thread::sleep(Duration::from_millis(40));
        assert!(bus.write(2, reg::ACCELERATION, 20).is_err());
        servos.with_bus(|bus| bus.slots[1].silent = false);
        bus.write(2, reg::ACCELERATION, 30).unwrap();
        let written = servos.with_bus(|bus| bus.slots[1].servo.register(reg::ACCELERATION));
        assert_eq!(written, 30);
    }

    #[test]
    fn an_unplugged_adapter_fails_open_handles_and_new_opens() {
        let servos = servos();
        let mut bus = bus_on(&servos);
        servos.unplug_adapter();
        assert!(bus.ping(1).unwrap_err().is_disconnected());
        assert!(servos.open().is_err());
        servos.plug_adapter();
        assert!(bus_on(&servos).ping(1).is_ok());
    }

    #[test]
    fn goals_are_audited_against_the_servos_position() {
        let servos = servos();
        let mut bus = bus_on(&servos);
        bus.write(1, reg::TORQUE_ENABLE, 1).unwrap();
        bus.sync_write(reg::GOAL_POSITION, &[(1, 2100), (2, 3000)])
            .unwrap();
        let audit = servos.goal_audit();
        assert_eq!(audit.goal_writes, 1, "servo 2 has torque off");
        assert_eq!(audit.max_jump_ticks, 52);
    }

    #[test]
    fn a_glitch_misreads_one_position_once() {
        let servos = servos();
        let mut bus = bus_on(&servos);
        servos.glitch_next_position(2, 3000);
        let ids = [1, 2];
        assert_eq!(
            bus.sync_read_register(reg::PRESENT_POSITION, &ids).unwrap(),
            [2048, 3000]
        );
        assert_eq!(
            bus.sync_read_register(reg::PRESENT_POSITION, &ids).unwrap(),
            [2048, 2048]
        );
    }
}
