//! Property tests of the wire protocol: encode/decode round trips, and no input byte sequence can
//! make the decoders panic.

use proptest::prelude::*;
use so101_feetech_driver::protocol::{
    decode_instruction, decode_status, encode_instruction, encode_status, registers, Instruction,
    PacketReader, ServoErrors, StatusPacket, BROADCAST_ID, MAX_ID,
};

fn unicast_id() -> impl Strategy<Value = u8> {
    0..=MAX_ID
}

fn instruction() -> impl Strategy<Value = Instruction> {
    prop_oneof![
        Just(Instruction::Ping),
        Just(Instruction::Action),
        (any::<u8>(), any::<u8>())
            .prop_map(|(address, length)| Instruction::Read { address, length }),
        (any::<u8>(), prop::collection::vec(any::<u8>(), 1..64))
            .prop_map(|(address, data)| Instruction::Write { address, data }),
        (any::<u8>(), prop::collection::vec(any::<u8>(), 1..64))
            .prop_map(|(address, data)| Instruction::RegWrite { address, data }),
    ]
}

fn sync_instruction() -> impl Strategy<Value = Instruction> {
    prop_oneof![
        (
            any::<u8>(),
            1..8u8,
            prop::collection::vec(unicast_id(), 1..20)
        )
            .prop_map(|(address, length, ids)| Instruction::SyncRead {
                address,
                length,
                ids
            }),
        (any::<u8>(), 1..6u8, 1..12usize).prop_flat_map(|(address, length, count)| {
            prop::collection::vec(
                (
                    unicast_id(),
                    prop::collection::vec(any::<u8>(), usize::from(length)),
                ),
                count,
            )
            .prop_map(move |entries| Instruction::SyncWrite {
                address,
                length,
                entries,
            })
        }),
    ]
}

proptest! {
    #[test]
    fn unicast_instructions_round_trip(id in unicast_id(), instruction in instruction()) {
        let packet = encode_instruction(id, &instruction).unwrap();
        prop_assert_eq!(decode_instruction(&packet).unwrap(), (id, instruction));
    }

    #[test]
    fn sync_instructions_round_trip(instruction in sync_instruction()) {
        let packet = encode_instruction(BROADCAST_ID, &instruction).unwrap();
        prop_assert_eq!(decode_instruction(&packet).unwrap(), (BROADCAST_ID, instruction));
    }

    #[test]
    fn status_packets_round_trip_through_the_stream_reader(
        id in unicast_id(), errors in any::<u8>(), parameters in prop::collection::vec(any::<u8>(), 0..64),
        noise in prop::collection::vec(any::<u8>(), 0..32),
    ) {
        let status = StatusPacket { id, errors: ServoErrors(errors), parameters };
        let packet = encode_status(&status).unwrap();
        prop_assert_eq!(decode_status(&packet).unwrap(), status.clone());
        // Noise first, then the packet twice, then idle-line bytes: the packet always comes through
        // intact. (Noise can look like a header announcing a longer packet than the bytes behind
        // it; the reader then waits for that length, as on the wire, where the bus times out
        // and drains. The trailing bytes complete such a fake packet so its checksum fails.)
        let mut reader = PacketReader::new();
        reader.push(&noise);
        reader.push(&packet);
        reader.push(&packet);
        reader.push(&[0u8; 300]);
        let mut received = Vec::new();
        while let Some(result) = reader.next_status() {
            if let Ok(packet) = result {
                received.push(packet);
            }
        }
        prop_assert!(received.last() == Some(&status), "{:?}", received);
    }

    #[test]
    fn decoders_never_panic_on_arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        let _ = decode_instruction(&bytes);
        let _ = decode_status(&bytes);
        let mut reader = PacketReader::new();
        for chunk in bytes.chunks(7) {
            reader.push(chunk);
            while reader.next_status().is_some() {}
        }
        prop_assert!(reader.buffered() <= bytes.len());
    }

    #[test]
    fn registers_round_trip_every_value_they_can_hold(index in 0..registers::ALL.len(), value in any::<i32>()) {
        let register = registers::ALL[index];
        if let Ok(bytes) = register.encode(value) {
            prop_assert_eq!(bytes.len(), usize::from(register.size));
            prop_assert_eq!(register.decode(&bytes).unwrap(), value);
        }
    }
}

/// Found by the property above: noise that reads as a header announcing 13 bytes, before a 6-byte
/// status packet sent twice.
#[test]
fn a_fake_header_longer_than_the_bytes_behind_it_delays_but_never_hides_a_packet() {
    let status = StatusPacket {
        id: 0,
        errors: ServoErrors(0),
        parameters: vec![],
    };
    let packet = encode_status(&status).unwrap();
    let mut reader = PacketReader::new();
    reader.push(&[0xFF, 0xFF, 0, 13]);
    reader.push(&packet);
    reader.push(&packet);
    let mut received = Vec::new();
    while let Some(result) = reader.next_status() {
        received.extend(result.ok());
    }
    assert!(
        received.is_empty(),
        "{received:?}: the reader cannot know the header is fake yet"
    );
    reader.push(&[0u8; 16]);
    while let Some(result) = reader.next_status() {
        received.extend(result.ok());
    }
    assert_eq!(received.last(), Some(&status));
}
