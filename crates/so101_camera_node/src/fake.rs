//! The in-process fake camera, a test source (`--camera NAME=fake:SETTINGS`): it serves real
//! MJPEG or YUYV frames of a known picture at its rate, with the faults a USB camera shows on
//! demand. SETTINGS, comma-separated, all optional:
//! - `mjpeg` or `yuyv`: the format it offers (default mjpeg);
//! - `WIDTHxHEIGHT@FPS`: the size and rate it offers (default 640x480@30; half the rate too);
//! - `drop_every=N`: every Nth frame is lost in the device (its sequence number skips one);
//! - `truncate_every=N`: every Nth frame arrives cut short (no JPEG end);
//! - `damage_every=N`: every Nth frame is delivered marked damaged (V4L2_BUF_FLAG_ERROR);
//! - `stall_at=K:SECONDS`: after frame K, no frame for SECONDS;
//! - `unplug_at=K:SECONDS`: after frame K, the camera is gone for SECONDS, then back;
//! - `fail_at=K`: after frame K, the stream fails once (EIO), the camera still there (each
//!   stream it is opened again in fails so too);
//! - `textured`: fine noise on the picture, so its JPEGs are as large as a webcam's (benchmarks).
//!
//! Its image controls: exposure (1..=5000, automatic at first), gain (0..=100, 32 at first) and
//! white balance (2800..=6500 K, automatic at first); no focus control, as many webcams. Like a
//! real camera it forgets their settings when it is unplugged.
//!
//! The picture of frame `sequence` ([`picture`]): red rises left to right, green top to bottom,
//! blue is `sequence * 8 mod 256` everywhere, so a subscriber can tell which frame it got.

use std::{
    sync::{Arc, Mutex, PoisonError},
    time::Duration,
};

use crate::{
    controls::{ControlKind, ControlState, Setting},
    decode::YuvRange,
    device::{monotonic_now, CameraDevice, CameraStream, CaptureError, Frame, OpenError},
    modes::{Mode, OfferedMode, PixelFormat, DEFAULT_FPS, DEFAULT_SIZE},
};

/// What the fake camera offers and does.
#[derive(Debug, Clone, PartialEq)]
pub struct FakeSettings {
    pub format: PixelFormat,
    pub width: u32,
    pub height: u32,
    pub fps: f64,
    pub drop_every: Option<u32>,
    pub truncate_every: Option<u32>,
    pub damage_every: Option<u32>,
    pub stall: Option<(u32, Duration)>,
    pub unplug: Option<(u32, Duration)>,
    pub fail_at: Option<u32>,
    /// Fine noise on the picture, so its JPEGs are as large as a webcam's (benchmarks).
    pub textured: bool,
}

impl Default for FakeSettings {
    fn default() -> Self {
        Self {
            format: PixelFormat::Mjpeg,
            width: DEFAULT_SIZE.0,
            height: DEFAULT_SIZE.1,
            fps: DEFAULT_FPS,
            drop_every: None,
            truncate_every: None,
            damage_every: None,
            stall: None,
            unplug: None,
            fail_at: None,
            textured: false,
        }
    }
}

impl std::str::FromStr for FakeSettings {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let mut settings = Self::default();
        for item in text.split(',').filter(|item| !item.is_empty()) {
            let bad = || format!("fake camera setting {item:?} not understood");
            match item.split_once('=') {
                None if item == "mjpeg" => settings.format = PixelFormat::Mjpeg,
                None if item == "yuyv" => settings.format = PixelFormat::Yuyv,
                None if item == "textured" => settings.textured = true,
                None => {
                    let (size, fps) = item.split_once('@').ok_or_else(bad)?;
                    let (width, height) = size.split_once('x').ok_or_else(bad)?;
                    settings.width = width.parse().map_err(|_| bad())?;
                    settings.height = height.parse().map_err(|_| bad())?;
                    settings.fps = fps.parse().map_err(|_| bad())?;
                    let even = settings.width % 2 == 0 && settings.width > 0;
                    let rate = settings.fps > 0.0 && settings.fps <= 1000.0;
                    if !even || settings.height == 0 || !rate {
                        return Err(format!(
                            "{item:?}: an even width, a height and a rate above 0"
                        ));
                    }
                }
                Some(("drop_every", n)) => settings.drop_every = Some(every(n).ok_or_else(bad)?),
                Some(("truncate_every", n)) => {
                    settings.truncate_every = Some(every(n).ok_or_else(bad)?)
                }
                Some(("damage_every", n)) => {
                    settings.damage_every = Some(every(n).ok_or_else(bad)?)
                }
                Some(("stall_at", at)) => settings.stall = Some(pause(at).ok_or_else(bad)?),
                Some(("unplug_at", at)) => settings.unplug = Some(pause(at).ok_or_else(bad)?),
                Some(("fail_at", k)) => settings.fail_at = Some(k.parse().map_err(|_| bad())?),
                Some(_) => return Err(bad()),
            }
        }
        Ok(settings)
    }
}

fn every(text: &str) -> Option<u32> {
    text.parse().ok().filter(|&n| n >= 2)
}

fn pause(text: &str) -> Option<(u32, Duration)> {
    let (frame, seconds) = text.split_once(':')?;
    let seconds: f64 = seconds
        .parse()
        .ok()
        .filter(|s: &f64| (0.0..=3600.0).contains(s))?;
    Some((frame.parse().ok()?, Duration::from_secs_f64(seconds)))
}

/// The picture of frame `sequence`, rgb8.
pub fn picture(width: u32, height: u32, sequence: u32) -> Vec<u8> {
    let blue = (sequence.wrapping_mul(8) % 256) as u8;
    let mut rgb = Vec::with_capacity((width * height * 3) as usize);
    for y in 0..height {
        for x in 0..width {
            rgb.push((x * 255 / width.saturating_sub(1).max(1)) as u8);
            rgb.push((y * 255 / height.saturating_sub(1).max(1)) as u8);
            rgb.push(blue);
        }
    }
    rgb
}

/// Adds a fixed pseudo-random pattern of +-4 to every byte (a hash of its index): the fine detail
/// of a webcam's picture: its 640x480 JPEG takes about 54 kB (a webcam's are 30-80 kB), the smooth
/// picture's 25 kB.
pub fn texture(rgb: &mut [u8]) {
    for (index, byte) in rgb.iter_mut().enumerate() {
        let hash = (index as u32).wrapping_mul(2_654_435_761).rotate_right(13);
        let offset = (hash % 9) as i32 - 4;
        *byte = (i32::from(*byte) + offset).clamp(0, 255) as u8;
    }
}

/// rgb8 as packed YUYV 4:2:2 (BT.601, limited range as USB cameras send it), chroma from each
/// pixel pair's mean.
pub fn yuyv_from_rgb(rgb: &[u8]) -> Vec<u8> {
    let luma = |p: &[u8]| {
        16.0 + (0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2])) * 219.0
            / 255.0
    };
    let byte = |value: f64| value.round().clamp(0.0, 255.0) as u8;
    let mut out = Vec::with_capacity(rgb.len() / 3 * 2);
    for pair in rgb.chunks_exact(6) {
        let (a, b) = pair.split_at(3);
        let mean = |i: usize| (f64::from(a[i]) + f64::from(b[i])) / 2.0;
        let (r, g, bl) = (mean(0), mean(1), mean(2));
        let chroma = 224.0 / 255.0;
        let u = (-0.168_736 * r - 0.331_264 * g + 0.5 * bl) * chroma + 128.0;
        let v = (0.5 * r - 0.418_688 * g - 0.081_312 * bl) * chroma + 128.0;
        out.extend([byte(luma(a)), byte(u), byte(luma(b)), byte(v)]);
    }
    out
}

/// The fake camera. Clones share whether it is plugged in.
#[derive(Debug, Clone)]
pub struct FakeCamera {
    settings: FakeSettings,
    /// While set: the camera is gone until this instant (monotonic).
    gone_until: Arc<Mutex<Option<Duration>>>,
}

impl FakeCamera {
    pub fn new(settings: FakeSettings) -> Self {
        Self {
            settings,
            gone_until: Arc::new(Mutex::new(None)),
        }
    }

    fn present(&self) -> bool {
        let mut gone = self
            .gone_until
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        match *gone {
            Some(until) if monotonic_now() < until => false,
            _ => {
                *gone = None;
                true
            }
        }
    }
}

impl CameraDevice for FakeCamera {
    fn modes(&mut self) -> Result<Vec<OfferedMode>, OpenError> {
        if !self.present() {
            return Err(OpenError::Missing("fake camera (unplugged)".into()));
        }
        let s = &self.settings;
        Ok(vec![OfferedMode {
            format: s.format,
            width: s.width,
            height: s.height,
            rates: vec![s.fps, s.fps / 2.0],
        }])
    }

    fn open(&mut self, mode: Mode) -> Result<Box<dyn CameraStream>, OpenError> {
        let offered = self.modes()?;
        let known = offered.iter().any(|m| {
            (m.format, m.width, m.height) == (mode.format, mode.width, mode.height)
                && m.rates.contains(&mode.fps)
        });
        if !known {
            return Err(OpenError::Failed(format!(
                "the fake camera offers no {mode}"
            )));
        }
        Ok(Box::new(FakeStream {
            camera: self.clone(),
            mode,
            start: monotonic_now(),
            next: 0,
            pause_until: None,
            failed: false,
            controls: fake_controls(),
            encoded: vec![None; PICTURES],
        }))
    }
}

struct FakeStream {
    camera: FakeCamera,
    mode: Mode,
    /// Frame k of this stream is due at start + k / fps (plus any stall).
    start: Duration,
    next: u32,
    pause_until: Option<Duration>,
    /// Whether this stream has had its `fail_at` failure.
    failed: bool,
    controls: Vec<ControlState>,
    /// Each picture's bytes, encoded once: serving a frame then costs a copy, so a benchmark of
    /// the node measures the node.
    encoded: Vec<Option<Vec<u8>>>,
}

/// Distinct pictures: blue is `sequence * 8 mod 256`.
const PICTURES: usize = 32;

/// The fake's controls as it powers up.
fn fake_controls() -> Vec<ControlState> {
    let control = |kind, minimum, maximum, has_auto, setting| ControlState {
        kind,
        minimum,
        maximum,
        has_auto,
        setting,
    };
    vec![
        control(ControlKind::Exposure, 1, 5000, true, Setting::Auto),
        control(ControlKind::Gain, 0, 100, false, Setting::Manual(32)),
        control(ControlKind::WhiteBalance, 2800, 6500, true, Setting::Auto),
    ]
}

impl FakeStream {
    fn due(&self, index: u32) -> Duration {
        let due = self.start + Duration::from_secs_f64(f64::from(index) / self.mode.fps);
        self.pause_until.map_or(due, |until| due.max(until))
    }

    fn frame(&mut self, sequence: u32, captured: Duration) -> Frame {
        let slot = sequence as usize % PICTURES;
        let mut data = match &self.encoded[slot] {
            Some(bytes) => bytes.clone(),
            None => {
                let bytes = self.encode(sequence);
                self.encoded[slot] = Some(bytes.clone());
                bytes
            }
        };
        if self
            .camera
            .settings
            .truncate_every
            .is_some_and(|n| sequence % n == n - 1)
        {
            data.truncate(data.len() * 2 / 3);
        }
        Frame {
            data,
            format: self.mode.format,
            yuv_range: YuvRange::Limited,
            width: self.mode.width,
            height: self.mode.height,
            captured,
            sequence,
        }
    }

    /// The bytes of frame `sequence`'s picture in the stream's format.
    fn encode(&self, sequence: u32) -> Vec<u8> {
        let mut rgb = picture(self.mode.width, self.mode.height, sequence);
        if self.camera.settings.textured {
            texture(&mut rgb);
        }
        match self.mode.format {
            PixelFormat::Yuyv => yuyv_from_rgb(&rgb),
            PixelFormat::Mjpeg => {
                let mut jpeg = Vec::new();
                // A picture this size always encodes (its sides fit u16, checked by the tests).
                let _ = jpeg_encoder::Encoder::new(&mut jpeg, 90).encode(
                    &rgb,
                    u16::try_from(self.mode.width).unwrap_or(u16::MAX),
                    u16::try_from(self.mode.height).unwrap_or(u16::MAX),
                    jpeg_encoder::ColorType::Rgb,
                );
                jpeg
            }
        }
    }
}

impl CameraStream for FakeStream {
    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CaptureError> {
        if !self.camera.present() {
            return Err(CaptureError::Gone("fake camera unplugged".into()));
        }
        let s = self.camera.settings.clone();
        if !self.failed && s.fail_at.is_some_and(|at| self.next > at) {
            self.failed = true;
            return Err(CaptureError::Failed(
                "fake stream failed (Input/output error)".into(),
            ));
        }
        // The device's own losses: the frame is never delivered, its sequence number is used.
        if s.drop_every.is_some_and(|n| self.next % n == n - 1) {
            self.next += 1;
        }
        let due = self.due(self.next);
        let now = monotonic_now();
        if due > now + timeout {
            std::thread::sleep(timeout);
            return Err(CaptureError::Timeout(timeout));
        }
        std::thread::sleep(due.saturating_sub(now));
        let frame = self.frame(self.next, due);
        if let Some((_, seconds)) = s.stall.filter(|(at, _)| *at == self.next) {
            self.pause_until = Some(due + seconds);
        }
        if let Some((_, seconds)) = s.unplug.filter(|(at, _)| *at == self.next) {
            let mut gone = self
                .camera
                .gone_until
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
            *gone = Some(due + seconds);
        }
        self.next += 1;
        if s.damage_every.is_some_and(|n| frame.sequence % n == n - 1) {
            return Err(CaptureError::Damaged {
                sequence: frame.sequence,
                reason: "marked corrupted by the fake".into(),
            });
        }
        Ok(frame)
    }

    fn controls(&mut self) -> Vec<ControlState> {
        self.controls.clone()
    }

    fn set_control(&mut self, kind: ControlKind, setting: Setting) -> Result<(), String> {
        let control = self
            .controls
            .iter_mut()
            .find(|control| control.kind == kind)
            .ok_or_else(|| format!("the camera has no {kind} control"))?;
        control.check(setting)?;
        control.setting = setting;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_textured_picture_makes_a_webcam_sized_jpeg() {
        let (_, mut stream) = open("640x480@30,textured");
        let textured = stream
            .next_frame(Duration::from_secs(1))
            .unwrap()
            .data
            .len();
        let (_, mut stream) = open("640x480@30");
        let smooth = stream
            .next_frame(Duration::from_secs(1))
            .unwrap()
            .data
            .len();
        assert!((30_000..150_000).contains(&textured), "{textured} bytes");
        assert!(
            smooth * 3 / 2 < textured,
            "{smooth} against {textured} bytes"
        );
    }

    use super::*;
    use crate::{jpeg::whole_jpeg, modes::choose};

    fn open(settings: &str) -> (FakeCamera, Box<dyn CameraStream>) {
        let mut camera = FakeCamera::new(settings.parse().unwrap_or_else(|e| panic!("{e}")));
        let mode = choose(&camera.modes().unwrap_or_default(), None, None)
            .unwrap_or_else(|e| panic!("{e}"));
        let stream = camera.open(mode).unwrap_or_else(|e| panic!("{e}"));
        (camera, stream)
    }

    const WAIT: Duration = Duration::from_secs(1);

    #[test]
    fn frames_come_at_the_rate_as_whole_jpegs_of_the_known_picture() {
        let (_, mut stream) = open("64x48@100");
        let frames: Vec<Frame> = (0..5).map(|_| stream.next_frame(WAIT).unwrap()).collect();
        for (k, frame) in frames.iter().enumerate() {
            assert_eq!(frame.sequence as usize, k);
            assert!(whole_jpeg(&frame.data).is_some());
            assert_eq!((frame.width, frame.height), (64, 48));
        }
        let gap = frames[4].captured - frames[0].captured;
        assert!((gap.as_secs_f64() - 0.04).abs() < 1e-6, "{gap:?}");
        assert!(monotonic_now() >= frames[4].captured);
    }

    #[test]
    fn yuyv_frames_are_two_bytes_a_pixel_of_the_picture() {
        let (_, mut stream) = open("yuyv,8x2@100");
        let frame = stream.next_frame(WAIT).unwrap();
        assert_eq!(frame.format, PixelFormat::Yuyv);
        assert_eq!(frame.data, yuyv_from_rgb(&picture(8, 2, 0)));
        assert_eq!(frame.data.len(), 8 * 2 * 2);
        // Grey stays grey (no chroma), its luma in limited range: 16 + 90 * 219 / 255.
        assert_eq!(
            yuyv_from_rgb(&[90, 90, 90, 90, 90, 90]),
            vec![93, 128, 93, 128]
        );
    }

    // The stall and the unplug last a second: far longer than any delay a loaded machine puts
    // between two calls, so the test sees them whatever the load.
    #[test]
    fn drops_truncations_stalls_and_unplugs_happen_where_asked() {
        let (_, mut stream) = open("16x8@200,drop_every=3,truncate_every=4");
        let frames: Vec<Frame> = (0..6).map(|_| stream.next_frame(WAIT).unwrap()).collect();
        let sequences: Vec<u32> = frames.iter().map(|f| f.sequence).collect();
        assert_eq!(sequences, [0, 1, 3, 4, 6, 7]);
        let whole: Vec<bool> = frames
            .iter()
            .map(|f| whole_jpeg(&f.data).is_some())
            .collect();
        assert_eq!(whole, [true, true, false, true, true, false]);

        let (_, mut damaging) = open("16x8@200,damage_every=3");
        let results: Vec<Result<u32, CaptureError>> = (0..4)
            .map(|_| damaging.next_frame(WAIT).map(|frame| frame.sequence))
            .collect();
        assert_eq!(results[..2], [Ok(0), Ok(1)]);
        assert!(
            matches!(results[2], Err(CaptureError::Damaged { sequence: 2, .. })),
            "{results:?}"
        );
        assert_eq!(results[3], Ok(3));

        let (_, mut failing) = open("16x8@200,fail_at=1");
        let results: Vec<Result<u32, CaptureError>> = (0..4)
            .map(|_| failing.next_frame(WAIT).map(|frame| frame.sequence))
            .collect();
        assert_eq!(results[..2], [Ok(0), Ok(1)]);
        assert!(
            matches!(results[2], Err(CaptureError::Failed(_))),
            "{results:?}"
        );
        assert_eq!(results[3], Ok(2), "once per stream");

        let (_, mut stalling) = open("16x8@200,stall_at=1:1.0");
        let first = stalling.next_frame(WAIT).unwrap();
        stalling.next_frame(WAIT).unwrap();
        assert_eq!(
            stalling.next_frame(Duration::from_millis(50)),
            Err(CaptureError::Timeout(Duration::from_millis(50)))
        );
        let after = stalling.next_frame(2 * WAIT).unwrap();
        assert!(after.captured - first.captured >= WAIT);

        let (mut camera, mut unplugged) = open("16x8@200,unplug_at=0:1.0");
        unplugged.next_frame(WAIT).unwrap();
        assert!(matches!(
            unplugged.next_frame(WAIT),
            Err(CaptureError::Gone(_))
        ));
        assert!(matches!(camera.modes(), Err(OpenError::Missing(_))));
        std::thread::sleep(Duration::from_millis(1050));
        assert!(camera.modes().is_ok(), "back after its time");
    }

    #[test]
    fn settings_are_checked() {
        assert_eq!("".parse::<FakeSettings>(), Ok(FakeSettings::default()));
        assert!("textured".parse::<FakeSettings>().unwrap().textured);
        for bad in [
            "65x48@30",
            "64x48",
            "drop_every=1",
            "stall_at=3",
            "hdr",
            "color=red",
        ] {
            assert!(bad.parse::<FakeSettings>().is_err(), "{bad}");
        }
    }
}
