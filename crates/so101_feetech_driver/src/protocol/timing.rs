//! Bus timing: how long bytes take on the wire, and how long to wait for an answer.

use std::time::Duration;

/// Bits per byte on the wire: start, 8 data, stop.
const BITS_PER_BYTE: u64 = 10;

/// Time one byte takes on the wire at `baud`.
pub fn byte_time(baud: u32) -> Duration {
    Duration::from_nanos(BITS_PER_BYTE * 1_000_000_000 / u64::from(baud.max(1)))
}

/// Time `bytes` take on the wire at `baud`.
pub fn wire_time(baud: u32, bytes: usize) -> Duration {
    byte_time(baud) * bytes as u32
}

/// Status packet length for a read of `length` bytes (header, id, len, error, data, checksum).
pub fn status_len(length: usize) -> usize {
    6 + length
}

/// How long to wait for the answers to a request: the request and all replies on the wire, each
/// servo's return delay, and `slack` for the USB adapter and the OS (the wire time alone is far too
/// tight with a USB-serial adapter).
pub fn response_timeout(
    baud: u32,
    request_len: usize,
    reply_lens: &[usize],
    return_delay: Duration,
    slack: Duration,
) -> Duration {
    let bytes = request_len + reply_lens.iter().sum::<usize>();
    wire_time(baud, bytes) + return_delay * reply_lens.len() as u32 + slack
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_megabaud_is_ten_microseconds_a_byte() {
        assert_eq!(byte_time(1_000_000), Duration::from_micros(10));
        assert_eq!(byte_time(115_200), Duration::from_nanos(86_805));
    }

    #[test]
    fn sync_read_and_write_of_six_servos_fit_the_documented_wire_budget() {
        // 14-byte SYNC_READ + 6 replies of 8 bytes = 62 bytes; 26-byte SYNC_WRITE.
        let read = wire_time(1_000_000, 14 + 6 * status_len(2));
        let write = wire_time(1_000_000, 26);
        assert_eq!(read, Duration::from_micros(620));
        assert_eq!(read + write, Duration::from_micros(880));
        let timeout = response_timeout(
            1_000_000,
            14,
            &[8; 6],
            Duration::from_micros(0),
            Duration::from_millis(2),
        );
        assert_eq!(timeout, Duration::from_micros(2620));
    }
}
