//! Transactions on the servo bus: one request, the answers it asks for, bounded retries.
//!
//! The bus is half duplex and nothing on it is reliable: a reply may be late, missing, corrupted or
//! preceded by noise. Every transaction therefore starts by dropping stale bytes, waits for its
//! answers only as long as the wire needs plus a slack for the adapter, and is retried a bounded
//! number of times. Servo error bits are conditions to report, not failed transactions.
//!
//! Protocol 0 has no sequence numbers, so a late reply looks like any other. Replies are matched to
//! their request by id and data length; after a servo missed an answer, its late reply is "owed",
//! and the next read from it asks for a different length (one byte more, dropped afterwards), so
//! the owed reply can never be taken as the answer to that read (when every length within reach is
//! owed, the owed replies are waited out first). A write acknowledgement has no data to vary: a
//! write to a servo that owes one is confirmed by reading the register back.

mod owed;
mod transport;

use std::{
    collections::BTreeSet,
    io,
    time::{Duration, Instant},
};

use owed::OwedReplies;
pub use transport::{usb_latency_timer_ms, Connector, SerialConnector, SerialTransport, Transport};

use crate::protocol::{
    encode_instruction,
    registers::{Register, RegisterError},
    timing::{response_timeout, status_len},
    Instruction, PacketReader, ProtocolError, ServoErrors, BROADCAST_ID,
};

/// Reads of stale bytes before a transaction, at most (each up to the buffer size).
const MAX_STALE_READS: usize = 8;

/// How the bus is driven.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BusConfig {
    pub baud: u32,
    /// Extra attempts after a transaction got no (valid) answer.
    pub retries: u32,
    /// Allowance for the USB adapter and the OS on top of the wire time.
    pub slack: Duration,
    /// How long each servo waits before it answers (Return_Delay_Time; factory 500 us).
    pub return_delay: Duration,
}

impl Default for BusConfig {
    fn default() -> Self {
        Self {
            baud: 1_000_000,
            retries: 2,
            slack: Duration::from_millis(10),
            return_delay: Duration::from_micros(500),
        }
    }
}

/// Counters of everything that went wrong (and right) on the bus.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct BusStats {
    /// Requests put on the wire, retries included.
    pub transactions: u64,
    /// Attempts that ended without every expected answer.
    pub timeouts: u64,
    /// Repeated attempts.
    pub retries: u64,
    /// Transactions that failed after every retry.
    pub failures: u64,
    /// Packets dropped because their checksum did not match.
    pub checksum_errors: u64,
    /// Bytes dropped because they were not part of a packet (noise, late answers).
    pub garbage_bytes: u64,
    /// Late answers to earlier requests, recognised and discarded.
    pub stale_replies: u64,
}

#[derive(Debug, thiserror::Error)]
pub enum BusError {
    #[error("the serial port failed: {0} (adapter unplugged?)")]
    Disconnected(#[source] io::Error),
    #[error("no valid answer from servo(s) {missing:?} to {what} within {timeout:?} ({attempts} attempt(s))")]
    NoAnswer {
        what: &'static str,
        missing: Vec<u8>,
        attempts: u32,
        timeout: Duration,
    },
    #[error("servo {id} did not take {register} = {wrote} (reads {read})")]
    NotConfirmed {
        id: u8,
        register: &'static str,
        wrote: i32,
        read: i32,
    },
    #[error(transparent)]
    Protocol(#[from] ProtocolError),
    #[error(transparent)]
    Register(#[from] RegisterError),
}

impl BusStats {
    /// Counters of two bus sessions together (the driver keeps totals across reconnects).
    pub fn plus(self, other: Self) -> Self {
        Self {
            transactions: self.transactions + other.transactions,
            timeouts: self.timeouts + other.timeouts,
            retries: self.retries + other.retries,
            failures: self.failures + other.failures,
            checksum_errors: self.checksum_errors + other.checksum_errors,
            garbage_bytes: self.garbage_bytes + other.garbage_bytes,
            stale_replies: self.stale_replies + other.stale_replies,
        }
    }
}

impl BusError {
    /// Whether the port itself is gone (reopen it), as opposed to servos not answering.
    pub fn is_disconnected(&self) -> bool {
        matches!(self, Self::Disconnected(_))
    }
}

/// One servo's answer to a read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reply {
    pub id: u8,
    pub errors: ServoErrors,
    pub data: Vec<u8>,
}

/// The servo bus on a transport.
pub struct ServoBus<T: Transport = SerialTransport> {
    transport: T,
    config: BusConfig,
    reader: PacketReader,
    stats: BusStats,
    buffer: Box<[u8; 1024]>,
    /// The error bits each servo reported last.
    servo_errors: [ServoErrors; 256],
    /// Set after a transaction that may have left bytes behind (a timeout: its late answers).
    may_have_stale_bytes: bool,
    /// Answers that servos still owe to requests that timed out.
    owed: OwedReplies,
    /// Servos whose owed answers arrived after all: they are there, only slow (a busy machine's
    /// emulator) or their answer was delayed.
    late_answerers: BTreeSet<u8>,
}

impl<T: Transport> ServoBus<T> {
    pub fn new(transport: T, config: BusConfig) -> Self {
        Self {
            transport,
            config,
            reader: PacketReader::new(),
            stats: BusStats::default(),
            buffer: Box::new([0; 1024]),
            servo_errors: [ServoErrors::default(); 256],
            may_have_stale_bytes: true,
            owed: OwedReplies::default(),
            late_answerers: BTreeSet::new(),
        }
    }

    /// Replaces the timing and retry settings (a scan probes briefly, then identifies patiently).
    pub fn set_config(&mut self, config: BusConfig) {
        self.config = config;
    }

    /// The servos whose answers came after their request had timed out, since the last call;
    /// first waits up to `wait` for answers still owed.
    pub fn take_late_answerers(&mut self, wait: Duration) -> Result<BTreeSet<u8>, BusError> {
        self.settle_owed_until(Instant::now() + wait, OwedReplies::is_empty)?;
        Ok(std::mem::take(&mut self.late_answerers))
    }

    pub fn config(&self) -> &BusConfig {
        &self.config
    }

    pub fn transport(&self) -> &T {
        &self.transport
    }

    pub fn transport_mut(&mut self) -> &mut T {
        &mut self.transport
    }

    /// Once the servos were told to answer at once (Return_Delay_Time = 0), waits get shorter.
    pub fn set_return_delay(&mut self, delay: Duration) {
        self.config.return_delay = delay;
    }

    pub fn stats(&self) -> BusStats {
        BusStats {
            checksum_errors: self.reader.checksum_errors,
            garbage_bytes: self.reader.garbage_bytes,
            ..self.stats
        }
    }

    /// The error bits servo `id` reported in its latest answer.
    pub fn servo_errors(&self, id: u8) -> ServoErrors {
        self.servo_errors[usize::from(id)]
    }

    pub fn ping(&mut self, id: u8) -> Result<ServoErrors, BusError> {
        let replies = self.transact("PING", id, &Instruction::Ping, &[id], 0)?;
        Ok(replies
            .first()
            .map(|reply| reply.errors)
            .unwrap_or_default())
    }

    pub fn read_bytes(&mut self, id: u8, address: u8, length: u8) -> Result<Vec<u8>, BusError> {
        let asked = self.read_length(address, length, &[id])?;
        let instruction = Instruction::Read {
            address,
            length: asked,
        };
        let mut replies = self.transact("READ", id, &instruction, &[id], usize::from(asked))?;
        let mut data = replies.pop().map(|reply| reply.data).unwrap_or_default();
        data.truncate(usize::from(length));
        Ok(data)
    }

    pub fn read(&mut self, id: u8, register: Register) -> Result<i32, BusError> {
        let bytes = self.read_bytes(id, register.address, register.size)?;
        Ok(register.decode(&bytes)?)
    }

    /// Writes one register and waits for the servo's acknowledgement (Response_Status_Level 1).
    /// While the servo owes a late acknowledgement, which could not be told from this one, the
    /// write is confirmed by reading the register back instead.
    pub fn write(&mut self, id: u8, register: Register, value: i32) -> Result<(), BusError> {
        let instruction = Instruction::Write {
            address: register.address,
            data: register.encode(value)?,
        };
        if !self.owed.any_of(&[id], 0, Instant::now()) {
            self.transact("WRITE", id, &instruction, &[id], 0)?;
            return Ok(());
        }
        // Whatever acknowledgement comes (the owed one or this write's) is waited for, so the
        // read below does not talk over it on the half-duplex line; it proves nothing by itself.
        // (One answer in, one more sent out: what is owed stays as it was.)
        match self.transact("WRITE", id, &instruction, &[id], 0) {
            Ok(_) | Err(BusError::NoAnswer { .. }) => {}
            Err(error) => return Err(error),
        }
        let read = self.read(id, register)?;
        if read != value {
            return Err(BusError::NotConfirmed {
                id,
                register: register.name,
                wrote: value,
                read,
            });
        }
        Ok(())
    }

    /// Writes one register without waiting for an answer: for changes after which the servo
    /// answers differently (a new id, a new baud rate). Verify with a read or ping afterwards.
    pub fn write_unacknowledged(
        &mut self,
        id: u8,
        register: Register,
        value: i32,
    ) -> Result<(), BusError> {
        let instruction = Instruction::Write {
            address: register.address,
            data: register.encode(value)?,
        };
        self.transact("WRITE", id, &instruction, &[], 0)?;
        // Let a reply in flight arrive and be dropped before the next transaction.
        std::thread::sleep(self.config.slack);
        Ok(())
    }

    /// Writes one register on every servo at once (broadcast id; nobody answers). The last resort
    /// when the servos do not answer one by one, e.g. torque off on the way out.
    pub fn broadcast_write(&mut self, register: Register, value: i32) -> Result<(), BusError> {
        let instruction = Instruction::Write {
            address: register.address,
            data: register.encode(value)?,
        };
        self.transact("WRITE", BROADCAST_ID, &instruction, &[], 0)?;
        Ok(())
    }

    /// One SYNC_READ; answers in `ids` order.
    pub fn sync_read(
        &mut self,
        address: u8,
        length: u8,
        ids: &[u8],
    ) -> Result<Vec<Reply>, BusError> {
        let asked = self.read_length(address, length, ids)?;
        let instruction = Instruction::SyncRead {
            address,
            length: asked,
            ids: ids.to_vec(),
        };
        let mut replies = self.transact(
            "SYNC_READ",
            BROADCAST_ID,
            &instruction,
            ids,
            usize::from(asked),
        )?;
        for reply in &mut replies {
            reply.data.truncate(usize::from(length));
        }
        Ok(replies)
    }

    /// One SYNC_READ of a register, decoded, in `ids` order.
    pub fn sync_read_register(
        &mut self,
        register: Register,
        ids: &[u8],
    ) -> Result<Vec<i32>, BusError> {
        self.sync_read(register.address, register.size, ids)?
            .iter()
            .map(|reply| Ok(register.decode(&reply.data)?))
            .collect()
    }

    /// One SYNC_WRITE of a register to several servos (no answers).
    pub fn sync_write(&mut self, register: Register, values: &[(u8, i32)]) -> Result<(), BusError> {
        let entries = values
            .iter()
            .map(|(id, value)| Ok((*id, register.encode(*value)?)))
            .collect::<Result<Vec<_>, RegisterError>>()?;
        let instruction = Instruction::SyncWrite {
            address: register.address,
            length: register.size,
            entries,
        };
        self.transact("SYNC_WRITE", BROADCAST_ID, &instruction, &[], 0)?;
        Ok(())
    }

    /// Sends `instruction` to `target` and collects one answer of `reply_len` data bytes from each
    /// of `expect` (in that order), retrying up to the configured number of times.
    fn transact(
        &mut self,
        what: &'static str,
        target: u8,
        instruction: &Instruction,
        expect: &[u8],
        reply_len: usize,
    ) -> Result<Vec<Reply>, BusError> {
        let request = encode_instruction(target, instruction)?;
        let reply_lens = vec![status_len(reply_len); expect.len()];
        let timeout = response_timeout(
            self.config.baud,
            request.len(),
            &reply_lens,
            self.config.return_delay,
            self.config.slack,
        );
        let mut attempts = 0;
        loop {
            attempts += 1;
            self.stats.transactions += 1;
            // Draining the port costs a syscall, so only after a timeout (whose answers may still
            // arrive); anything else left over is dropped from the reader.
            if std::mem::take(&mut self.may_have_stale_bytes) {
                self.drop_stale_bytes()?;
            } else {
                self.reader.clear();
            }
            self.transport
                .write_all(&request)
                .map_err(BusError::Disconnected)?;
            if expect.is_empty() {
                return Ok(Vec::new());
            }
            let missing =
                match self.collect(&request, expect, reply_len, Instant::now() + timeout)? {
                    Ok(replies) => return Ok(replies),
                    Err(missing) => missing,
                };
            self.stats.timeouts += 1;
            self.may_have_stale_bytes = true;
            self.owed.add(&missing, reply_len, Instant::now());
            if attempts > self.config.retries {
                self.stats.failures += 1;
                return Err(BusError::NoAnswer {
                    what,
                    missing,
                    attempts,
                    timeout,
                });
            }
            self.stats.retries += 1;
        }
    }

    /// Reads until every servo in `expect` answered or `deadline` passed. The inner `Err` lists
    /// the servos that did not answer.
    fn collect(
        &mut self,
        request: &[u8],
        expect: &[u8],
        reply_len: usize,
        deadline: Instant,
    ) -> Result<Result<Vec<Reply>, Vec<u8>>, BusError> {
        let mut answers: Vec<Option<Reply>> = vec![None; expect.len()];
        loop {
            while let Some(frame) = self.reader.next_frame() {
                // A corrupted frame is counted by the reader; its servo stays missing.
                let Ok(packet) = frame else { continue };
                // Adapters without direction control echo the request back.
                if packet == request {
                    continue;
                }
                let Ok(status) = crate::protocol::decode_status(&packet) else {
                    continue;
                };
                let len = status.parameters.len();
                if len != reply_len && self.owed.settle(status.id, len) {
                    self.stats.stale_replies += 1;
                    self.late_answerers.insert(status.id);
                    continue;
                }
                let slot = expect.iter().position(|id| *id == status.id);
                match slot {
                    Some(slot) if len == reply_len && answers[slot].is_none() => {
                        self.servo_errors[usize::from(status.id)] = status.errors;
                        answers[slot] = Some(Reply {
                            id: status.id,
                            errors: status.errors,
                            data: status.parameters,
                        });
                    }
                    // The late answer of another servo, as long as the one asked for.
                    _ if self.owed.settle(status.id, len) => {
                        self.stats.stale_replies += 1;
                        self.late_answerers.insert(status.id);
                    }
                    _ => self.reader.garbage_bytes += packet.len() as u64,
                }
            }
            if answers.iter().all(Option::is_some) {
                return Ok(Ok(answers.into_iter().flatten().collect()));
            }
            if Instant::now() >= deadline {
                let missing = expect
                    .iter()
                    .zip(&answers)
                    .filter(|(_, answer)| answer.is_none())
                    .map(|(id, _)| *id)
                    .collect();
                return Ok(Err(missing));
            }
            let count = self
                .transport
                .read_until(&mut self.buffer[..], deadline)
                .map_err(BusError::Disconnected)?;
            self.reader.push(&self.buffer[..count]);
        }
    }

    /// Drops whatever arrived since the last transaction (the tail of a late answer, noise). Bounded:
    /// a line that chatters without end (a floating RX, a device at another baud) must not hold
    /// the cycle; what is left is dropped by the reader as garbage.
    fn drop_stale_bytes(&mut self) -> Result<(), BusError> {
        for _ in 0..MAX_STALE_READS {
            let count = self
                .transport
                .read_until(&mut self.buffer[..], Instant::now())
                .map_err(BusError::Disconnected)?;
            if count == 0 {
                break;
            }
            self.reader.push(&self.buffer[..count]);
        }
        self.settle_buffered_replies();
        self.reader.clear();
        Ok(())
    }

    /// The length a read should ask for (see `OwedReplies::distinct_length`); when none is free,
    /// the owed replies are waited out for a slack's time and then taken as lost.
    fn read_length(&mut self, address: u8, length: u8, ids: &[u8]) -> Result<u8, BusError> {
        if let Some(asked) = self.owed.distinct_length(address, length, ids) {
            return Ok(asked);
        }
        self.reader.clear();
        self.settle_owed_until(Instant::now() + self.config.slack, |_| false)?;
        self.owed.forget(ids);
        Ok(length)
    }

    /// Reads and settles owed replies until `deadline`, or sooner once `settled` holds.
    fn settle_owed_until(
        &mut self,
        deadline: Instant,
        settled: impl Fn(&OwedReplies) -> bool,
    ) -> Result<(), BusError> {
        while !settled(&self.owed) {
            let count = self
                .transport
                .read_until(&mut self.buffer[..], deadline)
                .map_err(BusError::Disconnected)?;
            self.reader.push(&self.buffer[..count]);
            self.settle_buffered_replies();
            if count == 0 && Instant::now() >= deadline {
                break;
            }
        }
        Ok(())
    }

    /// Counts the owed replies among the buffered packets (the rest is left for the caller).
    fn settle_buffered_replies(&mut self) {
        while let Some(frame) = self.reader.next_frame() {
            let Ok(packet) = frame else { continue };
            if let Ok(status) = crate::protocol::decode_status(&packet) {
                if self.owed.settle(status.id, status.parameters.len()) {
                    self.stats.stale_replies += 1;
                    self.late_answerers.insert(status.id);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::VecDeque;

    use super::*;
    use crate::protocol::{encode_status, registers, StatusPacket};

    /// A scripted transport: each write is answered with the next canned reply (or nothing).
    struct Scripted {
        answers: VecDeque<Vec<u8>>,
        pending: Vec<u8>,
        written: Vec<Vec<u8>>,
    }

    impl Transport for Scripted {
        fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
            self.written.push(bytes.to_vec());
            if let Some(answer) = self.answers.pop_front() {
                self.pending.extend(answer);
            }
            Ok(())
        }

        fn read_until(&mut self, buffer: &mut [u8], _deadline: Instant) -> io::Result<usize> {
            let count = self.pending.len().min(buffer.len());
            buffer[..count].copy_from_slice(&self.pending[..count]);
            self.pending.drain(..count);
            Ok(count)
        }
    }

    fn status(id: u8, errors: u8, data: &[u8]) -> Vec<u8> {
        encode_status(&StatusPacket {
            id,
            errors: ServoErrors(errors),
            parameters: data.to_vec(),
        })
        .unwrap()
    }

    fn bus(answers: Vec<Vec<u8>>) -> ServoBus<Scripted> {
        ServoBus::new(
            Scripted {
                answers: answers.into(),
                pending: Vec::new(),
                written: Vec::new(),
            },
            BusConfig {
                slack: Duration::from_millis(1),
                ..BusConfig::default()
            },
        )
    }

    #[test]
    fn sync_read_returns_answers_in_request_order_and_keeps_error_bits() {
        let mut answer = status(2, 0x20, &[0x10, 0x00]);
        answer.extend(status(1, 0, &[0x00, 0x08]));
        let mut bus = bus(vec![answer]);
        let values = bus
            .sync_read_register(registers::PRESENT_POSITION, &[1, 2])
            .unwrap();
        assert_eq!(values, [2048, 16]);
        assert_eq!(bus.servo_errors(2).names(), ["overload"]);
    }

    #[test]
    fn a_missing_answer_is_retried_then_reported_with_the_missing_ids() {
        let mut bus = bus(vec![status(1, 0, &[0, 8]), Vec::new(), Vec::new()]);
        let error = bus
            .sync_read_register(registers::PRESENT_POSITION, &[1, 2])
            .unwrap_err();
        assert!(
            matches!(&error, BusError::NoAnswer { missing, attempts: 3, .. } if missing == &[1, 2]),
            "{error}"
        );
        let stats = bus.stats();
        assert_eq!(
            (stats.transactions, stats.retries, stats.failures),
            (3, 2, 1)
        );
    }

    #[test]
    fn noise_and_an_echo_before_the_answer_are_skipped() {
        let request = encode_instruction(
            3,
            &Instruction::Read {
                address: 3,
                length: 2,
            },
        )
        .unwrap();
        let mut answer = vec![0x00, 0xFF, 0x13];
        answer.extend(&request);
        answer.extend(status(3, 0, &777u16.to_le_bytes()));
        let mut bus = bus(vec![answer]);
        assert_eq!(bus.read(3, registers::MODEL_NUMBER).unwrap(), 777);
        assert_eq!(bus.stats().garbage_bytes, 3);
    }

    #[test]
    fn a_corrupted_answer_counts_and_the_retry_succeeds() {
        let mut bad = status(1, 0, &[0, 8]);
        bad[5] ^= 0x40;
        let mut bus = bus(vec![bad, status(1, 0, &[0, 8])]);
        assert_eq!(bus.read(1, registers::PRESENT_POSITION).unwrap(), 2048);
        let stats = bus.stats();
        assert_eq!((stats.checksum_errors, stats.retries), (1, 1));
    }

    #[test]
    fn sync_write_encodes_every_goal_and_waits_for_nothing() {
        let mut bus = bus(vec![]);
        bus.sync_write(registers::GOAL_POSITION, &[(1, 100), (2, -5)])
            .unwrap();
        let written = &bus.transport().written[0];
        // FF FF FE LEN 83 ADDR SIZE, (ID LO HI) x 2, CHK
        assert_eq!(written.len(), 7 + 2 * 3 + 1);
        assert!(bus
            .sync_write(registers::GOAL_POSITION, &[(1, 40_000)])
            .is_err());
    }
}
