//! The body of the cargo-fuzz target (fuzz/) over the emulator's side of the bus: instruction
//! packets from the driver, shared with the corpus replay test (tests/fuzz_corpus.rs) so the two
//! cannot drift. It never panics on any input and checks what the emulator promises.

use std::time::Duration;

use so101_feetech_driver::{
    fuzzing::{as_reads, assert_well_framed},
    protocol::{decode_instruction, decode_status, encode_instruction, PacketReader},
};

use crate::bus::{BusEmulator, Timing};

/// A byte stream from the driver, read as the pty serving thread reads it, each packet executed
/// by a bus of six factory servos: replies are whole, valid status packets, due no earlier than
/// their request.
pub fn instruction_stream(data: &[u8]) {
    let ids = [1, 2, 3, 4, 5, 6];
    let mut bus = BusEmulator::with_factory_servos(&ids, Timing::Realistic { baud: 1_000_000 }, 0);
    let mut reader = PacketReader::new();
    let mut now = Duration::ZERO;
    for read in as_reads(data) {
        reader.push(read);
        while let Some(frame) = reader.next_frame() {
            let Ok(packet) = frame else { continue };
            assert_well_framed(&packet);
            if let Ok((id, instruction)) = decode_instruction(&packet) {
                // Encoding what was decoded gives a packet that decodes to the same request.
                if let Ok(encoded) = encode_instruction(id, &instruction) {
                    assert_eq!(decode_instruction(&encoded), Ok((id, instruction)));
                }
            }
            now += Duration::from_millis(1);
            let response = bus.handle(now, &packet);
            assert!(response.bytes.is_empty() || response.due >= now);
            let mut replies = PacketReader::new();
            replies.push(&response.bytes);
            while let Some(reply) = replies.next_frame() {
                let reply = reply.expect("replies pass their checksum");
                decode_status(&reply).expect("replies are status packets");
            }
            assert_eq!(replies.buffered(), 0, "a reply is cut short");
            assert_eq!(replies.garbage_bytes, 0, "bytes between replies");
        }
        assert!(reader.buffered() < so101_feetech_driver::protocol::MAX_PACKET_LEN);
    }
}
