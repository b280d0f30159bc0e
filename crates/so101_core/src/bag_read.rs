//! Reading an episode bag's MCAP file (episode_bag's layout, recorder_node's output) as a stream
//! of messages: each message's topic and CDR payload, in file order. A bag is outside input (a
//! recording cut short, a file from elsewhere), so memory stays bounded by what the file holds
//! and by `record_length_limit`, whatever lengths its records claim.

use std::{borrow::Cow, collections::HashMap, io::Read};

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
    on_message: impl FnMut(&str, &[u8]) -> Result<(), E>,
) -> Result<Option<String>, ReadError<E>> {
    // Chunks come whole and are opened here: mcap's own walk through an uncompressed chunk
    // subtracts a record's claimed length from what the chunk holds without a check (a record
    // running past its chunk overflows), so each record's length is checked against its chunk.
    let options = LinearReaderOptions::default()
        .with_record_length_limit(record_length_limit)
        .with_emit_chunks(true);
    let mut reader = LinearReader::new_with_options(options);
    let mut records = Records {
        topics: HashMap::new(),
        on_message,
        record_length_limit,
    };
    while let Some(event) = reader.next_event() {
        let ended = match event {
            Ok(LinearReadEvent::ReadRequest(wanted)) => {
                let buffer = reader.insert(wanted.min(READ_SIZE));
                let read = input.read(buffer).map_err(ReadError::Read)?;
                reader.notify_read(read);
                continue;
            }
            Ok(LinearReadEvent::Record { data, opcode }) => records.record(opcode, data)?,
            Err(error) => Some(error.to_string()),
        };
        if ended.is_some() {
            return Ok(ended);
        }
    }
    Ok(None)
}

/// What the records read so far declared, and where messages go.
struct Records<F> {
    /// Channel id -> topic, as the file declares them before their messages.
    topics: HashMap<u16, String>,
    on_message: F,
    record_length_limit: usize,
}

impl<F> Records<F> {
    /// Takes one record (a chunk's records in turn); Some(why) where the file can be read no
    /// further.
    fn record<E>(&mut self, opcode: u8, data: &[u8]) -> Result<Option<String>, ReadError<E>>
    where
        F: FnMut(&str, &[u8]) -> Result<(), E>,
    {
        // Only channels and messages are parsed: mcap's parser reserves what a string's length
        // prefix claims before reading it (a 30-byte header record claiming a 1.3 GB profile
        // string), so the records whose strings this reader needs are parsed here, checked.
        match opcode {
            op::CHANNEL => match channel(data) {
                Some((id, topic)) => {
                    self.topics.insert(id, topic);
                }
                None => return Ok(Some("a channel record is malformed".to_owned())),
            },
            op::MESSAGE => match mcap::parse_record(opcode, data) {
                Ok(Record::Message { header, data }) => {
                    let topic = self
                        .topics
                        .get(&header.channel_id)
                        .map_or("", String::as_str);
                    (self.on_message)(topic, &data).map_err(ReadError::Handler)?;
                }
                Ok(_) => {}
                Err(error) => return Ok(Some(error.to_string())),
            },
            op::CHUNK => {
                let records = match chunk_records(data, self.record_length_limit) {
                    Ok(records) => records,
                    Err(why) => return Ok(Some(why)),
                };
                let mut rest = &records[..];
                while !rest.is_empty() {
                    let Some((opcode, data, after)) = next_record(rest) else {
                        return Ok(Some("a record runs past the end of its chunk".to_owned()));
                    };
                    if opcode == op::CHUNK {
                        return Ok(Some("a chunk holds a chunk".to_owned()));
                    }
                    if let Some(why) = self.record(opcode, data)? {
                        return Ok(Some(why));
                    }
                    rest = after;
                }
            }
            _ => {}
        }
        Ok(None)
    }
}

/// The first record of `records` (opcode, its data, what follows it), or None where its length
/// runs past the end.
fn next_record(records: &[u8]) -> Option<(u8, &[u8], &[u8])> {
    let (&opcode, rest) = records.split_first()?;
    let (length, rest) = rest.split_first_chunk::<8>()?;
    let length = usize::try_from(u64::from_le_bytes(*length)).ok()?;
    (length <= rest.len()).then(|| (opcode, &rest[..length], &rest[length..]))
}

/// A chunk record's records, decompressed and checked against the chunk's CRC (MCAP: start and end
/// time u64, uncompressed size u64, uncompressed CRC u32 (0: none), compression as a u32-prefixed
/// string, records length u64, records). Memory stays within what the chunk claims and the limit.
/// An uncompressed chunk's records are borrowed from it, not copied.
fn chunk_records(chunk: &[u8], limit: usize) -> Result<Cow<'_, [u8]>, String> {
    let malformed = || "a chunk record is malformed".to_owned();
    let uncompressed_size = u64::from_le_bytes(field(chunk, 16).ok_or_else(malformed)?);
    let crc = u32::from_le_bytes(field(chunk, 24).ok_or_else(malformed)?);
    let compression_length = u32::from_le_bytes(field(chunk, 28).ok_or_else(malformed)?);
    let compression_end = usize::try_from(compression_length)
        .ok()
        .and_then(|length| length.checked_add(32))
        .ok_or_else(malformed)?;
    let compression = chunk.get(32..compression_end).ok_or_else(malformed)?;
    let records_length = u64::from_le_bytes(field(chunk, compression_end).ok_or_else(malformed)?);
    let compressed = usize::try_from(records_length)
        .ok()
        .and_then(|length| chunk.get(compression_end + 8..)?.get(..length))
        .ok_or_else(malformed)?;
    let size = usize::try_from(uncompressed_size)
        .ok()
        .filter(|&size| size <= limit)
        .ok_or_else(|| {
            format!("a chunk claims {uncompressed_size} bytes, over the limit of {limit}")
        })?;
    let records = match compression {
        b"" => Cow::Borrowed(compressed),
        b"zstd" => Cow::Owned(decompress(
            zstd::stream::read::Decoder::with_buffer(compressed),
            size,
        )?),
        b"lz4" => Cow::Owned(decompress(lz4::Decoder::new(compressed), size)?),
        other => {
            let other = String::from_utf8_lossy(other);
            return Err(format!(
                "a chunk compressed as {other:?}, which this reader does not know"
            ));
        }
    };
    if records.len() != size {
        let held = records.len();
        return Err(format!(
            "a chunk holds {held} bytes of records, not the {size} it claims"
        ));
    }
    if crc != 0 && crc32fast::hash(&records) != crc {
        return Err("a chunk's records do not match its CRC".to_owned());
    }
    Ok(records)
}

/// The `N` little-endian bytes at `at`, where the record holds them.
fn field<const N: usize>(record: &[u8], at: usize) -> Option<[u8; N]> {
    record.get(at..)?.first_chunk().copied()
}

/// At most `size` bytes (and one more, to tell a chunk that holds more) from a decompressor; the
/// buffer grows with what it really yields, not with what the chunk claims.
fn decompress(decoder: Result<impl Read, std::io::Error>, size: usize) -> Result<Vec<u8>, String> {
    let mut records = Vec::new();
    decoder
        .and_then(|decoder| decoder.take(size as u64 + 1).read_to_end(&mut records))
        .map_err(|error| format!("a chunk does not decompress: {error}"))?;
    Ok(records)
}

/// A channel record's id and topic (MCAP: id u16, schema id u16, topic as a u32 length and UTF-8
/// bytes, then fields this reader does not need); None where a length runs past the record.
fn channel(record: &[u8]) -> Option<(u16, String)> {
    let id = u16::from_le_bytes(field(record, 0)?);
    let length = u32::from_le_bytes(field(record, 4)?);
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

    /// An uncompressed chunk record (CRC 0: unchecked) around `records`.
    fn chunk(records: &[u8]) -> Vec<u8> {
        let mut chunk = [0u8; 16].to_vec();
        chunk.extend((records.len() as u64).to_le_bytes());
        chunk.extend(0u32.to_le_bytes());
        chunk.extend(0u32.to_le_bytes());
        chunk.extend((records.len() as u64).to_le_bytes());
        chunk.extend(records);
        chunk
    }

    #[test]
    fn a_record_running_past_its_chunk_ends_the_file() {
        // Found by the episode_bag_mcap fuzz target: in an uncompressed chunk, a record claiming
        // more than the chunk holds; mcap subtracted its length from the chunk's (an overflow,
        // a panic in debug builds) and read on past the chunk as if it were inside it.
        let mut records = vec![op::CHANNEL];
        records.extend(40u64.to_le_bytes());
        records.extend([1, 0, 0, 0, 2, 0, 0, 0, b'/', b'a']);
        let chunk = chunk(&records);
        let mut file = file_with_record(op::CHUNK, chunk.len() as u64);
        file.extend(chunk);
        file.extend([0; 64]);
        let ended = read_messages(file.as_slice(), RECORD_LENGTH_LIMIT, no_messages);
        assert_eq!(
            ended.expect("reads from memory").as_deref(),
            Some("a record runs past the end of its chunk")
        );
    }

    #[test]
    fn a_chunk_claiming_more_than_the_limit_is_refused_unopened() {
        let mut chunk = chunk(&[]);
        chunk[16..24].copy_from_slice(&(1u64 << 40).to_le_bytes());
        let mut file = file_with_record(op::CHUNK, chunk.len() as u64);
        file.extend(chunk);
        let ended = read_messages(file.as_slice(), 1 << 20, no_messages);
        let ended = ended.expect("reads from memory").expect("ended early");
        assert!(ended.contains("over the limit"), "{ended}");
    }

    /// A bag of three messages on /task/reward, as mcap's writer writes it with `compression`.
    fn written_with(compression: Option<mcap::Compression>) -> Vec<u8> {
        let mut file = std::io::Cursor::new(Vec::new());
        let options = mcap::WriteOptions::new().compression(compression);
        let mut writer = options.create(&mut file).expect("a writer");
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
        file.into_inner()
    }

    #[test]
    fn channels_and_messages_are_read_from_every_compression_the_mcap_writer_writes() {
        use mcap::Compression::{Lz4, Zstd};
        for compression in [None, Some(Zstd), Some(Lz4)] {
            let file = written_with(compression);
            let mut seen = Vec::new();
            let ended = read_messages(file.as_slice(), RECORD_LENGTH_LIMIT, |topic, data| {
                seen.push((topic.to_owned(), data[0]));
                Ok::<(), ()>(())
            });
            assert_eq!(ended.expect("reads from memory"), None, "{compression:?}");
            let topic = "/task/reward".to_owned();
            let expected = [(topic.clone(), 0), (topic.clone(), 1), (topic, 2)];
            assert_eq!(seen, expected, "{compression:?}");
        }
    }

    #[test]
    fn a_chunk_whose_records_do_not_match_its_crc_ends_the_file() {
        let mut file = written_with(None);
        // The last byte of the third message's payload, inside the one chunk.
        let at = file
            .windows(12)
            .position(|w| w == [2; 12])
            .expect("the payload")
            + 11;
        file[at] ^= 0xFF;
        let mut seen = 0;
        let ended = read_messages(file.as_slice(), RECORD_LENGTH_LIMIT, |_, _| {
            seen += 1;
            Ok::<(), ()>(())
        });
        let ended = ended.expect("reads from memory");
        assert_eq!(
            ended.as_deref(),
            Some("a chunk's records do not match its CRC")
        );
        assert_eq!(seen, 0, "no message of a damaged chunk is handed over");
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
