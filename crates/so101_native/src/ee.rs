//! End-effector actions for Python (so101.ee): so101_core::ee_action over N x 6 arrays, the
//! forward kinematics of joint positions and the IK of end-effector targets, one row at a time
//! with the GIL released.

use numpy::{PyArray1, PyArray2, PyReadonlyArray2};
use pyo3::{exceptions::PyValueError, prelude::*};
use so101_core::ee_action::{ee_pose, joint_targets, EePose, EeStep};

fn rows(array: &PyReadonlyArray2<f64>, what: &str) -> PyResult<Vec<EePose>> {
    let view = array.as_array();
    if view.ncols() != 6 {
        return Err(PyValueError::new_err(format!(
            "{what}: an N x 6 array, not {} columns",
            view.ncols()
        )));
    }
    Ok(view
        .rows()
        .into_iter()
        .map(|row| std::array::from_fn(|column| row[column]))
        .collect())
}

fn array<'py>(py: Python<'py>, rows: &[EePose]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let rows: Vec<Vec<f64>> = rows.iter().map(|row| row.to_vec()).collect();
    if rows.is_empty() {
        return Ok(PyArray2::zeros(py, [0, 6], false));
    }
    PyArray2::from_vec2(py, &rows).map_err(|error| PyValueError::new_err(error.to_string()))
}

/// The end-effector state of joint positions (N x 6, rad): x y z (m, the arm's base frame),
/// pitch, roll (rad) and the gripper's joint (rad), N x 6.
#[pyfunction]
pub fn ee_poses<'py>(
    py: Python<'py>,
    joints: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let joints = rows(&joints, "joint positions")?;
    let poses: Vec<EePose> = py.detach(|| joints.iter().map(ee_pose).collect());
    array(py, &poses)
}

/// Joint targets for end-effector targets (N x 6, as `ee_poses` gives them), the IK of each row
/// starting from the same row of `current` (the joint targets in force, N x 6 rad). Returns
/// (targets N x 6 rad inside the joint limits, clamped bool[N]: the target was out of reach and
/// the nearest reachable pose is commanded, position error [N] m, angle error [N] rad).
#[pyfunction]
#[allow(clippy::type_complexity)]
pub fn ee_joint_targets<'py>(
    py: Python<'py>,
    targets: PyReadonlyArray2<'py, f64>,
    current: PyReadonlyArray2<'py, f64>,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<bool>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
)> {
    let targets = rows(&targets, "end-effector targets")?;
    let current = rows(&current, "joint targets in force")?;
    if targets.len() != current.len() {
        return Err(PyValueError::new_err(format!(
            "{} end-effector targets for {} rows of joint targets in force",
            targets.len(),
            current.len()
        )));
    }
    let steps: Vec<EeStep> = py
        .detach(|| {
            targets
                .iter()
                .zip(&current)
                .map(|(target, current)| joint_targets(target, current))
                .collect::<Result<_, _>>()
        })
        .map_err(|error| PyValueError::new_err(error.to_string()))?;
    let joints: Vec<EePose> = steps.iter().map(|step| step.targets).collect();
    Ok((
        array(py, &joints)?,
        PyArray1::from_iter(py, steps.iter().map(|step| step.clamped)),
        PyArray1::from_iter(py, steps.iter().map(|step| step.position_error)),
        PyArray1::from_iter(py, steps.iter().map(|step| step.angle_error)),
    ))
}
