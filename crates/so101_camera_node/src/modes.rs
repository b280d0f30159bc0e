//! Choosing the mode a camera streams in, from the modes it offers (what VIDIOC_ENUM_FMT,
//! ENUM_FRAMESIZES and ENUM_FRAMEINTERVALS list) and what the user asked for. MJPEG comes first:
//! it is what keeps three 640x480@30 cameras inside one USB 2.0 bus, and its frames are published
//! as they come. A mode the camera does not offer is refused with the modes it does offer.

use std::fmt;

/// The pixel formats the node takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum PixelFormat {
    /// Motion JPEG: each buffer one JPEG.
    Mjpeg,
    /// YUYV 4:2:2, converted and JPEG-encoded by the node.
    Yuyv,
}

impl PixelFormat {
    /// The V4L2 FourCC.
    pub fn fourcc(self) -> [u8; 4] {
        match self {
            Self::Mjpeg => *b"MJPG",
            Self::Yuyv => *b"YUYV",
        }
    }

    pub fn from_fourcc(fourcc: [u8; 4]) -> Option<Self> {
        match &fourcc {
            b"MJPG" => Some(Self::Mjpeg),
            b"YUYV" => Some(Self::Yuyv),
            _ => None,
        }
    }
}

impl fmt::Display for PixelFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Mjpeg => "MJPG",
            Self::Yuyv => "YUYV",
        })
    }
}

/// One frame size of one format, with the rates offered at it.
#[derive(Debug, Clone, PartialEq)]
pub struct OfferedMode {
    pub format: PixelFormat,
    pub width: u32,
    pub height: u32,
    /// Frames per second (1 / each offered frame interval).
    pub rates: Vec<f64>,
}

/// The mode to stream in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    pub format: PixelFormat,
    pub width: u32,
    pub height: u32,
    pub fps: f64,
}

impl fmt::Display for Mode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {}x{}@{}",
            self.format, self.width, self.height, self.fps
        )
    }
}

/// The size and rate used when the user names none: what LeRobot's SO-101 recordings use.
pub const DEFAULT_SIZE: (u32, u32) = (640, 480);
pub const DEFAULT_FPS: f64 = 30.0;
/// Two rates closer than this are the same (interval fractions such as 1001/30000).
const RATE_TOLERANCE: f64 = 0.05;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the camera offers no {requested}; it offers: {}", list(.offered))]
pub struct NoSuchMode {
    requested: String,
    offered: Vec<OfferedMode>,
}

/// One line per offered size: "MJPG 640x480@30,15".
pub fn list(offered: &[OfferedMode]) -> String {
    if offered.is_empty() {
        return "no MJPG or YUYV mode".to_owned();
    }
    offered
        .iter()
        .map(|mode| {
            let rates: Vec<String> = mode.rates.iter().map(|rate| format!("{rate}")).collect();
            format!(
                "{} {}x{}@{}",
                mode.format,
                mode.width,
                mode.height,
                rates.join(",")
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The mode for a request of `size` and `fps` (each optional): MJPEG before YUYV; without a size,
/// 640x480 where offered (at the rate asked), else the largest size offered at that rate; without
/// a rate, 30 where offered, else the highest.
pub fn choose(
    offered: &[OfferedMode],
    size: Option<(u32, u32)>,
    fps: Option<f64>,
) -> Result<Mode, NoSuchMode> {
    let mut formats: Vec<PixelFormat> = offered.iter().map(|mode| mode.format).collect();
    formats.sort();
    formats.dedup();
    for format in formats {
        let sizes: Vec<&OfferedMode> = offered
            .iter()
            .filter(|mode| mode.format == format && !mode.rates.is_empty())
            .collect();
        let mut candidates: Vec<&OfferedMode> = match size {
            Some(asked) => sizes
                .into_iter()
                .filter(|mode| (mode.width, mode.height) == asked)
                .collect(),
            None => sizes,
        };
        // 640x480 first, then the larger sizes first.
        candidates.sort_by_key(|mode| {
            (
                (mode.width, mode.height) != DEFAULT_SIZE,
                std::cmp::Reverse(mode.width * mode.height),
            )
        });
        for mode in candidates {
            let offers = |rate: f64| {
                mode.rates
                    .iter()
                    .copied()
                    .find(|offered| (offered - rate).abs() < RATE_TOLERANCE)
            };
            let rate = match fps {
                Some(fps) => offers(fps),
                None => offers(DEFAULT_FPS).or_else(|| mode.rates.iter().copied().reduce(f64::max)),
            };
            if let Some(fps) = rate {
                return Ok(Mode {
                    format,
                    width: mode.width,
                    height: mode.height,
                    fps,
                });
            }
        }
    }
    let requested = match (size, fps) {
        (Some((w, h)), Some(fps)) => format!("{w}x{h}@{fps}"),
        (Some((w, h)), None) => format!("{w}x{h}"),
        (None, Some(fps)) => format!("mode at {fps} frames/s"),
        (None, None) => "MJPG or YUYV mode".to_owned(),
    };
    Err(NoSuchMode {
        requested,
        offered: offered.to_vec(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What a common 1080p USB webcam lists (MJPEG up to 1920x1080@30, YUYV slower).
    fn webcam() -> Vec<OfferedMode> {
        let mode = |format, width, height, rates: &[f64]| OfferedMode {
            format,
            width,
            height,
            rates: rates.to_vec(),
        };
        vec![
            mode(PixelFormat::Yuyv, 640, 480, &[30.0, 15.0]),
            mode(PixelFormat::Yuyv, 1920, 1080, &[5.0]),
            mode(PixelFormat::Mjpeg, 1920, 1080, &[30.0, 15.0]),
            mode(PixelFormat::Mjpeg, 640, 480, &[30.0, 15.0]),
            mode(PixelFormat::Mjpeg, 320, 240, &[60.0, 30.0]),
        ]
    }

    fn mode(format: PixelFormat, width: u32, height: u32, fps: f64) -> Mode {
        Mode {
            format,
            width,
            height,
            fps,
        }
    }

    #[test]
    fn mjpeg_at_640x480_and_30_unless_asked_otherwise() {
        let offered = webcam();
        assert_eq!(
            choose(&offered, None, None),
            Ok(mode(PixelFormat::Mjpeg, 640, 480, 30.0))
        );
        assert_eq!(
            choose(&offered, Some((320, 240)), Some(60.0)),
            Ok(mode(PixelFormat::Mjpeg, 320, 240, 60.0))
        );
        assert_eq!(
            choose(&offered, Some((1920, 1080)), None),
            Ok(mode(PixelFormat::Mjpeg, 1920, 1080, 30.0))
        );
        // 29.97 (1001/30000) is the 30 a camera offers.
        assert_eq!(
            choose(&offered, None, Some(29.97)),
            Ok(mode(PixelFormat::Mjpeg, 640, 480, 30.0))
        );
    }

    #[test]
    fn a_yuyv_only_camera_streams_yuyv_at_its_largest_size_without_640x480() {
        let offered = vec![OfferedMode {
            format: PixelFormat::Yuyv,
            width: 800,
            height: 600,
            rates: vec![20.0, 10.0],
        }];
        assert_eq!(
            choose(&offered, None, None),
            Ok(mode(PixelFormat::Yuyv, 800, 600, 20.0))
        );
    }

    #[test]
    fn a_rate_alone_takes_the_largest_size_offered_at_that_rate() {
        // A camera like vivid's webcam input: 30 fps only at the sizes below 640x480.
        let mode = |width, height, rates: &[f64]| OfferedMode {
            format: PixelFormat::Yuyv,
            width,
            height,
            rates: rates.to_vec(),
        };
        let offered = vec![
            mode(320, 180, &[60.0, 30.0]),
            mode(640, 360, &[60.0, 30.0]),
            mode(640, 480, &[15.0, 10.0]),
            mode(1280, 720, &[15.0]),
            mode(1920, 1080, &[5.0]),
        ];
        assert_eq!(
            choose(&offered, None, Some(30.0)),
            Ok(super::Mode {
                format: PixelFormat::Yuyv,
                width: 640,
                height: 360,
                fps: 30.0
            })
        );
        assert_eq!(
            choose(&offered, None, None).map(|m| (m.width, m.height, m.fps)),
            Ok((640, 480, 15.0))
        );
        assert_eq!(
            choose(&offered, None, Some(5.0)).map(|m| (m.width, m.height)),
            Ok((1920, 1080))
        );
        assert!(choose(&offered, None, Some(90.0)).is_err());
    }

    #[test]
    fn a_mode_the_camera_lacks_is_refused_with_what_it_offers() {
        let offered = webcam();
        let refused = choose(&offered, Some((1280, 720)), None)
            .unwrap_err()
            .to_string();
        assert!(refused.contains("no 1280x720"), "{refused}");
        assert!(refused.contains("MJPG 640x480@30,15"), "{refused}");
        assert!(refused.contains("YUYV 1920x1080@5"), "{refused}");
        let too_fast = choose(&offered, Some((640, 480)), Some(90.0))
            .unwrap_err()
            .to_string();
        assert!(too_fast.contains("no 640x480@90"), "{too_fast}");
        assert!(choose(&[], None, None)
            .unwrap_err()
            .to_string()
            .contains("no MJPG or YUYV mode"));
    }

    #[test]
    fn fourccs_round_trip() {
        for format in [PixelFormat::Mjpeg, PixelFormat::Yuyv] {
            assert_eq!(PixelFormat::from_fourcc(format.fourcc()), Some(format));
        }
        assert_eq!(PixelFormat::from_fourcc(*b"H264"), None);
    }
}
