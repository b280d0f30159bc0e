//! Whether a camera buffer holds one whole JPEG: it starts with SOI (FF D8) and ends with EOI
//! (FF D9). A USB camera that loses packets, or a buffer cut short, delivers a frame without its
//! end; such a frame is dropped and counted, never published.

const SOI: [u8; 2] = [0xFF, 0xD8];
const EOI: [u8; 2] = [0xFF, 0xD9];

/// The JPEG in `buffer`: the bytes up to its EOI. Some cameras pad a frame with zeros after EOI
/// (the used length is rounded up); the padding is not part of the image.
pub fn whole_jpeg(buffer: &[u8]) -> Option<&[u8]> {
    if !buffer.starts_with(&SOI) {
        return None;
    }
    let end = buffer.iter().rposition(|&byte| byte != 0)? + 1;
    let jpeg = &buffer[..end];
    (jpeg.len() >= 4 && jpeg.ends_with(&EOI)).then_some(jpeg)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal marker sequence: SOI, an APP0 segment's start, EOI.
    fn frame() -> Vec<u8> {
        vec![0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x10, 0x4A, 0x46, 0xFF, 0xD9]
    }

    #[test]
    fn a_whole_frame_is_kept_as_it_is() {
        let jpeg = frame();
        assert_eq!(whole_jpeg(&jpeg), Some(jpeg.as_slice()));
    }

    #[test]
    fn zero_padding_after_the_end_is_cut() {
        let mut padded = frame();
        padded.extend([0, 0, 0, 0]);
        assert_eq!(whole_jpeg(&padded), Some(frame().as_slice()));
    }

    #[test]
    fn truncated_or_foreign_buffers_are_refused() {
        let jpeg = frame();
        assert_eq!(whole_jpeg(&jpeg[..jpeg.len() - 1]), None);
        assert_eq!(whole_jpeg(&jpeg[..6]), None);
        assert_eq!(whole_jpeg(&jpeg[2..]), None);
        assert_eq!(whole_jpeg(&[]), None);
        assert_eq!(whole_jpeg(&[0xFF, 0xD8, 0, 0]), None);
        assert_eq!(
            whole_jpeg(&[0xFF, 0xD8, 0xFF, 0xD9]),
            Some(&[0xFF, 0xD8, 0xFF, 0xD9][..])
        );
    }
}
