//! The image controls a user fixes for recording (exposure, gain, white balance, focus): their
//! parameter names, what a setting means, and the V4L2 controls that carry it. Pure.
//!
//! A setting is a number in the control's own unit, or [`AUTO`] for the camera's automatic mode.
//! Auto exposure flickers with the light and changes what a policy sees from one episode to the
//! next, which is why LeRobot users fix it; the camera's automatic modes stay the default.

use std::{fmt, str::FromStr};

/// The value of a parameter that hands the control to the camera's automatic mode.
pub const AUTO: i64 = -1;

/// One control a user sets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ControlKind {
    /// Exposure time, in units of 100 µs (V4L2's exposure_time_absolute); AUTO: aperture priority.
    Exposure,
    /// Sensor gain, in the camera's units; AUTO: automatic gain, where the camera has it.
    Gain,
    /// White balance temperature, K; AUTO: automatic white balance.
    WhiteBalance,
    /// Focus distance, in the camera's units; AUTO: continuous autofocus.
    Focus,
}

impl ControlKind {
    pub const ALL: [Self; 4] = [Self::Exposure, Self::Gain, Self::WhiteBalance, Self::Focus];

    /// The parameter's name under the camera's: `top.exposure`.
    pub fn key(self) -> &'static str {
        match self {
            Self::Exposure => "exposure",
            Self::Gain => "gain",
            Self::WhiteBalance => "white_balance",
            Self::Focus => "focus",
        }
    }

    pub fn description(self) -> &'static str {
        match self {
            Self::Exposure => "exposure time, 100 µs units (-1: automatic)",
            Self::Gain => {
                "sensor gain, the camera's units (-1: automatic, where the camera has it)"
            }
            Self::WhiteBalance => "white balance temperature, K (-1: automatic)",
            Self::Focus => "focus distance, the camera's units (-1: autofocus)",
        }
    }

    /// The V4L2 control that holds the manual value.
    pub fn value_control(self) -> u32 {
        match self {
            Self::Exposure => cid::EXPOSURE_ABSOLUTE,
            Self::Gain => cid::GAIN,
            Self::WhiteBalance => cid::WHITE_BALANCE_TEMPERATURE,
            Self::Focus => cid::FOCUS_ABSOLUTE,
        }
    }

    /// The V4L2 control that switches the automatic mode, if the control has one.
    pub fn auto_control(self) -> Option<u32> {
        match self {
            Self::Exposure => Some(cid::EXPOSURE_AUTO),
            Self::Gain => Some(cid::AUTOGAIN),
            Self::WhiteBalance => Some(cid::AUTO_WHITE_BALANCE),
            Self::Focus => Some(cid::FOCUS_AUTO),
        }
    }
}

impl fmt::Display for ControlKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.key())
    }
}

/// The V4L2 control ids (linux/v4l2-controls.h), checked against the kernel header's values in
/// the backend's tests.
pub mod cid {
    const USER_BASE: u32 = 0x0098_0900;
    const CAMERA_BASE: u32 = 0x009a_0900;
    pub const AUTO_WHITE_BALANCE: u32 = USER_BASE + 12;
    pub const AUTOGAIN: u32 = USER_BASE + 18;
    pub const GAIN: u32 = USER_BASE + 19;
    pub const WHITE_BALANCE_TEMPERATURE: u32 = USER_BASE + 26;
    pub const EXPOSURE_AUTO: u32 = CAMERA_BASE + 1;
    pub const EXPOSURE_ABSOLUTE: u32 = CAMERA_BASE + 2;
    pub const FOCUS_ABSOLUTE: u32 = CAMERA_BASE + 10;
    pub const FOCUS_AUTO: u32 = CAMERA_BASE + 12;
    /// EXPOSURE_AUTO's menu: manual, and aperture priority (auto exposure time, what UVC
    /// webcams offer; full auto is for cameras with an iris).
    pub const EXPOSURE_MANUAL: i64 = 1;
    pub const EXPOSURE_APERTURE_PRIORITY: i64 = 3;
}

/// What a control is set to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    Auto,
    Manual(i64),
}

impl Setting {
    /// As the parameter holds it.
    pub fn parameter(self) -> i64 {
        match self {
            Self::Auto => AUTO,
            Self::Manual(value) => value,
        }
    }

    pub fn from_parameter(value: i64) -> Self {
        if value == AUTO {
            Self::Auto
        } else {
            Self::Manual(value)
        }
    }
}

/// A control the camera has: its manual range and what it is set to now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControlState {
    pub kind: ControlKind,
    pub minimum: i64,
    pub maximum: i64,
    /// Whether the camera offers the automatic mode.
    pub has_auto: bool,
    pub setting: Setting,
}

impl ControlState {
    /// Whether the camera takes `setting`, or why not.
    pub fn check(&self, setting: Setting) -> Result<(), String> {
        match setting {
            Setting::Auto if !self.has_auto => {
                Err(format!("the camera has no automatic {}", self.kind))
            }
            Setting::Manual(value) if !(self.minimum..=self.maximum).contains(&value) => {
                Err(format!(
                    "{} {value} is outside the camera's {}..={}",
                    self.kind, self.minimum, self.maximum
                ))
            }
            _ => Ok(()),
        }
    }
}

/// The V4L2 control writes that make `setting` so on a camera that has (`has_auto`) or lacks the
/// control's automatic mode, in order: the automatic mode off before a manual value (a camera
/// ignores or refuses the value while its automatic mode is on).
pub fn writes(kind: ControlKind, setting: Setting, has_auto: bool) -> Vec<(u32, i64)> {
    let auto = kind.auto_control().filter(|_| has_auto);
    match (setting, auto) {
        (Setting::Auto, Some(id)) if kind == ControlKind::Exposure => {
            vec![(id, cid::EXPOSURE_APERTURE_PRIORITY)]
        }
        (Setting::Auto, Some(id)) => vec![(id, 1)],
        (Setting::Auto, None) => Vec::new(),
        (Setting::Manual(value), Some(id)) if kind == ControlKind::Exposure => {
            vec![(id, cid::EXPOSURE_MANUAL), (kind.value_control(), value)]
        }
        (Setting::Manual(value), Some(id)) => vec![(id, 0), (kind.value_control(), value)],
        (Setting::Manual(value), None) => vec![(kind.value_control(), value)],
    }
}

/// What the camera reports after `asked` was set: `Err` when it did not take the mode (a manual
/// value left on automatic, or the reverse: the request is refused with what it reports),
/// `Ok(Some(note))` when it took another value than asked (a driver rounding to its step: said,
/// not refused), `Ok(None)` when it reports what was asked.
pub fn read_back(
    kind: ControlKind,
    asked: Setting,
    reported: Option<Setting>,
) -> Result<Option<String>, String> {
    match (asked, reported) {
        (_, None) => Err(format!("{kind}: the camera no longer reports the control")),
        (Setting::Manual(value), Some(Setting::Auto)) => Err(format!(
            "{kind} set to {value}, but the camera still reports its automatic mode"
        )),
        (Setting::Auto, Some(Setting::Manual(value))) => Err(format!(
            "{kind} set to automatic, but the camera reports a manual {value}"
        )),
        (Setting::Manual(value), Some(Setting::Manual(read))) if read != value => Ok(Some(
            format!("{kind} set to {value}; the camera reports {read}"),
        )),
        _ => Ok(None),
    }
}

/// Whether the automatic-mode control's value means automatic.
pub fn is_auto(kind: ControlKind, auto_value: i64) -> bool {
    match kind {
        ControlKind::Exposure => auto_value != cid::EXPOSURE_MANUAL,
        _ => auto_value != 0,
    }
}

/// One `--control CAMERA.KEY=VALUE` (VALUE a number or `auto`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ControlRequest {
    pub camera: String,
    pub kind: ControlKind,
    pub setting: Setting,
}

impl FromStr for ControlRequest {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let keys: Vec<&str> = ControlKind::ALL.iter().map(|kind| kind.key()).collect();
        let expected = format!(
            "--control {text:?}: expected CAMERA.KEY=VALUE, KEY one of {}, VALUE a number or auto \
             (e.g. top.exposure=156)",
            keys.join(", ")
        );
        let (name, value) = text.split_once('=').ok_or_else(|| expected.clone())?;
        let (camera, key) = name.rsplit_once('.').ok_or_else(|| expected.clone())?;
        let kind = ControlKind::ALL
            .into_iter()
            .find(|kind| kind.key() == key)
            .ok_or_else(|| expected.clone())?;
        let setting = match value {
            // Whether the camera has an automatic mode is checked when it is opened.
            "auto" => Setting::Auto,
            number => match number.parse::<i64>() {
                Ok(value) if value >= 0 => Setting::Manual(value),
                _ => return Err(expected),
            },
        };
        Ok(Self {
            camera: camera.to_owned(),
            kind,
            setting,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_values_switch_the_automatic_mode_off_first() {
        assert_eq!(
            writes(ControlKind::Exposure, Setting::Manual(156), true),
            [(cid::EXPOSURE_AUTO, 1), (cid::EXPOSURE_ABSOLUTE, 156)]
        );
        assert_eq!(
            writes(ControlKind::Exposure, Setting::Auto, true),
            [(cid::EXPOSURE_AUTO, 3)]
        );
        assert_eq!(
            writes(ControlKind::WhiteBalance, Setting::Manual(4000), true),
            [
                (cid::AUTO_WHITE_BALANCE, 0),
                (cid::WHITE_BALANCE_TEMPERATURE, 4000)
            ]
        );
        assert_eq!(
            writes(ControlKind::Focus, Setting::Auto, true),
            [(cid::FOCUS_AUTO, 1)]
        );
        // A camera with automatic gain (vivid, many webcams) ignores a gain while it is on.
        assert_eq!(
            writes(ControlKind::Gain, Setting::Manual(40), true),
            [(cid::AUTOGAIN, 0), (cid::GAIN, 40)]
        );
        assert_eq!(
            writes(ControlKind::Gain, Setting::Manual(40), false),
            [(cid::GAIN, 40)]
        );
        assert_eq!(
            writes(ControlKind::Exposure, Setting::Manual(156), false),
            [(cid::EXPOSURE_ABSOLUTE, 156)]
        );
        assert!(is_auto(ControlKind::Exposure, 3));
        assert!(!is_auto(ControlKind::Exposure, 1));
        assert!(!is_auto(ControlKind::Focus, 0));
    }

    #[test]
    fn a_mode_the_camera_did_not_take_is_refused_and_a_rounded_value_is_said() {
        let gain = ControlKind::Gain;
        assert_eq!(
            read_back(gain, Setting::Manual(10), Some(Setting::Manual(10))),
            Ok(None)
        );
        assert_eq!(
            read_back(gain, Setting::Auto, Some(Setting::Auto)),
            Ok(None)
        );
        let still_auto = read_back(gain, Setting::Manual(10), Some(Setting::Auto)).unwrap_err();
        assert!(
            still_auto.contains("still reports its automatic mode"),
            "{still_auto}"
        );
        assert!(read_back(gain, Setting::Auto, Some(Setting::Manual(3))).is_err());
        let rounded = read_back(gain, Setting::Manual(10), Some(Setting::Manual(12)));
        assert_eq!(
            rounded,
            Ok(Some("gain set to 10; the camera reports 12".into()))
        );
        assert!(read_back(gain, Setting::Manual(10), None).is_err());
    }

    #[test]
    fn requests_name_a_camera_a_control_and_a_value() {
        let request: ControlRequest = "wrist.white_balance=auto".parse().unwrap();
        assert_eq!(
            request,
            ControlRequest {
                camera: "wrist".into(),
                kind: ControlKind::WhiteBalance,
                setting: Setting::Auto
            }
        );
        let request: ControlRequest = "top.exposure=156".parse().unwrap();
        assert_eq!(request.setting, Setting::Manual(156));
        for bad in ["top.exposure", "top=5", "top.iso=100", "top.exposure=-5"] {
            assert!(bad.parse::<ControlRequest>().is_err(), "{bad}");
        }
    }

    #[test]
    fn a_setting_outside_the_camera_s_range_is_refused_with_the_range() {
        let state = ControlState {
            kind: ControlKind::Gain,
            minimum: 0,
            maximum: 255,
            has_auto: false,
            setting: Setting::Manual(32),
        };
        assert!(state.check(Setting::Manual(255)).is_ok());
        let refused = state.check(Setting::Manual(300)).unwrap_err();
        assert!(refused.contains("0..=255"), "{refused}");
        assert!(state.check(Setting::Auto).is_err());
        assert_eq!(Setting::from_parameter(AUTO), Setting::Auto);
        assert_eq!(Setting::Manual(7).parameter(), 7);
    }
}
