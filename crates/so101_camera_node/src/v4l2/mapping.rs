//! What the V4L2 backend turns from the kernel's terms into the node's: offered frame sizes and
//! intervals into modes, a rate into an interval, a buffer's timestamp into a capture instant.
//! Pure: tested without a device.

use std::time::Duration;

use v4l::{
    buffer::Flags,
    format::{Colorspace, Quantization},
    fraction::Fraction,
    frameinterval::{FrameInterval, FrameIntervalEnum},
    framesize::{FrameSize, FrameSizeEnum},
    timestamp::Timestamp,
};

use crate::{decode::YuvRange, modes::DEFAULT_SIZE};

/// The range of a YUYV format's samples: what the driver says, or for "default" what the V4L2
/// specification defines (V4L2_MAP_QUANTIZATION_DEFAULT): full for the JPEG colorspace, limited
/// for every other Y'CbCr one. UVC cameras and vivid say "default" and send limited range.
pub fn yuv_range(quantization: Quantization, colorspace: Colorspace) -> YuvRange {
    match (quantization, colorspace) {
        (Quantization::FullRange, _) | (Quantization::Default, Colorspace::JPEG) => YuvRange::Full,
        _ => YuvRange::Limited,
    }
}

/// The sizes a format offers. A stepwise range (cameras that scale freely) offers its largest
/// size and the default size where the range holds it, rather than every step of it.
pub fn sizes_of(frame_sizes: &[FrameSize]) -> Vec<(u32, u32)> {
    let mut sizes = Vec::new();
    for frame_size in frame_sizes {
        match &frame_size.size {
            FrameSizeEnum::Discrete(size) => sizes.push((size.width, size.height)),
            FrameSizeEnum::Stepwise(range) => {
                let on_step = |value: u32, min: u32, max: u32, step: u32| {
                    (min..=max).contains(&value) && (value - min).is_multiple_of(step.max(1))
                };
                let (width, height) = DEFAULT_SIZE;
                if on_step(width, range.min_width, range.max_width, range.step_width)
                    && on_step(
                        height,
                        range.min_height,
                        range.max_height,
                        range.step_height,
                    )
                {
                    sizes.push(DEFAULT_SIZE);
                }
                sizes.push((range.max_width, range.max_height));
            }
        }
    }
    sizes.dedup();
    sizes
}

/// Frames per second of one frame interval.
pub fn rate_of(interval: Fraction) -> Option<f64> {
    (interval.numerator > 0 && interval.denominator > 0)
        .then(|| f64::from(interval.denominator) / f64::from(interval.numerator))
}

/// The rates a size offers, fastest first. A stepwise interval range offers its fastest rate,
/// its slowest, and 30 and 15 where they lie between.
pub fn rates_of(intervals: &[FrameInterval]) -> Vec<f64> {
    let mut rates = Vec::new();
    for interval in intervals {
        match &interval.interval {
            FrameIntervalEnum::Discrete(fraction) => rates.extend(rate_of(*fraction)),
            FrameIntervalEnum::Stepwise(range) => {
                let (Some(fastest), Some(slowest)) = (rate_of(range.min), rate_of(range.max))
                else {
                    continue;
                };
                rates.push(fastest);
                rates.extend([30.0, 15.0].into_iter().filter(|rate| {
                    (slowest..fastest).contains(rate) && (fastest - rate).abs() > 0.05
                }));
                if (fastest - slowest).abs() > 0.05 {
                    rates.push(slowest);
                }
            }
        }
    }
    rates.sort_by(|a, b| b.total_cmp(a));
    rates.dedup_by(|a, b| (*a - *b).abs() < 0.05);
    rates
}

/// The frame interval to ask for a rate: 30 is 1/30, 29.97 is 1000/29970 (the driver takes the
/// nearest it has).
pub fn interval_of(fps: f64) -> Fraction {
    let rounded = fps.round();
    if (fps - rounded).abs() < 1e-6 && rounded >= 1.0 {
        return Fraction::new(1, rounded as u32);
    }
    Fraction::new(1000, (fps * 1000.0).round().max(1.0) as u32)
}

/// When a buffer's frame was captured, on CLOCK_MONOTONIC. Drivers stamp buffers on the monotonic
/// clock (V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC, UVC at the start of the frame); a buffer stamped
/// otherwise (a copied or unknown clock) gets the instant it was dequeued.
pub fn capture_instant(flags: Flags, timestamp: Timestamp, dequeued: Duration) -> Duration {
    let monotonic = (flags & Flags::TIMESTAMP_MASK) == Flags::TIMESTAMP_MONOTONIC;
    match (u64::try_from(timestamp.sec), u32::try_from(timestamp.usec)) {
        (Ok(sec), Ok(usec)) if monotonic && usec < 1_000_000 && (sec, usec) != (0, 0) => {
            Duration::new(sec, usec * 1000)
        }
        _ => dequeued,
    }
}

/// A frame's rows without the padding a driver may add after each (its stride, bytesperline,
/// longer than `row_bytes`), as the YUYV conversion reads them: packed.
pub fn packed_rows(data: &[u8], stride: usize, row_bytes: usize, height: usize) -> Vec<u8> {
    if stride <= row_bytes {
        return data.to_vec();
    }
    data.chunks(stride)
        .take(height)
        .flat_map(|row| &row[..row_bytes.min(row.len())])
        .copied()
        .collect()
}

#[cfg(test)]
mod tests {
    use v4l::{
        frameinterval::Stepwise as IntervalRange,
        framesize::{Discrete, Stepwise as SizeRange},
        FourCC,
    };

    use super::*;

    #[test]
    fn yuyv_is_limited_range_unless_the_driver_says_full_or_jpeg() {
        use Colorspace::{Rec709, JPEG, SMPTE170M, SRGB};
        use Quantization::{Default, FullRange, LimitedRange};
        for colorspace in [SRGB, SMPTE170M, Rec709] {
            assert_eq!(yuv_range(Default, colorspace), YuvRange::Limited);
            assert_eq!(yuv_range(LimitedRange, colorspace), YuvRange::Limited);
            assert_eq!(yuv_range(FullRange, colorspace), YuvRange::Full);
        }
        assert_eq!(yuv_range(Default, JPEG), YuvRange::Full);
        assert_eq!(yuv_range(LimitedRange, JPEG), YuvRange::Limited);
    }

    fn discrete_size(width: u32, height: u32) -> FrameSize {
        FrameSize {
            index: 0,
            fourcc: FourCC::new(b"MJPG"),
            typ: 1,
            size: FrameSizeEnum::Discrete(Discrete { width, height }),
        }
    }

    fn interval(interval: FrameIntervalEnum) -> FrameInterval {
        FrameInterval {
            index: 0,
            fourcc: FourCC::new(b"MJPG"),
            width: 640,
            height: 480,
            typ: 1,
            interval,
        }
    }

    #[test]
    fn discrete_sizes_as_listed_and_stepwise_ranges_as_their_largest_and_the_default() {
        let listed = [discrete_size(1920, 1080), discrete_size(640, 480)];
        assert_eq!(sizes_of(&listed), [(1920, 1080), (640, 480)]);
        let range = |step| FrameSize {
            index: 0,
            fourcc: FourCC::new(b"YUYV"),
            typ: 3,
            size: FrameSizeEnum::Stepwise(SizeRange {
                min_width: 16,
                max_width: 1280,
                step_width: step,
                min_height: 16,
                max_height: 720,
                step_height: step,
            }),
        };
        assert_eq!(sizes_of(&[range(16)]), [(640, 480), (1280, 720)]);
        // 640 - 16 is no multiple of 100: the range does not hold 640x480.
        assert_eq!(sizes_of(&[range(100)]), [(1280, 720)]);
    }

    #[test]
    fn intervals_become_rates_fastest_first() {
        let discrete = |n, d| interval(FrameIntervalEnum::Discrete(Fraction::new(n, d)));
        assert_eq!(
            rates_of(&[discrete(1, 15), discrete(1, 30), discrete(1001, 30000)]),
            [30.0, 15.0]
        );
        assert_eq!(rates_of(&[discrete(0, 30)]), Vec::<f64>::new());
        let range = interval(FrameIntervalEnum::Stepwise(IntervalRange {
            min: Fraction::new(1, 60),
            max: Fraction::new(1, 5),
            step: Fraction::new(1, 1000),
        }));
        assert_eq!(rates_of(&[range]), [60.0, 30.0, 15.0, 5.0]);
    }

    #[test]
    fn padded_rows_are_packed() {
        // Two rows of 4 bytes, each padded to a stride of 6.
        let padded = [1, 2, 3, 4, 0, 0, 5, 6, 7, 8, 0, 0];
        assert_eq!(packed_rows(&padded, 6, 4, 2), [1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(packed_rows(&[1, 2, 3, 4], 4, 4, 1), [1, 2, 3, 4]);
    }

    #[test]
    fn a_rate_asks_for_its_interval() {
        let fraction = |f: Fraction| (f.numerator, f.denominator);
        assert_eq!(fraction(interval_of(30.0)), (1, 30));
        assert_eq!(fraction(interval_of(29.97)), (1000, 29970));
        assert_eq!(fraction(interval_of(7.5)), (1000, 7500));
        let back = rate_of(interval_of(29.97)).unwrap();
        assert!((back - 29.97).abs() < 1e-9);
    }

    #[test]
    fn monotonic_buffer_stamps_are_the_capture_instant_and_others_the_dequeue() {
        let dequeued = Duration::from_secs(100);
        let stamp = Timestamp::new(99, 966_667);
        assert_eq!(
            capture_instant(Flags::TIMESTAMP_MONOTONIC | Flags::DONE, stamp, dequeued),
            Duration::new(99, 966_667_000)
        );
        assert_eq!(
            capture_instant(Flags::TIMESTAMP_COPY, stamp, dequeued),
            dequeued
        );
        assert_eq!(
            capture_instant(Flags::TIMESTAMP_UNKNOWN, stamp, dequeued),
            dequeued
        );
        assert_eq!(
            capture_instant(Flags::TIMESTAMP_MONOTONIC, Timestamp::new(0, 0), dequeued),
            dequeued
        );
        assert_eq!(
            capture_instant(
                Flags::TIMESTAMP_MONOTONIC,
                Timestamp::new(5, 2_000_000),
                dequeued
            ),
            dequeued
        );
    }
}
