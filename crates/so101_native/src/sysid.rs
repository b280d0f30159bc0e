//! The identification's numerics for `so101-sysid` (python/src/so101/sysid): fitting the servo
//! model per joint (so101_core::servo::identify), the parameter files, and the gripper frame of
//! joint positions (the end-effector error of `compare`).

use numpy::{PyArray2, PyReadonlyArray2};
use pyo3::{exceptions::PyValueError, prelude::*};
use so101_core::{
    kinematics::{grasp_frame, SIM_BASE_IN_WORLD},
    robot::joint_index,
    servo::{
        identify::{fit_joint, JointRecording},
        ArmServoParams, ServoModelChoice, ARM_LOADS,
    },
};

fn arm_params(base: &str) -> PyResult<ArmServoParams> {
    ServoModelChoice::parse_params(base).map_err(|error| PyValueError::new_err(error.to_string()))
}

/// (time, value) rows of an N x 2 array.
fn rows(array: &PyReadonlyArray2<f64>, what: &str) -> PyResult<Vec<(f64, f64)>> {
    let view = array.as_array();
    if view.ncols() != 2 || view.nrows() == 0 || view.iter().any(|value| !value.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "{what}: an N x 2 array of finite (time, value) rows, N > 0"
        )));
    }
    Ok(view
        .rows()
        .into_iter()
        .map(|row| (row[0], row[1]))
        .collect())
}

/// The parameter file of `spec` ("sts3215" or a file), as JSON.
#[pyfunction]
pub fn servo_params_json(spec: &str) -> PyResult<String> {
    Ok(arm_params(spec)?.to_json())
}

/// Fits the servo model of each recorded joint, starting from `base` ("sts3215" or a parameter
/// file): `recordings` is [(joint name, goals N x 2 (s, rad), positions M x 2 (s, rad))]. Returns
/// the parameter file (JSON; joints not recorded keep `base`'s values) and, per joint, (name,
/// RMS replay error before, after (rad), replays run).
#[pyfunction]
#[pyo3(signature = (base, recordings, iterations = 400))]
#[allow(clippy::type_complexity)]
pub fn fit_servos(
    py: Python<'_>,
    base: &str,
    recordings: Vec<(String, PyReadonlyArray2<f64>, PyReadonlyArray2<f64>)>,
    iterations: u64,
) -> PyResult<(String, Vec<(String, f64, f64, u64)>)> {
    let mut params = arm_params(base)?;
    let mut jobs = Vec::new();
    for (name, commands, samples) in &recordings {
        let joint = joint_index(name)
            .ok_or_else(|| PyValueError::new_err(format!("{name:?} is not an SO-101 joint")))?;
        let recording = JointRecording {
            commands: rows(commands, &format!("{name} goals"))?,
            samples: rows(samples, &format!("{name} positions"))?,
        };
        jobs.push((name.clone(), joint, recording));
    }
    let results = py.detach(|| {
        jobs.iter()
            .map(|(name, joint, recording)| {
                fit_joint(&params.0[*joint], ARM_LOADS[*joint], recording, iterations)
                    .map(|fit| (name.clone(), *joint, fit))
            })
            .collect::<Result<Vec<_>, _>>()
    });
    let results =
        results.map_err(|error| PyValueError::new_err(format!("the fit failed: {error}")))?;
    let mut report = Vec::new();
    for (name, joint, fit) in results {
        params.0[joint] = fit.params;
        report.push((name, fit.rms_before, fit.rms_after, fit.evaluations));
    }
    Ok((params.to_json(), report))
}

/// One joint of `spec` ("sts3215" or a parameter file) replaying `goals` (N x 2: s, rad) from
/// rest at `start` (rad): its positions at `times` (s). What `fit_servos` compares to the
/// recording.
#[pyfunction]
pub fn replay_servo_joint<'py>(
    py: Python<'py>,
    spec: &str,
    joint: &str,
    start: f64,
    goals: PyReadonlyArray2<'py, f64>,
    times: Vec<f64>,
) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
    let params = arm_params(spec)?;
    let index = joint_index(joint)
        .ok_or_else(|| PyValueError::new_err(format!("{joint:?} is not an SO-101 joint")))?;
    let goals = rows(&goals, "goals")?;
    let positions =
        so101_core::servo::plant::replay(params.0[index], ARM_LOADS[index], start, &goals, &times);
    Ok(numpy::PyArray1::from_vec(py, positions))
}

/// Gripper frame positions (m, world frame of the sim's scene) of joint positions (N x 6, rad).
#[pyfunction]
pub fn grasp_positions<'py>(
    py: Python<'py>,
    joints: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let view = joints.as_array();
    if view.ncols() != 6 {
        return Err(PyValueError::new_err(
            "joint positions: an N x 6 array (rad)",
        ));
    }
    let rows: Vec<Vec<f64>> = view
        .rows()
        .into_iter()
        .map(|row| {
            let arm = [row[0], row[1], row[2], row[3], row[4]];
            let position = grasp_frame(&arm).translation.vector;
            (0..3)
                .map(|axis| position[axis] + SIM_BASE_IN_WORLD[axis])
                .collect()
        })
        .collect();
    PyArray2::from_vec2(py, &rows).map_err(|error| PyValueError::new_err(error.to_string()))
}
