//! The keyword options of World and WorldBatch: one signature for both, each default written once
//! (here), each value taken as a Python user writes it.

use std::path::PathBuf;

use pyo3::{
    exceptions::{PyTypeError, PyValueError},
    prelude::*,
    types::PyDict,
};
use so101_core::{
    servo::{ServoModelSpec, GAIN80, STS3215},
    task::{TaskKind, CONTROL_RATE_HZ},
};
use so101_sim::{
    cameras::placement::CameraPlacements,
    randomization::{
        spec::{DEFAULT, OFF},
        RandomizationSpec,
    },
};

/// How every world of a World or WorldBatch is made, besides its scene.
#[derive(Debug, Clone)]
pub struct WorldOptions {
    /// The mesh-free variant of the scene.
    pub lite: bool,
    pub task: TaskKind,
    /// Control periods per second of sim time (Hz).
    pub control_rate: f64,
    pub dense_reward: bool,
    /// The first world's seed of cube placements.
    pub seed: u64,
    /// A model's name or a parameter file (.json; str or os.PathLike).
    pub servo_params: ServoModelSpec,
    /// True (the default ranges), False, "off", "default" or a file of ranges (.toml; str or
    /// os.PathLike).
    pub randomize: RandomizationSpec,
    /// Where the user's real cameras stand (so101-camera-align's file; str or os.PathLike), or
    /// None: the scene's own placements.
    pub camera_poses: Option<CameraPlacements>,
}

impl Default for WorldOptions {
    fn default() -> Self {
        Self {
            lite: true,
            task: TaskKind::CubeToBin,
            control_rate: CONTROL_RATE_HZ,
            dense_reward: false,
            seed: 0,
            servo_params: ServoModelSpec::default(),
            randomize: RandomizationSpec::off(),
            camera_poses: None,
        }
    }
}

impl WorldOptions {
    /// The defaults with a constructor's keyword arguments over them; `class` names the
    /// constructor in errors. A name that is no option is a TypeError, as Python's own are.
    pub fn from_keywords(class: &str, keywords: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut options = Self::default();
        for (key, value) in keywords.into_iter().flat_map(|keywords| keywords.iter()) {
            let key: String = key.extract()?;
            let taken = match key.as_str() {
                "lite" => value.extract().map(|lite| options.lite = lite),
                "task" => task(&value).map(|task| options.task = task),
                "control_rate" => control_rate(&value).map(|rate| options.control_rate = rate),
                "dense_reward" => value.extract().map(|dense| options.dense_reward = dense),
                "seed" => value.extract().map(|seed| options.seed = seed),
                "servo_params" => servo_model(&value).map(|model| options.servo_params = model),
                "randomize" => randomization(&value).map(|spec| options.randomize = spec),
                "camera_poses" => camera_placements(&value).map(|file| options.camera_poses = file),
                _ => {
                    return Err(PyTypeError::new_err(format!(
                        "{class}() got an unexpected keyword argument '{key}'"
                    )))
                }
            };
            taken.map_err(|error| in_argument(value.py(), class, &key, &error))?;
        }
        Ok(options)
    }
}

/// `error` of argument `key`, said so (of the same type: TypeError, ValueError, ...).
fn in_argument(py: Python<'_>, class: &str, key: &str, error: &PyErr) -> PyErr {
    let message = format!("{class}() argument '{key}': {}", error.value(py));
    if error.is_instance_of::<PyValueError>(py) {
        PyValueError::new_err(message)
    } else {
        PyTypeError::new_err(message)
    }
}

fn type_name(value: &Bound<'_, PyAny>) -> String {
    value
        .get_type()
        .name()
        .map_or_else(|_| "?".to_owned(), |name| name.to_string())
}

fn task(value: &Bound<'_, PyAny>) -> PyResult<TaskKind> {
    value
        .extract::<String>()?
        .parse()
        .map_err(PyValueError::new_err)
}

fn control_rate(value: &Bound<'_, PyAny>) -> PyResult<f64> {
    let rate: f64 = value.extract()?;
    if rate.is_finite() && rate > 0.0 {
        Ok(rate)
    } else {
        Err(PyValueError::new_err(format!(
            "{rate} is not a positive rate in Hz"
        )))
    }
}

/// A model's name (str) or a parameter file (str or os.PathLike), its file read now.
fn servo_model(value: &Bound<'_, PyAny>) -> PyResult<ServoModelSpec> {
    let spec = if let Ok(text) = value.extract::<String>() {
        ServoModelSpec::parse(&text)
    } else if let Ok(path) = value.extract::<PathBuf>() {
        ServoModelSpec::load(&path)
    } else {
        return Err(PyTypeError::new_err(format!(
            "a servo model's name ({STS3215:?}, {GAIN80:?}) or a parameter file (str or \
             os.PathLike), not {}",
            type_name(value)
        )));
    };
    spec.map_err(|error| PyValueError::new_err(error.to_string()))
}

/// A flag (True: the default ranges), a word (str) or a file of ranges (str or os.PathLike), its
/// file read now.
fn randomization(value: &Bound<'_, PyAny>) -> PyResult<RandomizationSpec> {
    let spec = if let Ok(on) = value.extract::<bool>() {
        Ok(RandomizationSpec::from_flag(on))
    } else if let Ok(text) = value.extract::<String>() {
        RandomizationSpec::parse(&text)
    } else if let Ok(path) = value.extract::<PathBuf>() {
        RandomizationSpec::load(&path)
    } else {
        return Err(PyTypeError::new_err(format!(
            "True, False, {OFF:?}, {DEFAULT:?} or a file of ranges (str or os.PathLike), not {}",
            type_name(value)
        )));
    };
    spec.map_err(|error| PyValueError::new_err(error.to_string()))
}

/// None, or a camera placements file (str or os.PathLike), read now.
fn camera_placements(value: &Bound<'_, PyAny>) -> PyResult<Option<CameraPlacements>> {
    if value.is_none() {
        return Ok(None);
    }
    let path: PathBuf = value.extract().map_err(|_| {
        PyTypeError::new_err(format!(
            "None or a file of camera placements (str or os.PathLike), not {}",
            type_name(value)
        ))
    })?;
    CameraPlacements::load(&path)
        .map(Some)
        .map_err(|error| PyValueError::new_err(error.to_string()))
}
