//! Splitting a byte stream from the bus into packets, resynchronising after garbage: line noise,
//! a half packet from before a reconnect, or a corrupted byte must cost one packet, not the link.

use super::packet::{decode_status, StatusPacket, MAX_PACKET_LEN};

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    #[error("packet from id {id} failed its checksum")]
    Checksum { id: u8 },
}

/// Accumulates received bytes and yields complete, checksum-valid packets.
#[derive(Debug, Default)]
pub struct PacketReader {
    buffer: Vec<u8>,
    /// Bytes dropped because they were not part of any packet.
    pub garbage_bytes: u64,
    /// Packets dropped because their checksum did not match.
    pub checksum_errors: u64,
}

impl PacketReader {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn push(&mut self, bytes: &[u8]) {
        self.buffer.extend_from_slice(bytes);
    }

    /// Forgets everything buffered (after a timeout: the rest of a late answer is garbage).
    pub fn clear(&mut self) {
        self.garbage_bytes += self.buffer.len() as u64;
        self.buffer.clear();
    }

    pub fn buffered(&self) -> usize {
        self.buffer.len()
    }

    /// The next complete packet (header to checksum) in the stream, `None` until one is complete.
    pub fn next_frame(&mut self) -> Option<Result<Vec<u8>, FrameError>> {
        loop {
            self.skip_to_header();
            if self.buffer.len() < 4 {
                return None;
            }
            let length = usize::from(self.buffer[3]);
            if length < 2 || length + 4 > MAX_PACKET_LEN {
                // Not a real header: resume the search one byte further.
                self.drop_front(1);
                continue;
            }
            if self.buffer.len() < length + 4 {
                return None;
            }
            let packet: Vec<u8> = self.buffer[..length + 4].to_vec();
            let body = &packet[2..packet.len() - 1];
            if super::packet::checksum(body) != packet[packet.len() - 1] {
                self.checksum_errors += 1;
                self.drop_front(1);
                return Some(Err(FrameError::Checksum { id: packet[2] }));
            }
            self.buffer.drain(..packet.len());
            return Some(Ok(packet));
        }
    }

    /// The next status packet; frames that are not valid status packets count as errors.
    pub fn next_status(&mut self) -> Option<Result<StatusPacket, FrameError>> {
        self.next_frame().map(|frame| {
            frame.map(|packet| {
                decode_status(&packet).expect("next_frame returns only well-framed packets")
            })
        })
    }

    /// Drops bytes before the first `FF FF` that is followed by an id (not a third `FF`).
    fn skip_to_header(&mut self) {
        let start = self
            .buffer
            .windows(3)
            .position(|window| window[0] == 0xFF && window[1] == 0xFF && window[2] != 0xFF);
        let drop = match start {
            Some(start) => start,
            // Keep a trailing FF (FF FF) that may begin a header whose id has not arrived yet.
            None => {
                self.buffer.len()
                    - self
                        .buffer
                        .iter()
                        .rev()
                        .take(2)
                        .take_while(|byte| **byte == 0xFF)
                        .count()
            }
        };
        self.drop_front(drop);
    }

    fn drop_front(&mut self, count: usize) {
        self.garbage_bytes += count as u64;
        self.buffer.drain(..count);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{encode_status, ServoErrors};

    fn status(id: u8, parameters: &[u8]) -> Vec<u8> {
        encode_status(&StatusPacket {
            id,
            errors: ServoErrors(0),
            parameters: parameters.to_vec(),
        })
        .unwrap()
    }

    #[test]
    fn packets_split_across_reads_are_joined() {
        let packet = status(1, &[0x00, 0x08]);
        let mut reader = PacketReader::new();
        for byte in &packet[..packet.len() - 1] {
            reader.push(&[*byte]);
            assert!(reader.next_status().is_none());
        }
        reader.push(&packet[packet.len() - 1..]);
        assert_eq!(
            reader.next_status().unwrap().unwrap().parameters,
            [0x00, 0x08]
        );
        assert_eq!(reader.buffered(), 0);
    }

    #[test]
    fn garbage_before_and_between_packets_is_skipped() {
        let mut reader = PacketReader::new();
        reader.push(&[0x12, 0xFF, 0x00, 0xFF]);
        reader.push(&status(2, &[7]));
        reader.push(&[0xFF, 0xFF, 0xFF]);
        reader.push(&status(3, &[8]));
        assert_eq!(reader.next_status().unwrap().unwrap().id, 2);
        assert_eq!(reader.next_status().unwrap().unwrap().id, 3);
        assert!(reader.next_status().is_none());
        assert_eq!(reader.garbage_bytes, 4 + 3);
    }

    #[test]
    fn a_corrupted_packet_is_reported_and_the_next_one_still_arrives() {
        let mut bad = status(4, &[1, 2]);
        bad[5] ^= 0x01;
        let mut reader = PacketReader::new();
        reader.push(&bad);
        reader.push(&status(5, &[3]));
        assert_eq!(
            reader.next_status(),
            Some(Err(FrameError::Checksum { id: 4 }))
        );
        assert_eq!(reader.next_status().unwrap().unwrap().id, 5);
        assert_eq!(reader.checksum_errors, 1);
    }
}
