//! One in-process world: a so101_sim task environment behind a Python class.

use std::sync::{Mutex, PoisonError};

use numpy::{PyArray1, PyArray2, PyReadonlyArray1};
use pyo3::{exceptions::PyValueError, prelude::*, types::PyDict};
use so101_core::robot::{JointPositions, JOINT_COUNT};
use so101_sim::{
    env::{SimOptions, TaskEnv, TaskSettings},
    scene,
};

use crate::{
    cameras::{CameraSet, Frames},
    options::WorldOptions,
};

/// How a world is made: the same for one world and for every world of a batch.
#[derive(Debug, Clone)]
pub struct WorldSpec {
    pub scene: String,
    pub options: WorldOptions,
}

impl WorldSpec {
    /// Loads the scene and binds a task environment with the placement sequence of `seed`.
    pub fn build(&self, seed: u64) -> PyResult<TaskEnv> {
        let options = &self.options;
        let mut simulation = scene::load(self.scene.as_ref(), options.lite)
            .map_err(|error| PyValueError::new_err(format!("{error:#}")))?;
        if let Some(placements) = &options.camera_poses {
            placements
                .apply(&mut simulation)
                .map_err(|error| PyValueError::new_err(error.to_string()))?;
        }
        let settings = TaskSettings {
            kind: options.task,
            dense_reward: options.dense_reward,
        };
        let sim_options = SimOptions::from_specs(&options.servo_params, &options.randomize);
        TaskEnv::with_options(
            simulation,
            options.control_rate,
            settings,
            seed,
            sim_options,
        )
        .map_err(|error| PyValueError::new_err(error.to_string()))
    }
}

/// Six finite joint targets from a Python array (rad).
pub fn joint_targets(values: &[f64]) -> PyResult<JointPositions> {
    if values.len() != JOINT_COUNT || !values.iter().all(|value| value.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "an action is {JOINT_COUNT} finite joint targets (rad), not {values:?}"
        )));
    }
    let mut targets = [0.0; JOINT_COUNT];
    targets.copy_from_slice(values);
    Ok(targets)
}

/// (min, max) of each joint in contract order, as the scene declares them (actions are clamped
/// to these).
pub fn limits_array<'py>(py: Python<'py>, env: &TaskEnv) -> Bound<'py, PyArray2<f64>> {
    let rows: Vec<Vec<f64>> = env
        .world()
        .limits()
        .iter()
        .map(|limit| vec![limit.min, limit.max])
        .collect();
    PyArray2::from_vec2(py, &rows).expect("six rows of two")
}

/// The SO-101 cube-to-bin scene in-process: `step(action)` runs one control period with the
/// action's joint targets (clamped to the limits), `reset(seed)` starts an episode (the cube at
/// the next seeded placement, the arm settled at home), `observe()` gives
/// (state float64[19], reward, success). State: joint positions (6, rad), velocities (6, rad/s),
/// cube position (3, m, world) and orientation (4, w x y z).
///
/// Keyword options (WorldBatch's too): lite (the mesh-free scene; default), task, control_rate
/// (Hz; default the policy's control rate), dense_reward, seed, servo_params (a model's name or a
/// so101-sysid parameter file, str or os.PathLike; default the STS3215 model), randomize
/// (True: the default ranges, False, "off", "default" or a file of ranges; default off) and
/// camera_poses (so101-camera-align's file of real camera placements; default None).
#[pyclass(module = "so101_native")]
pub struct World {
    // In a Mutex only so the class is Sync, as PyO3 requires; every method takes `&mut self`
    // (PyO3 checks the borrow), so the lock is never contended and is reached with get_mut.
    inner: Mutex<WorldState>,
}

struct WorldState {
    env: TaskEnv,
    cameras: Option<CameraSet>,
}

impl World {
    fn state(&mut self) -> &mut WorldState {
        self.inner.get_mut().unwrap_or_else(PoisonError::into_inner)
    }
}

#[pymethods]
impl World {
    #[new]
    #[pyo3(signature = (scene, **options))]
    fn new(scene: &str, options: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let spec = WorldSpec {
            scene: scene.to_owned(),
            options: WorldOptions::from_keywords("World", options)?,
        };
        Ok(Self {
            inner: Mutex::new(WorldState {
                env: spec.build(spec.options.seed)?,
                cameras: None,
            }),
        })
    }

    /// Starts an episode; a seed restarts the sequence of cube placements from it. Returns the
    /// cube's start (x, y, yaw).
    #[pyo3(signature = (seed = None))]
    fn reset(&mut self, py: Python<'_>, seed: Option<u64>) -> (f64, f64, f64) {
        let WorldState { env, cameras } = self.state();
        let start = py.detach(|| env.reset(seed));
        if let Some(cameras) = cameras {
            cameras.restart(env.world().time());
        }
        (start.x, start.y, start.yaw)
    }

    /// One control period towards `action` (six joint targets, rad).
    fn step(&mut self, py: Python<'_>, action: PyReadonlyArray1<'_, f64>) -> PyResult<()> {
        let targets = joint_targets(action.as_slice()?)?;
        let env = &mut self.state().env;
        py.detach(|| env.step(&targets));
        Ok(())
    }

    /// (state float64[19], reward, success) of the current instant.
    fn observe<'py>(&mut self, py: Python<'py>) -> (Bound<'py, PyArray1<f64>>, f64, bool) {
        let observation = self.state().env.observe();
        (
            PyArray1::from_slice(py, &observation.state_vector()),
            observation.outcome.reward,
            observation.outcome.success,
        )
    }

    /// Joint efforts (actuator forces, N m) in contract order.
    fn efforts<'py>(&mut self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.state().env.world().arm_state().effort)
    }

    /// Sim time since the world was made (monotonic across episodes), s.
    #[getter]
    fn time(&mut self) -> f64 {
        self.state().env.world().time()
    }

    /// Physics steps since the world was made (settling after resets included).
    #[getter]
    fn physics_steps(&mut self) -> u64 {
        self.state().env.world().total_steps()
    }

    /// Physics divergences so far (MuJoCo reset its state; the episode restarted from its start).
    #[getter]
    fn divergences(&mut self) -> u64 {
        self.state().env.divergences
    }

    /// Puts the arm at rest at these joint positions (6, rad; clamped to the limits), the servos
    /// holding them: a replay starting where a recording started.
    fn place_arm(&mut self, positions: PyReadonlyArray1<f64>) -> PyResult<()> {
        let targets = joint_targets(positions.as_slice()?)?;
        self.state().env.world_mut().place_arm(&targets);
        Ok(())
    }

    /// JSON: the servo model and its parameters, the randomization ranges and the current
    /// episode's draw (null without randomization).
    #[getter]
    fn episode_settings(&mut self) -> String {
        so101_sim::provenance::episode_settings(&self.state().env).to_string()
    }

    /// float64[6, 2]: (min, max) of each joint, rad.
    #[getter]
    fn joint_limits<'py>(&mut self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        limits_array(py, &self.state().env)
    }

    /// Renders these cameras from now on: {name: (height, width)}, names of the scene's cameras
    /// (top, front, wrist). `renderer`: "auto", "egl" or "osmesa".
    #[pyo3(signature = (cameras, renderer = "auto", shadows = false))]
    fn enable_cameras(
        &mut self,
        cameras: Vec<(String, (u32, u32))>,
        renderer: &str,
        shadows: bool,
    ) -> PyResult<()> {
        let state = self.state();
        state.cameras = None;
        state.cameras = Some(CameraSet::start(&state.env, &cameras, renderer, shadows)?);
        Ok(())
    }

    /// {camera: uint8[height, width, 3]} of the current instant (enable_cameras first).
    fn render<'py>(&mut self, py: Python<'py>) -> PyResult<Frames<'py>> {
        let WorldState { env, cameras } = self.state();
        let Some(cameras) = cameras else {
            return Err(PyValueError::new_err(
                "no cameras: call enable_cameras first",
            ));
        };
        let batch = py.detach(|| cameras.capture(env))?;
        cameras.to_python(py, batch)
    }
}
