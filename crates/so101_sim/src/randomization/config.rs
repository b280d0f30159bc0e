//! The randomization ranges: assets/randomization.toml (embedded, the defaults) with a user's file
//! over it.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// The project's documented defaults, compiled in so every door has them without a path.
pub const DEFAULT_TOML: &str = include_str!("../../../../assets/randomization.toml");

/// The held-out shift set (assets/randomization_heldout.toml), compiled in; its pictures are
/// fetched at set-up into assets/third_party/heldout_backgrounds.
pub const HELDOUT_TOML: &str = include_str!("../../../../assets/randomization_heldout.toml");

/// A closed interval to draw from uniformly.
pub type Range = [f64; 2];

/// The largest value a range or a jitter may take: far beyond any sensible setting (a scale of a
/// thousand, a metre of camera jitter is already absurd), and small enough that every draw stays
/// finite, also where it is narrowed to f32 for MuJoCo (a file allowing 1e300 gave an infinite light).
pub const MAX_SETTING: f64 = 1e3;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RandomizationConfig {
    pub cube: CubeRanges,
    pub scene: SceneRanges,
    pub lighting: LightingRanges,
    pub cameras: CameraRanges,
    pub servos: ServoRanges,
    pub observation: ObservationNoise,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CubeRanges {
    pub size_scale: Range,
    pub mass_scale: Range,
    pub friction_scale: Range,
    pub colour_jitter: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneRanges {
    pub table_colour_jitter: f64,
    pub bin_colour_jitter: f64,
    /// Real backgrounds: a folder with a folder of pictures per fixed camera (`top/*.jpg`, ...),
    /// one drawn per episode and camera (crate::cameras::backgrounds). Relative to the file
    /// that names it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backgrounds: Option<PathBuf>,
    /// A distractor on the table, seen by the cameras only (no collision): a cylinder of a
    /// random colour beside the cube's area, placed anew each episode.
    #[serde(default)]
    pub distractor: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightingRanges {
    pub direction_jitter: f64,
    pub intensity_scale: Range,
    pub ambient: Range,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraRanges {
    pub position_jitter: f64,
    pub fovy_jitter: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServoRanges {
    pub gain_scale: Range,
    pub damping_scale: Range,
    pub friction_scale: Range,
    pub armature_scale: Range,
    pub latency: Range,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationNoise {
    pub joint_noise: f64,
    pub cube_position_noise: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read the randomization file {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("randomization {path}: {message}")]
    Invalid { path: String, message: String },
    #[error("{0:?} is not a randomization: use off (or false), default (or true), heldout or a file of ranges (.toml)")]
    Choice(String),
}

impl RandomizationConfig {
    /// The defaults of assets/randomization.toml.
    pub fn defaults() -> Self {
        Self::from_toml(DEFAULT_TOML, "defaults").expect("the embedded defaults are valid")
    }

    /// A user's file: its keys over the defaults.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.display().to_string(),
            source,
        })?;
        let name = path.display().to_string();
        Self::from_toml(&text, &name)?.with_backgrounds_from(path.parent(), &name, "")
    }

    /// The held-out shift set: its file's keys over the defaults, its pictures from assets/.
    pub fn heldout() -> Result<Self, ConfigError> {
        let assets = Path::new(so101_core::robot::DEFAULT_SCENE).parent();
        Self::from_toml(HELDOUT_TOML, "heldout")?.with_backgrounds_from(
            assets,
            "heldout",
            " (fetched by scripts/setup.sh: run it, or scripts/fetch_backgrounds.sh)",
        )
    }

    /// `scene.backgrounds` relative to `folder` (the file that names it), and there.
    fn with_backgrounds_from(
        mut self,
        folder: Option<&Path>,
        name: &str,
        hint: &str,
    ) -> Result<Self, ConfigError> {
        if let (Some(backgrounds), Some(folder)) = (&self.scene.backgrounds, folder) {
            self.scene.backgrounds = Some(folder.join(backgrounds));
        }
        if let Some(backgrounds) = &self.scene.backgrounds {
            if !backgrounds.is_dir() {
                return Err(ConfigError::Invalid {
                    path: name.to_owned(),
                    message: format!(
                        "scene.backgrounds: {} is not a folder{hint}",
                        backgrounds.display()
                    ),
                });
            }
        }
        Ok(self)
    }

    pub fn from_toml(text: &str, name: &str) -> Result<Self, ConfigError> {
        let invalid = |message: String| ConfigError::Invalid {
            path: name.to_owned(),
            message,
        };
        let mut merged: toml::Table = DEFAULT_TOML
            .parse()
            .map_err(|error: toml::de::Error| invalid(error.to_string()))?;
        let user: toml::Table = text
            .parse()
            .map_err(|error: toml::de::Error| invalid(error.to_string()))?;
        for (section, values) in user {
            match (merged.get_mut(&section), values) {
                (Some(toml::Value::Table(base)), toml::Value::Table(values)) => base.extend(values),
                _ => return Err(invalid(format!("unknown section [{section}]"))),
            }
        }
        let config: Self = toml::Value::Table(merged)
            .try_into()
            .map_err(|error: toml::de::Error| invalid(error.to_string()))?;
        config.check().map_err(invalid)?;
        Ok(config)
    }

    /// Ranges ordered and finite, scales positive, jitters and noise not negative.
    /// Every range and amount must be finite, not negative and at most [`MAX_SETTING`].
    fn check(&self) -> Result<(), String> {
        let ranges = [
            ("cube.size_scale", self.cube.size_scale, true),
            ("cube.mass_scale", self.cube.mass_scale, true),
            ("cube.friction_scale", self.cube.friction_scale, true),
            (
                "lighting.intensity_scale",
                self.lighting.intensity_scale,
                false,
            ),
            ("lighting.ambient", self.lighting.ambient, false),
            ("servos.gain_scale", self.servos.gain_scale, true),
            ("servos.damping_scale", self.servos.damping_scale, false),
            ("servos.friction_scale", self.servos.friction_scale, false),
            ("servos.armature_scale", self.servos.armature_scale, false),
            ("servos.latency", self.servos.latency, false),
        ];
        for (name, [low, high], positive) in ranges {
            let floor_ok = if positive { low > 0.0 } else { low >= 0.0 };
            if !(low.is_finite() && high <= MAX_SETTING && low <= high && floor_ok) {
                return Err(format!(
                    "{name} = [{low}, {high}] must be finite, low <= high <= {MAX_SETTING}, and low {}",
                    if positive { "> 0" } else { ">= 0" }
                ));
            }
        }
        if self.servos.latency[1] > so101_core::servo::params::MAX_LATENCY {
            return Err("servos.latency above 0.5 s".to_owned());
        }
        let amounts = [
            ("cube.colour_jitter", self.cube.colour_jitter),
            ("scene.table_colour_jitter", self.scene.table_colour_jitter),
            ("scene.bin_colour_jitter", self.scene.bin_colour_jitter),
            ("lighting.direction_jitter", self.lighting.direction_jitter),
            ("cameras.position_jitter", self.cameras.position_jitter),
            ("cameras.fovy_jitter", self.cameras.fovy_jitter),
            ("observation.joint_noise", self.observation.joint_noise),
            (
                "observation.cube_position_noise",
                self.observation.cube_position_noise,
            ),
        ];
        for (name, value) in amounts {
            if !(value.is_finite() && (0.0..=MAX_SETTING).contains(&value)) {
                return Err(format!("{name} = {value} must be from 0 to {MAX_SETTING}"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn huge_ranges_and_jitters_are_refused_not_drawn_to_infinity() {
        // Found by the randomization_toml fuzz target: an ambient range up to about 6.7e84 was
        // accepted, and its draw, narrowed to f32 for MuJoCo, was infinite.
        let error =
            RandomizationConfig::from_toml("[lighting]\nambient = [1.12, 6.6e84]\n", "test")
                .unwrap_err()
                .to_string();
        assert!(
            error.contains("lighting.ambient") && error.contains("1000"),
            "{error}"
        );
        let error = RandomizationConfig::from_toml("[cameras]\nposition_jitter = 1e300\n", "test")
            .unwrap_err()
            .to_string();
        assert!(error.contains("cameras.position_jitter"), "{error}");
        let bytes = b"[lighting]\nambient = [1.12, 66666666666666666666666666666666666666666666666666666666666666666666666666666666666660.40]\n";
        crate::randomization::fuzzing::randomization_toml(bytes);
    }

    #[test]
    fn backgrounds_are_found_from_the_file_that_names_them_or_refused() {
        let dir = std::env::temp_dir().join(format!("so101_ranges_{}", std::process::id()));
        std::fs::create_dir_all(dir.join("stills")).unwrap();
        let file = dir.join("desk.toml");
        std::fs::write(&file, "[scene]\nbackgrounds = \"stills\"\n").unwrap();
        let config = RandomizationConfig::load(&file).unwrap();
        assert_eq!(config.scene.backgrounds, Some(dir.join("stills")));
        std::fs::write(&file, "[scene]\nbackgrounds = \"elsewhere\"\n").unwrap();
        let error = RandomizationConfig::load(&file).unwrap_err().to_string();
        assert!(
            error.contains("elsewhere") && error.contains("not a folder"),
            "{error}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_users_file_overrides_only_its_keys() {
        let config =
            RandomizationConfig::from_toml("[cube]\nmass_scale = [1.0, 2.0]\n", "test").unwrap();
        assert_eq!(config.cube.mass_scale, [1.0, 2.0]);
        assert_eq!(
            config.cube.size_scale,
            RandomizationConfig::defaults().cube.size_scale
        );
    }

    #[test]
    fn bad_files_name_what_is_wrong() {
        let error = |text| {
            RandomizationConfig::from_toml(text, "mine.toml")
                .unwrap_err()
                .to_string()
        };
        assert!(error("[cube]\nmass_scale = [2.0, 1.0]\n").contains("cube.mass_scale"));
        assert!(error("[cube]\nweight = 3\n").contains("weight"));
        assert!(error("[sky]\nblue = 1\n").contains("[sky]"));
        assert!(error("[observation]\njoint_noise = -1.0\n").contains("joint_noise"));
    }
}
