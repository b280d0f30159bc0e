//! The randomization as a user asks for it: off, the default ranges, or a file of ranges; from a
//! command line, a ROS launch argument, a Gymnasium or LeRobot option (where `true` and `false`
//! are what a user writes). Parsed, and its file read, once, where the option is taken.

use std::{fmt, path::Path, str::FromStr};

use super::config::{ConfigError, RandomizationConfig};

/// No randomization: every episode is the nominal scene.
pub const OFF: &str = "off";
/// The ranges of assets/randomization.toml.
pub const DEFAULT: &str = "default";
/// The held-out shift set of assets/randomization_heldout.toml.
pub const HELDOUT: &str = "heldout";

/// What to randomize with, and how the user named it.
#[derive(Debug, Clone, PartialEq)]
pub struct RandomizationSpec {
    /// `off`, `default`, `heldout` or the file's path: what the node's parameters and logs show.
    name: String,
    config: Option<RandomizationConfig>,
}

impl RandomizationSpec {
    /// `off` or `false`, `default` or `true` (either case), `heldout`, or the path of a file of
    /// ranges (.toml).
    pub fn parse(text: &str) -> Result<Self, ConfigError> {
        if text == OFF || text.eq_ignore_ascii_case("false") {
            Ok(Self::off())
        } else if text == DEFAULT || text.eq_ignore_ascii_case("true") {
            Ok(Self::default_ranges())
        } else if text == HELDOUT {
            Ok(Self {
                name: HELDOUT.to_owned(),
                config: Some(RandomizationConfig::heldout()?),
            })
        } else if text.ends_with(".toml") || Path::new(text).is_file() {
            Self::load(Path::new(text))
        } else {
            Err(ConfigError::Choice(text.to_owned()))
        }
    }

    /// A file of ranges, whatever its name (a path handed over as a path, not as text).
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Ok(Self {
            name: path.display().to_string(),
            config: Some(RandomizationConfig::load(path)?),
        })
    }

    /// `on`: the default ranges; otherwise off.
    pub fn from_flag(on: bool) -> Self {
        if on {
            Self::default_ranges()
        } else {
            Self::off()
        }
    }

    pub fn off() -> Self {
        Self {
            name: OFF.to_owned(),
            config: None,
        }
    }

    pub fn default_ranges() -> Self {
        Self {
            name: DEFAULT.to_owned(),
            config: Some(RandomizationConfig::defaults()),
        }
    }

    /// `off`, `default` or the file's path.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The ranges (`None`: off).
    pub fn config(&self) -> Option<&RandomizationConfig> {
        self.config.as_ref()
    }

    pub fn into_config(self) -> Option<RandomizationConfig> {
        self.config
    }
}

impl Default for RandomizationSpec {
    fn default() -> Self {
        Self::off()
    }
}

impl fmt::Display for RandomizationSpec {
    fn fmt(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        formatter.write_str(&self.name)
    }
}

impl FromStr for RandomizationSpec {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        Self::parse(text).map_err(|error| error.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_and_flags_name_off_and_the_default_ranges() {
        for off in ["off", "false", "False", "FALSE"] {
            let spec = RandomizationSpec::parse(off).unwrap();
            assert_eq!((spec.name(), spec.config()), (OFF, None), "{off}");
        }
        for on in ["default", "true", "True"] {
            let spec = RandomizationSpec::parse(on).unwrap();
            assert_eq!(spec.name(), DEFAULT, "{on}");
            assert_eq!(spec.config(), Some(&RandomizationConfig::defaults()));
        }
        assert_eq!(
            RandomizationSpec::from_flag(true),
            RandomizationSpec::default_ranges()
        );
        assert_eq!(
            RandomizationSpec::from_flag(false),
            RandomizationSpec::default()
        );
    }

    #[test]
    fn heldout_widens_every_range_and_adds_pictures_and_a_distractor() {
        let defaults = RandomizationConfig::defaults();
        // Its pictures are fetched by scripts/setup.sh, which the test command runs first.
        let spec = RandomizationSpec::parse(HELDOUT).unwrap();
        assert_eq!(spec.name(), HELDOUT);
        let heldout = spec.config().unwrap();
        let wider = |[low, high]: [f64; 2], [d_low, d_high]: [f64; 2]| {
            low <= d_low && high >= d_high && (low, high) != (d_low, d_high)
        };
        assert!(wider(heldout.cube.size_scale, defaults.cube.size_scale));
        assert!(wider(heldout.cube.mass_scale, defaults.cube.mass_scale));
        assert!(wider(
            heldout.lighting.intensity_scale,
            defaults.lighting.intensity_scale
        ));
        assert!(wider(heldout.lighting.ambient, defaults.lighting.ambient));
        assert!(wider(heldout.servos.gain_scale, defaults.servos.gain_scale));
        assert!(wider(heldout.servos.latency, defaults.servos.latency));
        assert!(heldout.cube.colour_jitter > defaults.cube.colour_jitter);
        assert!(heldout.lighting.direction_jitter > defaults.lighting.direction_jitter);
        assert!(heldout.cameras.position_jitter > defaults.cameras.position_jitter);
        assert!(heldout.cameras.fovy_jitter > defaults.cameras.fovy_jitter);
        assert!(heldout.scene.distractor && !defaults.scene.distractor);
        let pictures = heldout.scene.backgrounds.as_ref().unwrap();
        assert!(pictures.join("top").is_dir() && pictures.join("front").is_dir());
    }

    #[test]
    fn a_file_is_read_once_and_named_by_its_path() {
        let dir = std::env::temp_dir().join(format!("so101_randomize_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("ranges.toml");
        std::fs::write(&path, "[observation]\njoint_noise = 0.25\n").unwrap();
        let spec: RandomizationSpec = path.to_str().unwrap().parse().unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(spec.name(), path.display().to_string());
        assert_eq!(spec.config().unwrap().observation.joint_noise, 0.25);
    }

    #[test]
    fn anything_else_names_the_value_and_the_choices() {
        let error = RandomizationSpec::parse("yes").unwrap_err().to_string();
        assert!(
            error.contains("\"yes\"") && error.contains("off") && error.contains(".toml"),
            "{error}"
        );
        let missing = RandomizationSpec::parse("/nonexistent/ranges.toml").unwrap_err();
        assert!(
            missing.to_string().contains("/nonexistent/ranges.toml"),
            "{missing}"
        );
    }
}
