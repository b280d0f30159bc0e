//! A batch of in-process worlds stepped in one call, spread over a thread pool with the GIL
//! released: the native side of `gym.make_vec("so101/...", num_envs=N)`.

use std::sync::{Mutex, PoisonError};

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::{
    exceptions::{PyIndexError, PyValueError},
    prelude::*,
    types::{PyDict, PyList},
};
use rayon::prelude::*;
use so101_core::robot::{JointPositions, JOINT_COUNT};
use so101_sim::env::{TaskEnv, STATE_SIZE};

use crate::{
    cameras::CameraSet,
    options::WorldOptions,
    world::{joint_targets, limits_array, WorldSpec},
};

/// N worlds of the same scene and task. World i's placements start from seed + i unless reset
/// with a seed of its own.
#[pyclass(module = "so101_native")]
pub struct WorldBatch {
    // In a Mutex only so the class is Sync, as PyO3 requires (see world::World).
    inner: Mutex<BatchState>,
}

struct BatchState {
    envs: Vec<TaskEnv>,
    cameras: Vec<CameraSet>,
    pool: rayon::ThreadPool,
}

impl WorldBatch {
    fn state(&mut self) -> &mut BatchState {
        self.inner.get_mut().unwrap_or_else(PoisonError::into_inner)
    }
}

#[pymethods]
impl WorldBatch {
    /// `threads`: worker threads stepping the worlds (0: one per CPU core); the other options are
    /// World's.
    #[new]
    #[pyo3(signature = (num_worlds, scene, *, threads = 0, **options))]
    fn new(
        num_worlds: usize,
        scene: &str,
        threads: usize,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        if num_worlds == 0 {
            return Err(PyValueError::new_err("a batch needs at least one world"));
        }
        let spec = WorldSpec {
            scene: scene.to_owned(),
            options: WorldOptions::from_keywords("WorldBatch", options)?,
        };
        let seed = spec.options.seed;
        let envs = (0..num_worlds as u64)
            .map(|index| spec.build(seed.wrapping_add(index)))
            .collect::<PyResult<Vec<_>>>()?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|index| format!("so101-world-{index}"))
            .build()
            .map_err(|error| PyValueError::new_err(error.to_string()))?;
        Ok(Self {
            inner: Mutex::new(BatchState {
                envs,
                cameras: Vec::new(),
                pool,
            }),
        })
    }

    fn __len__(&mut self) -> usize {
        self.state().envs.len()
    }

    /// Starts a new episode in world `index` (a seed restarts its placement sequence).
    #[pyo3(signature = (index, seed = None))]
    fn reset(&mut self, py: Python<'_>, index: usize, seed: Option<u64>) -> PyResult<()> {
        let envs = &mut self.state().envs;
        let count = envs.len();
        let env = envs
            .get_mut(index)
            .ok_or_else(|| PyIndexError::new_err(format!("world {index} of {count}")))?;
        py.detach(|| env.reset(seed));
        Ok(())
    }

    /// JSON of world `index`'s current episode: servo model and parameters, randomization ranges
    /// and draw (as World.episode_settings).
    fn episode_settings(&mut self, index: usize) -> PyResult<String> {
        let envs = &self.state().envs;
        let env = envs
            .get(index)
            .ok_or_else(|| PyIndexError::new_err(format!("world {index} of {}", envs.len())))?;
        Ok(so101_sim::provenance::episode_settings(env).to_string())
    }

    /// Starts a new episode in every world, in parallel; `seeds` (one per world) restart their
    /// placement sequences.
    #[pyo3(signature = (seeds = None))]
    fn reset_all(&mut self, py: Python<'_>, seeds: Option<Vec<u64>>) -> PyResult<()> {
        let BatchState { envs, pool, .. } = self.state();
        let seeds: Vec<Option<u64>> = match seeds {
            None => vec![None; envs.len()],
            Some(seeds) if seeds.len() == envs.len() => seeds.into_iter().map(Some).collect(),
            Some(seeds) => {
                return Err(PyValueError::new_err(format!(
                    "{} seeds for {} worlds",
                    seeds.len(),
                    envs.len()
                )))
            }
        };
        py.detach(|| {
            pool.install(|| {
                envs.par_iter_mut().zip(seeds).for_each(|(env, seed)| {
                    env.reset(seed);
                })
            })
        });
        Ok(())
    }

    /// One control period in every world (those `active` marks, when given): `actions`
    /// float64[N, 6], joint targets (rad).
    #[pyo3(signature = (actions, active = None))]
    fn step(
        &mut self,
        py: Python<'_>,
        actions: PyReadonlyArray2<'_, f64>,
        active: Option<Vec<bool>>,
    ) -> PyResult<()> {
        let BatchState { envs, pool, .. } = self.state();
        let active = active.unwrap_or_else(|| vec![true; envs.len()]);
        if active.len() != envs.len() {
            return Err(PyValueError::new_err(format!(
                "{} active flags for {} worlds",
                active.len(),
                envs.len()
            )));
        }
        let shape = actions.shape();
        if shape != [envs.len(), JOINT_COUNT] {
            return Err(PyValueError::new_err(format!(
                "actions of shape {shape:?}, expected [{}, {JOINT_COUNT}]",
                envs.len()
            )));
        }
        let targets: Vec<JointPositions> = actions
            .as_slice()?
            .chunks_exact(JOINT_COUNT)
            .map(joint_targets)
            .collect::<PyResult<_>>()?;
        py.detach(|| {
            pool.install(|| {
                envs.par_iter_mut()
                    .zip(targets.par_iter())
                    .zip(active.par_iter())
                    .filter(|(_, active)| **active)
                    .for_each(|((env, targets), _)| env.step(targets))
            })
        });
        Ok(())
    }

    /// (states float64[N, 19], rewards float64[N], successes bool[N]).
    #[allow(clippy::type_complexity)]
    fn observe<'py>(
        &mut self,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<bool>>,
    )> {
        let envs = &self.state().envs;
        let mut states = Vec::with_capacity(envs.len() * STATE_SIZE);
        let mut rewards = Vec::with_capacity(envs.len());
        let mut successes = Vec::with_capacity(envs.len());
        for env in envs {
            let observation = env.observe();
            states.extend_from_slice(&observation.state_vector());
            rewards.push(observation.outcome.reward);
            successes.push(observation.outcome.success);
        }
        Ok((
            PyArray1::from_vec(py, states).reshape([envs.len(), STATE_SIZE])?,
            PyArray1::from_vec(py, rewards),
            PyArray1::from_vec(py, successes),
        ))
    }

    /// float64[6, 2]: (min, max) of each joint, rad.
    #[getter]
    fn joint_limits<'py>(&mut self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        limits_array(py, &self.state().envs[0])
    }

    /// Renders these cameras in every world from now on (one render thread per world).
    #[pyo3(signature = (cameras, renderer = "auto", shadows = false))]
    fn enable_cameras(
        &mut self,
        cameras: Vec<(String, (u32, u32))>,
        renderer: &str,
        shadows: bool,
    ) -> PyResult<()> {
        let state = self.state();
        state.cameras.clear();
        for env in &state.envs {
            state
                .cameras
                .push(CameraSet::start(env, &cameras, renderer, shadows)?);
        }
        Ok(())
    }

    /// [{camera: uint8[height, width, 3]}] of every world at the current instant, rendered by
    /// the worlds' render threads at once.
    fn render<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let BatchState { envs, cameras, .. } = self.state();
        if cameras.is_empty() {
            return Err(PyValueError::new_err(
                "no cameras: call enable_cameras first",
            ));
        }
        let batches = py.detach(|| {
            cameras
                .iter_mut()
                .zip(envs.iter_mut())
                .map(|(set, env)| set.request(env))
                .collect::<Vec<_>>()
                .into_iter()
                .zip(cameras.iter())
                .map(|(requested, set)| requested.and_then(|()| set.receive()))
                .collect::<PyResult<Vec<_>>>()
        })?;
        let frames = PyList::empty(py);
        for (set, batch) in cameras.iter().zip(batches) {
            frames.append(set.to_python(py, batch)?)?;
        }
        Ok(frames)
    }
}
