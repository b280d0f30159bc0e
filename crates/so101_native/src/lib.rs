//! `so101_native`: the simulation core (so101_sim) as a Python extension. Worlds step, reset with
//! a seed, observe and render in-process; a batch steps many worlds in one call across threads;
//! the scripted expert plans in-process; end-effector targets become joint targets by the core's IK. The GIL is released while the physics or the renderer
//! works. so101.envs builds the Gymnasium environments on it.

mod batch;
mod cameras;
mod ee;
mod expert;
mod options;
mod sysid;
mod world;

use pyo3::prelude::*;

#[pymodule]
fn so101_native(module: &Bound<'_, PyModule>) -> PyResult<()> {
    module.add_class::<world::World>()?;
    module.add_class::<batch::WorldBatch>()?;
    module.add_class::<expert::Expert>()?;
    module.add("STATE_SIZE", so101_sim::env::STATE_SIZE)?;
    module.add("SETTLE_SECONDS", so101_sim::env::SETTLE_SECONDS)?;
    module.add(
        "EXPERT_SUCCESS_SHOWN_SECONDS",
        so101_core::expert::SUCCESS_SHOWN_SECONDS,
    )?;
    module.add("EXPERT_JUDGE_SECONDS", so101_core::expert::JUDGE_SECONDS)?;
    module.add("EXPERT_GRIPPER_OPEN", so101_core::expert::GRIPPER_OPEN)?;
    module.add("EXPERT_GRIPPER_CLOSED", so101_core::expert::GRIPPER_CLOSED)?;
    // Where the sim puts the arm's base in its world (m): the cube's pose is in the world frame,
    // the forward kinematics' in the base's.
    module.add(
        "SIM_BASE_IN_WORLD",
        so101_core::kinematics::SIM_BASE_IN_WORLD.to_vec(),
    )?;
    module.add_function(wrap_pyfunction!(mujoco_version, module)?)?;
    module.add_function(wrap_pyfunction!(ee::ee_poses, module)?)?;
    module.add_function(wrap_pyfunction!(ee::ee_joint_targets, module)?)?;
    module.add_function(wrap_pyfunction!(scene_xml, module)?)?;
    module.add_function(wrap_pyfunction!(sysid::servo_params_json, module)?)?;
    module.add_function(wrap_pyfunction!(sysid::fit_servos, module)?)?;
    module.add_function(wrap_pyfunction!(sysid::grasp_positions, module)?)?;
    module.add_function(wrap_pyfunction!(sysid::replay_servo_joint, module)?)?;
    Ok(())
}

/// Version of the MuJoCo library the worlds run on ("2.2.2").
#[pyfunction]
fn mujoco_version() -> String {
    so101_sim::mujoco::version()
}

/// The MJCF text of the scene as the worlds load it (its lite variant with `lite`), for stepping
/// the same scene elsewhere (the benchmark's MuJoCo-bindings anchor).
#[pyfunction]
#[pyo3(signature = (scene, lite = true))]
fn scene_xml(scene: &str, lite: bool) -> PyResult<String> {
    let xml = std::fs::read_to_string(scene)
        .map_err(|error| pyo3::exceptions::PyOSError::new_err(format!("{scene}: {error}")))?;
    if !lite {
        return Ok(xml);
    }
    so101_sim::scene::lite_variant(&xml)
        .map_err(|error| pyo3::exceptions::PyValueError::new_err(format!("{scene}: {error}")))
}
