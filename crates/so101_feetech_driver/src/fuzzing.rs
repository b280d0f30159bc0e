//! The bodies of the cargo-fuzz targets (fuzz/) over this crate's parsers of outside input, shared
//! with the corpus replay test (tests/fuzz_corpus.rs) so the two cannot drift. Each takes the raw
//! fuzzer input, never panics on any input, and asserts what the parser promises.

use std::path::Path;

use crate::{
    calibration::{ArmCalibration, MAX_TICKS},
    protocol::{checksum, decode_status, encode_status, PacketReader, MAX_PACKET_LEN},
};

/// The input as a serial port delivers it: the first byte sets how many bytes each read returns
/// (1..=64), the rest is the stream, so packets arrive split at every possible place.
pub fn as_reads(data: &[u8]) -> impl Iterator<Item = &[u8]> {
    let (read_size, stream) = match data.split_first() {
        Some((first, rest)) => (usize::from(*first % 64) + 1, rest),
        None => (1, data),
    };
    stream.chunks(read_size)
}

/// Checks a frame `PacketReader` yielded: header, length, checksum and bus limit hold.
pub fn assert_well_framed(frame: &[u8]) {
    assert!(
        frame.len() >= 6 && frame.len() <= MAX_PACKET_LEN,
        "{frame:?}"
    );
    assert_eq!(&frame[..2], &[0xFF, 0xFF]);
    assert_ne!(frame[2], 0xFF, "an id of FF is part of a header");
    assert_eq!(usize::from(frame[3]) + 4, frame.len());
    assert_eq!(checksum(&frame[2..frame.len() - 1]), frame[frame.len() - 1]);
}

/// The driver's side: status packets from the servos, read as the bus reads them.
pub fn status_stream(data: &[u8]) {
    let mut reader = PacketReader::new();
    let mut statuses = 0usize;
    for read in as_reads(data) {
        reader.push(read);
        while let Some(frame) = reader.next_frame() {
            let Ok(frame) = frame else { continue };
            assert_well_framed(&frame);
            let status = decode_status(&frame).expect("a well-framed packet decodes as a status");
            // What the servo sent is what the driver would send back as that status.
            if let Ok(encoded) = encode_status(&status) {
                assert_eq!(encoded, frame);
            }
            statuses += 1;
        }
        // Whatever is left is at most one incomplete packet: memory is bounded by the bus limit.
        assert!(reader.buffered() < MAX_PACKET_LEN, "{}", reader.buffered());
    }
    // The same stream in one read gives the same packets (`next_status` is the driver's call).
    let mut whole = PacketReader::new();
    whole.push(data.get(1..).unwrap_or_default());
    let mut again = 0usize;
    while let Some(status) = whole.next_status() {
        again += usize::from(status.is_ok());
    }
    assert_eq!(again, statuses);
}

/// A LeRobot calibration file's text: an accepted one holds only values the servos can take, and
/// writing it out and reading it back gives the same calibration; conversions never panic.
pub fn calibration_json(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = Path::new("fuzz.json");
    let Ok(calibration) = ArmCalibration::from_json(text, path) else {
        return;
    };
    let again = ArmCalibration::from_json(&calibration.to_json(), path)
        .expect("a calibration's own JSON is accepted");
    assert_eq!(again, calibration);
    for (joint, motor) in calibration.motors.iter().enumerate() {
        for ticks in [motor.range_min, motor.range_max, 0, MAX_TICKS] {
            let radians = calibration.radians_from_ticks(joint, ticks);
            assert!(radians.is_finite());
            // A position read back converts to the goal that holds it (clamped into the range).
            assert_eq!(
                calibration.ticks_from_radians(joint, radians),
                motor.clamp_ticks(ticks)
            );
            assert!(calibration.radians_per_second(joint, ticks).is_finite());
        }
    }
    assert!(calibration
        .limits_in_radians()
        .iter()
        .all(|(low, high)| low.is_finite() && high.is_finite() && low <= high));
}
