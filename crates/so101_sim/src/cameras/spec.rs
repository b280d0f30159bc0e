//! Which cameras the node renders, at what size and rate: `--cameras top,front:320x240,wrist@15`.

use std::fmt;

/// Width and height of a frame, in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameSize {
    pub width: u32,
    pub height: u32,
}

impl fmt::Display for FrameSize {
    fn fmt(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(formatter, "{}x{}", self.width, self.height)
    }
}

/// Largest frame side accepted (MuJoCo's offscreen buffer is one GL renderbuffer).
pub const MAX_SIDE: u32 = 4096;
/// Highest camera rate accepted, frames per second of sim time.
pub const MAX_RATE: f64 = 1000.0;
/// Lowest camera rate (frames/s): one frame every 10 s.
pub const MIN_RATE: f64 = 0.1;

/// One entry of `--cameras`: a model camera by name, with the size and rate it overrides.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraRequest {
    pub name: String,
    pub size: Option<FrameSize>,
    pub rate: Option<f64>,
}

/// A camera with everything decided.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraSpec {
    pub name: String,
    pub size: FrameSize,
    pub rate: f64,
}

/// The parsed value of `--cameras` (empty for "none").
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CameraList(pub Vec<CameraRequest>);

impl CameraList {
    /// Every requested camera, with the defaults filled in where the entry named none: `size`
    /// gives each camera's default size by name.
    pub fn resolve(&self, size: impl Fn(&str) -> FrameSize, rate: f64) -> Vec<CameraSpec> {
        self.0
            .iter()
            .map(|request| CameraSpec {
                name: request.name.clone(),
                size: request.size.unwrap_or_else(|| size(&request.name)),
                rate: request.rate.unwrap_or(rate),
            })
            .collect()
    }
}

/// Parses `NAME[:WIDTHxHEIGHT][@RATE]` entries separated by commas, or "none".
pub fn parse_camera_list(text: &str) -> Result<CameraList, String> {
    let text = text.trim();
    if text.is_empty() || text.eq_ignore_ascii_case("none") {
        return Ok(CameraList::default());
    }
    let mut requests: Vec<CameraRequest> = Vec::new();
    for entry in text.split(',') {
        let request = parse_request(entry.trim())?;
        if requests.iter().any(|other| other.name == request.name) {
            return Err(format!("camera {:?} is listed twice", request.name));
        }
        requests.push(request);
    }
    Ok(CameraList(requests))
}

fn parse_request(entry: &str) -> Result<CameraRequest, String> {
    let (rest, rate) = match entry.split_once('@') {
        Some((rest, rate)) => (rest, Some(parse_rate(rate)?)),
        None => (entry, None),
    };
    let (name, size) = match rest.split_once(':') {
        Some((name, size)) => (name, Some(parse_size(size)?)),
        None => (rest, None),
    };
    if !is_camera_name(name) {
        return Err(format!(
            "{entry:?}: a camera entry is NAME[:WIDTHxHEIGHT][@RATE], NAME in letters, digits and '_'"
        ));
    }
    Ok(CameraRequest {
        name: name.to_owned(),
        size,
        rate,
    })
}

/// A camera's name as the node takes it: letters, digits and '_' (it becomes part of topic names).
pub fn is_camera_name(name: &str) -> bool {
    !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Parses `WIDTHxHEIGHT`.
pub fn parse_size(text: &str) -> Result<FrameSize, String> {
    let parsed = text.split_once(['x', 'X']).and_then(|(width, height)| {
        Some((width.parse::<u32>().ok()?, height.parse::<u32>().ok()?))
    });
    match parsed {
        Some((width, height))
            if (1..=MAX_SIDE).contains(&width) && (1..=MAX_SIDE).contains(&height) =>
        {
            Ok(FrameSize { width, height })
        }
        _ => Err(format!(
            "{text:?} is not a frame size WIDTHxHEIGHT with sides from 1 to {MAX_SIDE}"
        )),
    }
}

/// Parses a camera rate in frames per second of sim time.
pub fn parse_rate(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(rate) if (MIN_RATE..=MAX_RATE).contains(&rate) => Ok(rate),
        _ => Err(format!(
            "{text:?} is not a camera rate from {MIN_RATE} to {MAX_RATE} frames/s"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const VGA: FrameSize = FrameSize {
        width: 640,
        height: 480,
    };

    #[test]
    fn entries_take_defaults_unless_they_override_them() {
        let list = parse_camera_list("top, front:320x240 ,wrist@15,side:64x48@2.5").unwrap();
        let specs = list.resolve(|_| VGA, 30.0);
        let summary: Vec<(&str, FrameSize, f64)> = specs
            .iter()
            .map(|spec| (spec.name.as_str(), spec.size, spec.rate))
            .collect();
        assert_eq!(
            summary,
            [
                ("top", VGA, 30.0),
                (
                    "front",
                    FrameSize {
                        width: 320,
                        height: 240
                    },
                    30.0
                ),
                ("wrist", VGA, 15.0),
                (
                    "side",
                    FrameSize {
                        width: 64,
                        height: 48
                    },
                    2.5
                ),
            ]
        );
    }

    #[test]
    fn none_and_empty_mean_no_camera() {
        assert!(parse_camera_list("none").unwrap().0.is_empty());
        assert!(parse_camera_list(" ").unwrap().0.is_empty());
    }

    #[test]
    fn bad_entries_are_refused_with_the_reason() {
        for bad in [
            "top,,front",
            "top:640",
            "top:0x480",
            "top:640x99999",
            "top@0",
            "top@-3",
            "top@nan",
            "top@5000",
            "to p",
            "top/x",
            "top,top",
            ":640x480",
        ] {
            assert!(parse_camera_list(bad).is_err(), "{bad}");
        }
        assert!(parse_camera_list("top,top").unwrap_err().contains("twice"));
    }
}
