//! Reading an episode bag's MCAP file (episode_bag's layout, recorder_node's output) as a stream
//! of messages: each message's topic and CDR payload, in file order. A bag is outside input (a
//! recording cut short, a file from elsewhere), so memory stays bounded by what the file holds
//! and by `record_length_limit`, whatever lengths its records claim.

use std::{collections::HashMap, io::Read};

use byteorder::{BigEndian, LittleEndian};
use mcap::{
    records::{op, Record},
    sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions},
};
use serde::de::DeserializeOwned;

/// The longest record (a chunk, compressed or not, or a message) a bag reader accepts: the
/// recorder's largest chunk (`--chunk-size` is at most 1 GiB) with a message over it.
pub const RECORD_LENGTH_LIMIT: usize = 2 << 30;
/// At most this much is read from the file at once, so a record that claims more bytes than the
/// file holds costs only what the file holds.
const READ_SIZE: usize = 64 << 10;

#[derive(Debug, thiserror::Error)]
pub enum ReadError<E> {
    #[error(transparent)]
    Read(std::io::Error),
    /// What the message handler returned.
    #[error(transparent)]
    Handler(E),
}

/// Hands every message of the MCAP stream `input` to `on_message` with its channel's topic ("" for
/// a channel the file never declared). Returns why the file ended early, if it did: a recording
/// cut short leaves a truncated file, and the messages before the damage were handed over.
pub fn read_messages<E>(
    mut input: impl Read,
    record_length_limit: usize,
    mut on_message: impl FnMut(&str, &[u8]) -> Result<(), E>,
) -> Result<Option<String>, ReadError<E>> {
    let options = LinearReaderOptions::default().with_record_length_limit(record_length_limit);
    let mut reader = LinearReader::new_with_options(options);
    // Channel id -> topic, as the file declares them before their messages.
    let mut topics: HashMap<u16, String> = HashMap::new();
    while let Some(event) = reader.next_event() {
        let record = match event {
            Ok(LinearReadEvent::ReadRequest(wanted)) => {
                let buffer = reader.insert(wanted.min(READ_SIZE));
                let read = input.read(buffer).map_err(ReadError::Read)?;
                reader.notify_read(read);
                continue;
            }
            // Only channels and messages are parsed: mcap's parser reserves what a string's length
            // prefix claims before reading it (a 30-byte header record claiming a 1.3 GB profile
            // string), so the records whose strings this reader needs are parsed here, checked.
            Ok(LinearReadEvent::Record { data, opcode }) => match opcode {
                op::CHANNEL => match channel(data) {
                    Some((id, topic)) => {
                        topics.insert(id, topic);
                        continue;
                    }
                    None => return Ok(Some("a channel record is malformed".to_owned())),
                },
                op::MESSAGE => mcap::parse_record(opcode, data),
                _ => continue,
            },
            Err(error) => Err(error),
        };
        match record {
            Ok(Record::Message { header, data }) => {
                let topic = topics.get(&header.channel_id).map_or("", String::as_str);
                on_message(topic, &data).map_err(ReadError::Handler)?;
            }
            Ok(_) => {}
            Err(error) => return Ok(Some(error.to_string())),
        }
    }
    Ok(None)
}

/// A channel record's id and topic (MCAP: id u16, schema id u16, topic as a u32 length and UTF-8
/// bytes, then fields this reader does not need); None where a length runs past the record.
fn channel(record: &[u8]) -> Option<(u16, String)> {
    let id = u16::from_le_bytes(record.get(..2)?.try_into().ok()?);
    let length = u32::from_le_bytes(record.get(4..8)?.try_into().ok()?);
    let topic = record.get(8..8usize.checked_add(usize::try_from(length).ok()?)?)?;
    Some((id, String::from_utf8(topic.to_vec()).ok()?))
}

/// A CDR payload (4-byte encapsulation header, then the data) as `T`, or None where it is not one.
pub fn decode_cdr<T: DeserializeOwned>(data: &[u8]) -> Option<T> {
    let (header, payload) = (data.get(..4)?, data.get(4..)?);
    let decoded = match header[1] {
        0x01 => cdr_encoding::from_bytes::<T, LittleEndian>(payload),
        0x00 => cdr_encoding::from_bytes::<T, BigEndian>(payload),
        _ => return None,
    };
    decoded.ok().map(|(value, _)| value)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// MCAP's magic, then a record header: opcode and a little-endian length.
    fn file_with_record(opcode: u8, length: u64) -> Vec<u8> {
        let mut file = b"\x89MCAP0\r\n".to_vec();
        file.push(opcode);
        file.extend(length.to_le_bytes());
        file
    }

    /// Counts the reads and remembers the largest buffer it was asked to fill.
    struct Recorder<'a> {
        file: &'a [u8],
        largest_read: usize,
    }

    impl Read for Recorder<'_> {
        fn read(&mut self, buffer: &mut [u8]) -> std::io::Result<usize> {
            self.largest_read = self.largest_read.max(buffer.len());
            let count = buffer.len().min(self.file.len());
            buffer[..count].copy_from_slice(&self.file[..count]);
            self.file = &self.file[count..];
            Ok(count)
        }
    }

    fn no_messages(_: &str, _: &[u8]) -> Result<(), ()> {
        panic!("the file holds no message");
    }

    #[test]
    fn a_record_longer_than_the_limit_ends_the_file_instead_of_allocating_it() {
        // A header (opcode 1) claiming 2^62 bytes: once a capacity-overflow panic or an abort.
        let file = file_with_record(0x01, 1 << 62);
        let ended = read_messages(file.as_slice(), RECORD_LENGTH_LIMIT, no_messages);
        assert!(ended.expect("reads from memory").is_some());
    }

    #[test]
    fn a_record_claiming_more_than_the_file_holds_is_read_in_pieces() {
        // 1 GiB claimed (within the limit) by a file of 17 bytes: once a 1 GiB buffer.
        let file = file_with_record(0x01, 1 << 30);
        let mut input = Recorder {
            file: &file,
            largest_read: 0,
        };
        let ended = read_messages(&mut input, RECORD_LENGTH_LIMIT, no_messages);
        assert!(ended.expect("reads from memory").is_some(), "truncated");
        assert!(input.largest_read <= READ_SIZE, "{}", input.largest_read);
    }

    #[test]
    fn a_string_claiming_more_than_its_record_holds_is_not_allocated() {
        // Found by the episode_bag_mcap fuzz target (minimized): a header record (opcode 1) of 22
        // bytes whose profile string claims 0x4D8A_0E04 bytes; mcap's parser reserved them.
        let mut file = file_with_record(0x01, 22);
        file.extend([0x04, 0x0E, 0x8A, 0x4D]);
        file.extend([0; 18]);
        // A channel whose topic claims 4 GB, then a message on it.
        file.push(0x04);
        file.extend(14u64.to_le_bytes());
        file.extend([1, 0, 0, 0, 0xFF, 0xFF, 0xFF, 0xFF, b'/', b'a', 0, 0, 0, 0]);
        let ended = read_messages(file.as_slice(), RECORD_LENGTH_LIMIT, no_messages);
        assert_eq!(
            ended.expect("reads from memory").as_deref(),
            Some("a channel record is malformed")
        );
    }

    #[test]
    fn channels_and_messages_are_read_from_a_file_the_mcap_writer_wrote() {
        let mut file = std::io::Cursor::new(Vec::new());
        let mut writer = mcap::Writer::new(&mut file).expect("a writer");
        let channel = writer
            .add_channel(0, "/task/reward", "cdr", &Default::default())
            .expect("a channel");
        for sequence in 0..3 {
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence,
                log_time: u64::from(sequence),
                publish_time: u64::from(sequence),
            };
            writer
                .write_to_known_channel(&header, &[sequence as u8; 12])
                .expect("a message");
        }
        writer.finish().expect("finished");
        drop(writer);
        let mut seen = Vec::new();
        let ended = read_messages(
            file.get_ref().as_slice(),
            RECORD_LENGTH_LIMIT,
            |topic, data| {
                seen.push((topic.to_owned(), data[0]));
                Ok::<(), ()>(())
            },
        );
        assert_eq!(ended.expect("reads from memory"), None);
        let topic = "/task/reward".to_owned();
        assert_eq!(seen, [(topic.clone(), 0), (topic.clone(), 1), (topic, 2)]);
    }

    #[test]
    fn a_cdr_payload_decodes_into_its_type() {
        #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
        struct Reading {
            name: String,
            value: f64,
        }
        let reading = Reading {
            name: "gripper".into(),
            value: 0.5,
        };
        let mut bytes = vec![0x00, 0x01, 0x00, 0x00];
        bytes.extend(cdr_encoding::to_vec::<_, LittleEndian>(&reading).expect("encodes"));
        assert_eq!(decode_cdr::<Reading>(&bytes), Some(reading));
        assert_eq!(decode_cdr::<Reading>(&bytes[..6]), None);
        assert_eq!(decode_cdr::<Reading>(&[0x00, 0x07, 0x00, 0x00]), None);
    }
}
