//! Encoding and decoding of whole packets.
//!
//! Instruction: `FF FF ID LEN INST P1..Pn CHK`; status: `FF FF ID LEN ERR P1..Pn CHK`; LEN = n + 2
//! and CHK = !(ID + LEN + INST/ERR + sum(P)) (low byte).

/// Address that every servo obeys and none answers.
pub const BROADCAST_ID: u8 = 0xFE;
/// Highest id a servo can have.
pub const MAX_ID: u8 = 0xFC;
/// Longest packet the servos accept, header and checksum included.
pub const MAX_PACKET_LEN: usize = 250;

const PING: u8 = 0x01;
const READ: u8 = 0x02;
const WRITE: u8 = 0x03;
const REG_WRITE: u8 = 0x04;
const ACTION: u8 = 0x05;
const SYNC_READ: u8 = 0x82;
const SYNC_WRITE: u8 = 0x83;

/// Header, id, length and checksum: the bytes of a packet that are not instruction or parameters.
const FRAMING_LEN: usize = 5;

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProtocolError {
    #[error("servo id {0} is out of range (1..={MAX_ID}, or {BROADCAST_ID} for broadcast)")]
    BadId(u8),
    #[error("packet of {0} bytes exceeds the bus limit of {MAX_PACKET_LEN}")]
    TooLong(usize),
    #[error("{instruction} needs at least one servo")]
    NoServos { instruction: &'static str },
    #[error("sync write entry for servo {id} has {got} bytes, expected {expected}")]
    EntryLength { id: u8, got: usize, expected: usize },
    #[error("{instruction} must be sent to the broadcast id")]
    NotBroadcast { instruction: &'static str },
    #[error("read or write of {0} bytes: length must be 1..=255")]
    BadLength(usize),
    #[error("packet is malformed: {0}")]
    Malformed(&'static str),
    #[error("unknown instruction 0x{0:02X}")]
    UnknownInstruction(u8),
}

/// A request to the servos.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Instruction {
    Ping,
    Read {
        address: u8,
        length: u8,
    },
    Write {
        address: u8,
        data: Vec<u8>,
    },
    /// Like Write, but takes effect only at the next [`Instruction::Action`].
    RegWrite {
        address: u8,
        data: Vec<u8>,
    },
    Action,
    /// Each listed servo answers with one status packet, in the order given.
    SyncRead {
        address: u8,
        length: u8,
        ids: Vec<u8>,
    },
    /// Writes `length` bytes at `address` of each servo; nobody answers.
    SyncWrite {
        address: u8,
        length: u8,
        entries: Vec<(u8, Vec<u8>)>,
    },
}

impl Instruction {
    fn code(&self) -> u8 {
        match self {
            Self::Ping => PING,
            Self::Read { .. } => READ,
            Self::Write { .. } => WRITE,
            Self::RegWrite { .. } => REG_WRITE,
            Self::Action => ACTION,
            Self::SyncRead { .. } => SYNC_READ,
            Self::SyncWrite { .. } => SYNC_WRITE,
        }
    }

    fn parameters(&self) -> Result<Vec<u8>, ProtocolError> {
        Ok(match self {
            Self::Ping | Self::Action => Vec::new(),
            Self::Read { address, length } => vec![*address, *length],
            Self::Write { address, data } | Self::RegWrite { address, data } => {
                if data.is_empty() {
                    return Err(ProtocolError::BadLength(0));
                }
                std::iter::once(*address)
                    .chain(data.iter().copied())
                    .collect()
            }
            Self::SyncRead {
                address,
                length,
                ids,
            } => {
                if ids.is_empty() {
                    return Err(ProtocolError::NoServos {
                        instruction: "SYNC_READ",
                    });
                }
                for id in ids {
                    check_unicast_id(*id)?;
                }
                [*address, *length]
                    .into_iter()
                    .chain(ids.iter().copied())
                    .collect()
            }
            Self::SyncWrite {
                address,
                length,
                entries,
            } => {
                if entries.is_empty() {
                    return Err(ProtocolError::NoServos {
                        instruction: "SYNC_WRITE",
                    });
                }
                let mut parameters = vec![*address, *length];
                for (id, data) in entries {
                    check_unicast_id(*id)?;
                    if data.len() != usize::from(*length) {
                        return Err(ProtocolError::EntryLength {
                            id: *id,
                            got: data.len(),
                            expected: usize::from(*length),
                        });
                    }
                    parameters.push(*id);
                    parameters.extend_from_slice(data);
                }
                parameters
            }
        })
    }
}

/// Error bits a servo reports in its status packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ServoErrors(pub u8);

impl ServoErrors {
    pub const VOLTAGE: u8 = 0x01;
    pub const ANGLE_SENSOR: u8 = 0x02;
    pub const OVERHEAT: u8 = 0x04;
    pub const OVERCURRENT: u8 = 0x08;
    pub const OVERLOAD: u8 = 0x20;

    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// Names of the bits that are set (unknown bits as hex).
    pub fn names(self) -> Vec<String> {
        let known = [
            (Self::VOLTAGE, "voltage"),
            (Self::ANGLE_SENSOR, "angle sensor"),
            (Self::OVERHEAT, "overheat"),
            (Self::OVERCURRENT, "overcurrent"),
            (Self::OVERLOAD, "overload"),
        ];
        let mut names: Vec<String> = known
            .iter()
            .filter(|(bit, _)| self.0 & bit != 0)
            .map(|(_, name)| (*name).to_owned())
            .collect();
        let unknown = self.0 & !known.iter().fold(0, |all, (bit, _)| all | bit);
        if unknown != 0 {
            names.push(format!("0x{unknown:02X}"));
        }
        names
    }
}

/// A servo's answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StatusPacket {
    pub id: u8,
    pub errors: ServoErrors,
    pub parameters: Vec<u8>,
}

fn check_unicast_id(id: u8) -> Result<(), ProtocolError> {
    if id > MAX_ID {
        return Err(ProtocolError::BadId(id));
    }
    Ok(())
}

/// The checksum over id, length, instruction/error and parameters.
pub fn checksum(body: &[u8]) -> u8 {
    !body.iter().fold(0u8, |sum, byte| sum.wrapping_add(*byte))
}

fn frame(id: u8, code: u8, parameters: &[u8]) -> Result<Vec<u8>, ProtocolError> {
    let total = FRAMING_LEN + 1 + parameters.len();
    if total > MAX_PACKET_LEN {
        return Err(ProtocolError::TooLong(total));
    }
    let mut packet = Vec::with_capacity(total);
    packet.extend_from_slice(&[0xFF, 0xFF, id, (parameters.len() + 2) as u8, code]);
    packet.extend_from_slice(parameters);
    packet.push(checksum(&packet[2..]));
    Ok(packet)
}

/// The bytes of an instruction packet to `id`.
pub fn encode_instruction(id: u8, instruction: &Instruction) -> Result<Vec<u8>, ProtocolError> {
    let broadcast_only = matches!(
        instruction,
        Instruction::SyncRead { .. } | Instruction::SyncWrite { .. }
    );
    if broadcast_only && id != BROADCAST_ID {
        return Err(ProtocolError::NotBroadcast {
            instruction: if matches!(instruction, Instruction::SyncRead { .. }) {
                "SYNC_READ"
            } else {
                "SYNC_WRITE"
            },
        });
    }
    if id != BROADCAST_ID {
        check_unicast_id(id)?;
    }
    frame(id, instruction.code(), &instruction.parameters()?)
}

/// The bytes of a status packet (what a servo, or the emulator, sends).
pub fn encode_status(status: &StatusPacket) -> Result<Vec<u8>, ProtocolError> {
    check_unicast_id(status.id)?;
    frame(status.id, status.errors.0, &status.parameters)
}

/// Parses one complete instruction packet (the emulator's side). Returns the target id.
pub fn decode_instruction(packet: &[u8]) -> Result<(u8, Instruction), ProtocolError> {
    let (id, code, parameters) = split_frame(packet)?;
    let need = |count: usize| {
        if parameters.len() < count {
            Err(ProtocolError::Malformed("too few parameters"))
        } else {
            Ok(())
        }
    };
    let instruction = match code {
        PING => Instruction::Ping,
        ACTION => Instruction::Action,
        READ => {
            need(2)?;
            Instruction::Read {
                address: parameters[0],
                length: parameters[1],
            }
        }
        WRITE | REG_WRITE => {
            need(2)?;
            let (address, data) = (parameters[0], parameters[1..].to_vec());
            if code == WRITE {
                Instruction::Write { address, data }
            } else {
                Instruction::RegWrite { address, data }
            }
        }
        SYNC_READ => {
            need(3)?;
            Instruction::SyncRead {
                address: parameters[0],
                length: parameters[1],
                ids: parameters[2..].to_vec(),
            }
        }
        SYNC_WRITE => {
            need(2)?;
            let (address, length) = (parameters[0], parameters[1]);
            let stride = usize::from(length) + 1;
            let body = &parameters[2..];
            if length == 0 || body.is_empty() || body.len() % stride != 0 {
                return Err(ProtocolError::Malformed(
                    "sync write entries do not divide evenly",
                ));
            }
            let entries = body
                .chunks(stride)
                .map(|entry| (entry[0], entry[1..].to_vec()))
                .collect();
            Instruction::SyncWrite {
                address,
                length,
                entries,
            }
        }
        other => return Err(ProtocolError::UnknownInstruction(other)),
    };
    Ok((id, instruction))
}

/// Parses one complete status packet.
pub fn decode_status(packet: &[u8]) -> Result<StatusPacket, ProtocolError> {
    let (id, errors, parameters) = split_frame(packet)?;
    Ok(StatusPacket {
        id,
        errors: ServoErrors(errors),
        parameters: parameters.to_vec(),
    })
}

/// Checks header, length and checksum; returns id, instruction/error byte and parameters.
fn split_frame(packet: &[u8]) -> Result<(u8, u8, &[u8]), ProtocolError> {
    if packet.len() < FRAMING_LEN + 1 || packet[0] != 0xFF || packet[1] != 0xFF {
        return Err(ProtocolError::Malformed("no header"));
    }
    let length = usize::from(packet[3]);
    if length < 2 || packet.len() != length + 4 {
        return Err(ProtocolError::Malformed(
            "length field does not match the packet",
        ));
    }
    let (body, check) = packet[2..].split_at(packet.len() - 3);
    if checksum(body) != check[0] {
        return Err(ProtocolError::Malformed("checksum mismatch"));
    }
    Ok((packet[2], packet[4], &packet[5..packet.len() - 1]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ping_matches_the_documented_bytes() {
        // FF FF 01 02 01 CHK, CHK = !(1 + 2 + 1) = 0xFB
        assert_eq!(
            encode_instruction(1, &Instruction::Ping).unwrap(),
            [0xFF, 0xFF, 0x01, 0x02, 0x01, 0xFB]
        );
    }

    #[test]
    fn sync_read_of_six_positions_is_fourteen_bytes() {
        let packet = encode_instruction(
            BROADCAST_ID,
            &Instruction::SyncRead {
                address: 56,
                length: 2,
                ids: vec![1, 2, 3, 4, 5, 6],
            },
        )
        .unwrap();
        assert_eq!(packet.len(), 14);
        assert_eq!(&packet[..7], &[0xFF, 0xFF, 0xFE, 10, 0x82, 56, 2]);
    }

    #[test]
    fn sync_write_of_six_goals_is_twenty_six_bytes() {
        let entries = (1..=6).map(|id| (id, vec![0x00, 0x08])).collect();
        let packet = encode_instruction(
            BROADCAST_ID,
            &Instruction::SyncWrite {
                address: 42,
                length: 2,
                entries,
            },
        )
        .unwrap();
        assert_eq!(packet.len(), 26);
    }

    #[test]
    fn invalid_requests_are_refused() {
        assert_eq!(
            encode_instruction(0xFD, &Instruction::Ping),
            Err(ProtocolError::BadId(0xFD))
        );
        assert!(matches!(
            encode_instruction(
                1,
                &Instruction::SyncRead {
                    address: 56,
                    length: 2,
                    ids: vec![1]
                }
            ),
            Err(ProtocolError::NotBroadcast { .. })
        ));
        assert!(matches!(
            encode_instruction(
                BROADCAST_ID,
                &Instruction::SyncRead {
                    address: 56,
                    length: 2,
                    ids: vec![]
                }
            ),
            Err(ProtocolError::NoServos { .. })
        ));
        let entries = vec![(1, vec![0, 0]), (2, vec![0])];
        assert_eq!(
            encode_instruction(
                BROADCAST_ID,
                &Instruction::SyncWrite {
                    address: 42,
                    length: 2,
                    entries
                }
            ),
            Err(ProtocolError::EntryLength {
                id: 2,
                got: 1,
                expected: 2
            })
        );
        let huge = Instruction::Write {
            address: 0,
            data: vec![0; 250],
        };
        assert!(matches!(
            encode_instruction(1, &huge),
            Err(ProtocolError::TooLong(_))
        ));
    }

    #[test]
    fn status_errors_are_named() {
        assert_eq!(ServoErrors(0x24).names(), ["overheat", "overload"]);
        assert_eq!(ServoErrors(0x40).names(), ["0x40"]);
        assert!(ServoErrors(0).is_empty());
    }

    #[test]
    fn corrupted_packets_are_rejected() {
        let mut packet = encode_status(&StatusPacket {
            id: 3,
            errors: ServoErrors(0),
            parameters: vec![1, 2],
        })
        .unwrap();
        assert!(decode_status(&packet).is_ok());
        packet[5] ^= 0x10;
        assert_eq!(
            decode_status(&packet),
            Err(ProtocolError::Malformed("checksum mismatch"))
        );
    }
}
