//! The scripted expert of every task in-process (so101_core::expert, the planner teleop_node's
//! expert source uses), for demonstrations at simulation speed: plan from the settled cube, then
//! each period the joint targets for the arm as measured (the plan waits at its gates for the
//! ramped servos), moved at most `max_step` per period.

use nalgebra::Vector3;
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::{exceptions::PyValueError, prelude::*};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use so101_core::{
    expert::{cube_yaw, ExpertConfig, Plan, SIM_BIN_IN_WORLD},
    kinematics::SIM_BASE_IN_WORLD,
    robot::{follow, JointPositions},
    task::TaskKind,
};

use crate::world::joint_targets;

/// The expert with teleop_node's options: `waypoint_noise` (m) and `action_noise` (rad) are the
/// standard deviations of its noise, drawn from a generator seeded with `seed`; `max_step` (rad)
/// is the largest change of a target in one period; `task` the task it plays ("cube_to_bin", ...).
#[pyclass(module = "so101_native")]
pub struct Expert {
    config: ExpertConfig,
    rng: ChaCha8Rng,
    max_step: f64,
    plan: Option<Plan>,
    last: JointPositions,
}

fn array<const N: usize>(values: &[f64], what: &str) -> PyResult<[f64; N]> {
    <[f64; N]>::try_from(values)
        .ok()
        .filter(|values| values.iter().all(|value| value.is_finite()))
        .ok_or_else(|| PyValueError::new_err(format!("{what}: {N} finite numbers, not {values:?}")))
}

#[pymethods]
impl Expert {
    #[new]
    #[pyo3(signature = (waypoint_noise = 0.0, action_noise = 0.0, seed = 0, max_step = 0.1, task = "cube_to_bin"))]
    fn new(
        waypoint_noise: f64,
        action_noise: f64,
        seed: u64,
        max_step: f64,
        task: &str,
    ) -> PyResult<Self> {
        let task: TaskKind = task.parse().map_err(PyValueError::new_err)?;
        for (name, value) in [
            ("waypoint_noise", waypoint_noise),
            ("action_noise", action_noise),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(PyValueError::new_err(format!("{name} {value}: not >= 0")));
            }
        }
        if !(max_step.is_finite() && max_step > 0.0) {
            return Err(PyValueError::new_err(format!(
                "max_step {max_step}: not > 0"
            )));
        }
        Ok(Self {
            config: ExpertConfig::for_scene(
                Vector3::from(SIM_BASE_IN_WORLD),
                Vector3::from(SIM_BIN_IN_WORLD),
                waypoint_noise,
                action_noise,
            )
            .for_task(task),
            rng: ChaCha8Rng::seed_from_u64(seed),
            max_step,
            plan: None,
            last: [0.0; 6],
        })
    }

    /// Plans a pick-and-place from the arm's joint targets (rad) and the cube's world pose
    /// (position m, orientation w x y z), as /cube/pose gives it. Returns the plan's duration (s);
    /// ValueError when no grasp reaches the cube.
    fn plan(
        &mut self,
        joints: PyReadonlyArray1<'_, f64>,
        cube_position: PyReadonlyArray1<'_, f64>,
        cube_orientation: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<f64> {
        let joints = joint_targets(joints.as_slice()?)?;
        let position: [f64; 3] = array(cube_position.as_slice()?, "cube_position")?;
        let orientation: [f64; 4] = array(cube_orientation.as_slice()?, "cube_orientation")?;
        let in_base = Vector3::from(position) - Vector3::from(SIM_BASE_IN_WORLD);
        let plan = Plan::new(
            &joints,
            in_base,
            cube_yaw(orientation),
            &self.config,
            &mut self.rng,
        )
        .map_err(|error| PyValueError::new_err(error.to_string()))?;
        let duration = plan.duration();
        self.plan = Some(plan);
        self.last = joints;
        Ok(duration)
    }

    /// The joint targets (rad) of the next period of `period` seconds, for the arm at `joints`
    /// (rad, as measured): the plan waits at its gates for the arm (held at its end). The cube's
    /// world pose now (position m, orientation w x y z), when given, is where a regrasp goes.
    #[pyo3(signature = (joints, period, cube_position = None, cube_orientation = None))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        joints: PyReadonlyArray1<'_, f64>,
        period: f64,
        cube_position: Option<PyReadonlyArray1<'_, f64>>,
        cube_orientation: Option<PyReadonlyArray1<'_, f64>>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let measured = joint_targets(joints.as_slice()?)?;
        let cube = match (cube_position, cube_orientation) {
            (Some(position), Some(orientation)) => {
                let position: [f64; 3] = array(position.as_slice()?, "cube_position")?;
                let orientation: [f64; 4] = array(orientation.as_slice()?, "cube_orientation")?;
                let in_base = Vector3::from(position) - Vector3::from(SIM_BASE_IN_WORLD);
                Some((in_base, cube_yaw(orientation)))
            }
            (None, None) => None,
            _ => {
                return Err(PyValueError::new_err(
                    "cube_position and cube_orientation: both or neither",
                ))
            }
        };
        if !(period.is_finite() && period > 0.0) {
            return Err(PyValueError::new_err(format!("period {period}: not > 0")));
        }
        let Some(plan) = &mut self.plan else {
            return Err(PyValueError::new_err("no plan: call plan() after a reset"));
        };
        let wanted = plan.step(period, &measured, cube, &self.config, &mut self.rng);
        self.last = follow(&self.last, &wanted, self.max_step);
        Ok(PyArray1::from_slice(py, &self.last))
    }

    /// The plan has been played to its end (false before a plan).
    #[getter]
    fn finished(&self) -> bool {
        self.plan.as_ref().is_some_and(Plan::finished)
    }

    /// How many times this episode's plan went back up to grasp again (a jaw had landed on the
    /// cube, or the jaws closed on nothing).
    #[getter]
    fn regrasps(&self) -> u32 {
        self.plan.as_ref().map_or(0, Plan::regrasps)
    }
}
