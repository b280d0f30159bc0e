//! One `--camera NAME=DEVICE[:WIDTHxHEIGHT][@FPS]` request: the topic name, the device (a
//! /dev/videoN path, a stable /dev/v4l/by-id/... path, an index, or the `fake:` test source) and
//! optionally the size and rate to negotiate.

use std::{fmt, path::PathBuf, str::FromStr};

/// Largest frame side and rate a request may name.
const MAX_SIDE: u32 = 8192;
const MAX_FPS: f64 = 1000.0;

/// Where a camera's frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum DeviceName {
    /// A device node (/dev/video2, /dev/v4l/by-id/usb-...-video-index0).
    Path(PathBuf),
    /// /dev/video<index>.
    Index(u32),
    /// The in-process test source (`fake:` and its settings): documented as a test source only.
    Fake(String),
}

impl DeviceName {
    /// The device node to open, for a real camera.
    pub fn path(&self) -> Option<PathBuf> {
        match self {
            Self::Path(path) => Some(path.clone()),
            Self::Index(index) => Some(PathBuf::from(format!("/dev/video{index}"))),
            Self::Fake(_) => None,
        }
    }
}

impl fmt::Display for DeviceName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Path(path) => write!(f, "{}", path.display()),
            Self::Index(index) => write!(f, "{index}"),
            Self::Fake(settings) => write!(f, "fake:{settings}"),
        }
    }
}

/// A camera as the user asked for it.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraRequest {
    /// The name in `camera/<name>/...` (top, front, wrist match the sim's).
    pub name: String,
    pub device: DeviceName,
    pub size: Option<(u32, u32)>,
    pub fps: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("--camera {text:?}: {reason} (expected NAME=DEVICE[:WIDTHxHEIGHT][@FPS], e.g. top=/dev/video0:640x480@30)")]
pub struct RequestError {
    text: String,
    reason: String,
}

impl FromStr for CameraRequest {
    type Err = RequestError;

    fn from_str(text: &str) -> Result<Self, RequestError> {
        let error = |reason: &str| RequestError {
            text: text.to_owned(),
            reason: reason.to_owned(),
        };
        let (name, rest) = text
            .split_once('=')
            .ok_or_else(|| error("no '=' between the name and the device"))?;
        if !valid_name(name) {
            return Err(error(
                "the name is a ROS name token: a letter, then letters, digits or '_'",
            ));
        }
        if let Some(settings) = rest.strip_prefix("fake:") {
            return Ok(Self {
                name: name.to_owned(),
                device: DeviceName::Fake(settings.to_owned()),
                size: None,
                fps: None,
            });
        }
        let (rest, fps) = match rest.rsplit_once('@') {
            Some((rest, fps)) => (rest, Some(parse_fps(fps).map_err(|reason| error(&reason))?)),
            None => (rest, None),
        };
        // A size follows the last ':' only where it reads as one (by-id paths hold ':').
        let (device, size) = match rest.rsplit_once(':') {
            Some((device, size)) if looks_like_a_size(size) => (
                device,
                Some(parse_size(size).map_err(|reason| error(&reason))?),
            ),
            _ => (rest, None),
        };
        if device.is_empty() {
            return Err(error("no device"));
        }
        let device = match device.parse::<u32>() {
            Ok(index) => DeviceName::Index(index),
            Err(_) => DeviceName::Path(PathBuf::from(device)),
        };
        Ok(Self {
            name: name.to_owned(),
            device,
            size,
            fps,
        })
    }
}

/// DIGITSxDIGITS: what follows a device's last ':' when it is a size.
fn looks_like_a_size(text: &str) -> bool {
    text.split_once('x').is_some_and(|(w, h)| {
        [w, h]
            .iter()
            .all(|side| !side.is_empty() && side.bytes().all(|b| b.is_ascii_digit()))
    })
}

fn valid_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars
        .next()
        .is_some_and(|first| first.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let parsed = text
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)));
    match parsed {
        Some((w, h)) if (1..=MAX_SIDE).contains(&w) && (1..=MAX_SIDE).contains(&h) => Ok((w, h)),
        _ => Err(format!(
            "{text:?} is not a size WIDTHxHEIGHT with sides from 1 to {MAX_SIDE}"
        )),
    }
}

fn parse_fps(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(fps) if fps > 0.0 && fps <= MAX_FPS => Ok(fps),
        _ => Err(format!(
            "{text:?} is not a frame rate above 0 and at most {MAX_FPS}"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(text: &str) -> CameraRequest {
        text.parse().unwrap_or_else(|error| panic!("{error}"))
    }

    #[test]
    fn paths_indices_sizes_and_rates() {
        let top = request("top=/dev/video0:640x480@30");
        assert_eq!(top.name, "top");
        assert_eq!(top.device, DeviceName::Path("/dev/video0".into()));
        assert_eq!((top.size, top.fps), (Some((640, 480)), Some(30.0)));
        let wrist = request("wrist=2");
        assert_eq!(wrist.device, DeviceName::Index(2));
        assert_eq!(wrist.device.path(), Some(PathBuf::from("/dev/video2")));
        assert_eq!((wrist.size, wrist.fps), (None, None));
        assert_eq!(request("front=1@15").fps, Some(15.0));
    }

    #[test]
    fn a_by_id_path_keeps_its_colons() {
        let path = "/dev/v4l/by-id/usb-046d_C922_Pro_Stream_Webcam_ABC123-video-index0";
        let plain = request(&format!("top={path}"));
        assert_eq!(plain.device, DeviceName::Path(path.into()));
        let by_path = "/dev/v4l/by-path/pci-0000:00:14.0-usb-0:2:1.0-video-index0";
        let sized = request(&format!("top={by_path}:1280x720@30"));
        assert_eq!(sized.device, DeviceName::Path(by_path.into()));
        assert_eq!(sized.size, Some((1280, 720)));
        assert_eq!(request(&format!("top={by_path}")).size, None);
    }

    #[test]
    fn the_fake_source_keeps_its_settings_whole() {
        let fake = request("wrist=fake:mjpeg,640x480@30,unplug_after=90");
        assert_eq!(
            fake.device,
            DeviceName::Fake("mjpeg,640x480@30,unplug_after=90".into())
        );
        assert_eq!(fake.device.path(), None);
    }

    #[test]
    fn bad_requests_say_what_is_wrong() {
        for (text, says) in [
            ("/dev/video0", "no '='"),
            ("1top=/dev/video0", "ROS name"),
            ("top-cam=/dev/video0", "ROS name"),
            ("top=", "no device"),
            ("top=/dev/video0:0x480", "sides from 1"),
            ("top=/dev/video0:640x480@0", "frame rate above 0"),
            ("top=/dev/video0@fast", "frame rate"),
        ] {
            let error = text.parse::<CameraRequest>().unwrap_err().to_string();
            assert!(error.contains(says), "{text}: {error}");
            assert!(error.contains("NAME=DEVICE"), "{error}");
        }
    }
}
