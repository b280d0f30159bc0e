//! The simulated SO-101 and its cube-to-bin scene: the bridge between MuJoCo's arrays and the
//! stack's view (joints in contract order, cube pose, task observation).

use nalgebra::{Matrix3, Vector3};
use so101_core::{
    expert::{PUSH_TARGET_RADIUS, SIM_PUSH_TARGET_IN_WORLD},
    robot::{JointLimit, JointPositions, JOINT_COUNT, JOINT_NAMES},
    servo::{ArmServoParams, ServoModelChoice},
};

use crate::{
    mujoco::{MujocoError, ObjectKind, Simulation},
    placement::CubeStart,
    scene::TABLE_TOP_Z,
    servos::ArmServos,
    task::{OrientedBox, StackBase, TaskObservation},
    timing::steps_in_period,
};

#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    #[error(transparent)]
    Mujoco(#[from] MujocoError),
    #[error("the scene has no {kind:?} named {name:?}, which the simulation needs")]
    Missing { kind: ObjectKind, name: String },
    #[error(
        "the control period {period} s is shorter than a physics step ({timestep} s): lower --rate"
    )]
    Period { period: f64, timestep: f64 },
}

/// State of the arm in contract order (rad, rad/s, N m).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ArmState {
    pub position: JointPositions,
    pub velocity: JointPositions,
    pub effort: JointPositions,
}

/// World position and orientation (w, x, y, z) of the cube.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CubePose {
    pub position: [f64; 3],
    pub orientation: [f64; 4],
}

#[derive(Debug, Clone, Copy)]
struct NominalCube {
    rest_height: f64,
    half_extents: [f64; 3],
    mass: f64,
    inertia: [f64; 3],
    friction: [f64; 3],
}

/// Indices into the model, resolved once by name.
struct SceneIds {
    joint_qpos: [usize; JOINT_COUNT],
    joint_dof: [usize; JOINT_COUNT],
    actuator: [usize; JOINT_COUNT],
    cube_body: usize,
    cube_qpos: usize,
    cube_dof: usize,
    cube_geom: usize,
    fixed_jaw_body: usize,
    moving_jaw_body: usize,
    gripper_tip_site: usize,
    cube_site: usize,
    bin_goal_site: usize,
    bin_inside_site: usize,
    /// place_cube's pad; a scene without one offers no place to set the cube down.
    place_pad_site: Option<usize>,
    /// stack_cube's green cube; a scene without one offers nothing to stack on.
    stack_base: Option<StackBaseIds>,
}

/// stack_cube's green cube in the model, and where it stands when parked (the scene's pose).
#[derive(Debug, Clone, Copy)]
struct StackBaseIds {
    body: usize,
    qpos: usize,
    dof: usize,
    geom: usize,
    half_edge: f64,
}

/// The views' group of a shown geom, and of one no view draws (so101_sim::mujoco::render).
const SHOWN_GROUP: i32 = 0;
const HIDDEN_GROUP: i32 = 5;

pub struct World {
    sim: Simulation,
    ids: SceneIds,
    servos: ArmServos,
    limits: [JointLimit; JOINT_COUNT],
    targets: JointPositions,
    timestep: f64,
    control_period: f64,
    cube_rest_height: f64,
    /// The cube as the scene writes it: rest height, half extents, mass, inertia, friction.
    nominal_cube: NominalCube,
    /// Sim time at which the current episode started: MuJoCo restarts its clock at every reset,
    /// but /clock must never go backwards.
    episode_start_time: f64,
    /// Control periods and physics steps done in this episode. Time is counted in steps rather than
    /// summed by MuJoCo, so stamps do not drift by rounding.
    episode_periods: u64,
    episode_steps: u64,
    total_steps: u64,
    /// Where this episode put the cube (`None`: the scene's own pose).
    episode_cube: Option<CubeStart>,
    /// Where every reset stands stack_cube's green cube on the table (x, y; world frame, m);
    /// `None`: parked off the table, drawn in no view.
    stack_base_at: Option<[f64; 2]>,
}

fn stack_base_ids(sim: &Simulation) -> Option<StackBaseIds> {
    let joint = sim.id(ObjectKind::Joint, "stack_base_joint")?;
    let geom = sim.id(ObjectKind::Geom, "stack_base_geom")?;
    Some(StackBaseIds {
        body: sim.id(ObjectKind::Body, "stack_base")?,
        qpos: sim.joint_qpos_address(joint),
        dof: sim.joint_dof_address(joint),
        geom,
        half_edge: sim.geom_size(geom)[2],
    })
}

fn require(sim: &Simulation, kind: ObjectKind, name: &str) -> Result<usize, WorldError> {
    sim.id(kind, name).ok_or_else(|| WorldError::Missing {
        kind,
        name: name.to_owned(),
    })
}

impl World {
    /// Binds the scene with the default servo model (the STS3215): every joint, actuator, site
    /// and body the node uses must exist by name.
    pub fn new(sim: Simulation, control_period: f64) -> Result<Self, WorldError> {
        Self::with_servos(sim, control_period, ServoModelChoice::default())
    }

    /// Binds the scene with the given servo model driving the arm.
    pub fn with_servos(
        mut sim: Simulation,
        control_period: f64,
        servos: ServoModelChoice,
    ) -> Result<Self, WorldError> {
        let timestep = sim.timestep();
        if control_period.is_nan() || control_period < timestep {
            return Err(WorldError::Period {
                period: control_period,
                timestep,
            });
        }
        let mut joint_qpos = [0; JOINT_COUNT];
        let mut joint_dof = [0; JOINT_COUNT];
        let mut actuator = [0; JOINT_COUNT];
        let mut limits = [JointLimit::new(0.0, 0.0); JOINT_COUNT];
        for (index, name) in JOINT_NAMES.iter().enumerate() {
            let joint = require(&sim, ObjectKind::Joint, name)?;
            joint_qpos[index] = sim.joint_qpos_address(joint);
            joint_dof[index] = sim.joint_dof_address(joint);
            actuator[index] = require(&sim, ObjectKind::Actuator, name)?;
            let (min, max) = sim.joint_range(joint);
            limits[index] = JointLimit::new(min, max);
        }
        let cube_joint = require(&sim, ObjectKind::Joint, "cube_joint")?;
        let ids = SceneIds {
            joint_qpos,
            joint_dof,
            actuator,
            cube_body: require(&sim, ObjectKind::Body, "cube")?,
            cube_qpos: sim.joint_qpos_address(cube_joint),
            cube_dof: sim.joint_dof_address(cube_joint),
            cube_geom: require(&sim, ObjectKind::Geom, "cube_geom")?,
            fixed_jaw_body: require(&sim, ObjectKind::Body, "gripper")?,
            moving_jaw_body: require(&sim, ObjectKind::Body, "moving_jaw")?,
            gripper_tip_site: require(&sim, ObjectKind::Site, "gripper_tip")?,
            cube_site: require(&sim, ObjectKind::Site, "cube_site")?,
            bin_goal_site: require(&sim, ObjectKind::Site, "bin_goal")?,
            bin_inside_site: require(&sim, ObjectKind::Site, "bin_inside")?,
            place_pad_site: sim.id(ObjectKind::Site, "place_pad"),
            stack_base: stack_base_ids(&sim),
        };
        let cube_rest_height = sim.qpos()[ids.cube_qpos + 2];
        let (mass, inertia) = sim.body_mass(ids.cube_body);
        let nominal_cube = NominalCube {
            rest_height: cube_rest_height,
            half_extents: sim.geom_size(ids.cube_geom),
            mass,
            inertia,
            friction: sim.geom_friction(ids.cube_geom),
        };
        let servos = ArmServos::install(servos, &mut sim, &ids.actuator, &ids.joint_dof);
        let mut world = Self {
            sim,
            ids,
            servos,
            limits,
            targets: [0.0; JOINT_COUNT],
            timestep,
            control_period,
            cube_rest_height,
            nominal_cube,
            episode_start_time: 0.0,
            episode_periods: 0,
            episode_steps: 0,
            total_steps: 0,
            episode_cube: None,
            stack_base_at: None,
        };
        world.reset(None);
        Ok(world)
    }

    /// The MuJoCo simulation itself (read only), for setting up cameras.
    pub fn simulation(&self) -> &Simulation {
        &self.sim
    }

    /// The MuJoCo simulation itself, for the camera rig (rendering reads the state, never steps).
    pub fn simulation_mut(&mut self) -> &mut Simulation {
        &mut self.sim
    }

    /// The servo model driving the arm.
    pub fn servos(&self) -> &ArmServos {
        &self.servos
    }

    /// Replaces the STS3215 model's parameters (no effect on the gain-80 servos), from the next
    /// physics step on.
    pub fn set_servo_params(&mut self, params: ArmServoParams) {
        if self.servos.params().is_some() {
            self.servos = ArmServos::install(
                ServoModelChoice::Sts3215(Box::new(params)),
                &mut self.sim,
                &self.ids.actuator,
                &self.ids.joint_dof,
            );
        }
    }

    /// The cube scaled from the scene's: edge (`size`), mass and inertia (`mass`), sliding
    /// friction (`friction`). Its rest height follows its size; takes effect at the next reset.
    pub fn set_cube_scales(&mut self, size: f64, mass: f64, friction: f64) {
        let nominal = self.nominal_cube;
        let half = nominal.half_extents.map(|value| value * size);
        self.sim.set_geom_size(self.ids.cube_geom, half);
        // A uniform box: inertia grows with mass and with the square of the size.
        let inertia = nominal.inertia.map(|value| value * mass * size * size);
        self.sim
            .set_body_mass(self.ids.cube_body, nominal.mass * mass, inertia);
        let mut sliding = nominal.friction;
        sliding[0] *= friction;
        self.sim.set_geom_friction(self.ids.cube_geom, sliding);
        self.cube_rest_height = nominal.rest_height + (half[2] - nominal.half_extents[2]);
    }

    /// Stands stack_cube's green cube at (x, y) on the table, now and at every reset, and shows
    /// it; `None`: from the next reset it stays parked off the table, hidden (every other task).
    /// Without the cube in the scene, nothing changes.
    pub fn set_stack_base(&mut self, at: Option<[f64; 2]>) {
        let Some(ids) = self.ids.stack_base else {
            return;
        };
        self.stack_base_at = at;
        let group = if at.is_some() {
            SHOWN_GROUP
        } else {
            HIDDEN_GROUP
        };
        self.sim.set_geom_group(ids.geom, group);
        // Standing from now on, not only from the next reset: the sim node's first episode
        // starts without one.
        self.stand_stack_base();
        self.sim.forward();
    }

    /// Puts stack_cube's green cube, at rest, where [`World::set_stack_base`] stands it.
    fn stand_stack_base(&mut self) {
        let (Some(ids), Some([x, y])) = (self.ids.stack_base, self.stack_base_at) else {
            return;
        };
        let standing = [x, y, TABLE_TOP_Z + ids.half_edge, 1.0, 0.0, 0.0, 0.0];
        self.sim.qpos_mut()[ids.qpos..ids.qpos + 7].copy_from_slice(&standing);
        self.sim.qvel_mut()[ids.dof..ids.dof + 6].fill(0.0);
    }

    /// Joint limits as the scene declares them (commands are clamped to these).
    pub fn limits(&self) -> &[JointLimit; JOINT_COUNT] {
        &self.limits
    }

    pub fn targets_mut(&mut self) -> &mut JointPositions {
        &mut self.targets
    }

    /// Sim time since the world was created (monotonic across episodes).
    pub fn time(&self) -> f64 {
        self.episode_start_time + self.episode_steps as f64 * self.timestep
    }

    pub fn timestep(&self) -> f64 {
        self.timestep
    }

    /// Sim time at which the next [`World::advance`] ends: whole physics steps, so the period's
    /// length is the rounded one the world runs (at 30 Hz on 2 ms steps, 32 or 34 ms), not 1/rate.
    pub fn period_end(&self) -> f64 {
        let steps = steps_in_period(self.episode_periods, self.control_period, self.timestep);
        self.episode_start_time + (self.episode_steps + steps) as f64 * self.timestep
    }

    /// Physics steps since the world was created.
    pub fn total_steps(&self) -> u64 {
        self.total_steps
    }

    /// Starts a new episode: arm at home (all joints 0) and holding there, the cube at `cube` (or
    /// where the scene puts it). Sim time goes on from where the last episode ended.
    pub fn reset(&mut self, cube: Option<CubeStart>) {
        self.episode_cube = cube;
        self.episode_start_time = self.time();
        self.episode_periods = 0;
        self.episode_steps = 0;
        self.sim.reset();
        self.targets = [0.0; JOINT_COUNT];
        if let Some(start) = cube {
            let qpos = self.sim.qpos_mut();
            let base = self.ids.cube_qpos;
            qpos[base] = start.x;
            qpos[base + 1] = start.y;
            qpos[base + 2] = self.cube_rest_height;
            qpos[base + 3..base + 7].copy_from_slice(&start.quaternion());
        }
        let cube_dof = self.ids.cube_dof;
        self.sim.qvel_mut()[cube_dof..cube_dof + 6].fill(0.0);
        self.stand_stack_base();
        self.servos.hold(&self.targets);
        self.write_controls();
        self.sim.forward();
    }

    /// Puts the arm at `positions` at rest, the servos holding them (a replay starting where a
    /// recording did). Positions outside the limits are clamped.
    pub fn place_arm(&mut self, positions: &JointPositions) {
        let mut placed = *positions;
        for (joint, position) in placed.iter_mut().enumerate() {
            *position = self.limits[joint].clamp(*position);
        }
        for (joint, position) in placed.iter().enumerate() {
            self.sim.qpos_mut()[self.ids.joint_qpos[joint]] = *position;
            self.sim.qvel_mut()[self.ids.joint_dof[joint]] = 0.0;
        }
        self.targets = placed;
        self.servos.hold(&placed);
        self.write_controls();
        self.sim.forward();
    }

    /// Lets the physics run `seconds` (whole physics steps) with the current targets, before the
    /// episode's first control period: the control periods that follow keep their length.
    pub fn settle(&mut self, seconds: f64) {
        let steps = (seconds / self.timestep).round().max(0.0) as u64;
        self.write_controls();
        self.physics_steps(steps);
        self.sim.refresh_kinematics();
    }

    /// Advances one control period with the current targets. Returns false when the physics
    /// diverged: MuJoCo then resets its state to the model's initial one by itself (and restarts its
    /// clock, which is how this notices), and the episode is restarted from its own cube pose so
    /// the seeded episode is not silently replaced by the scene's default.
    pub fn advance(&mut self) -> bool {
        self.write_controls();
        let steps = steps_in_period(self.episode_periods, self.control_period, self.timestep);
        self.physics_steps(steps);
        self.episode_periods += 1;
        // Poses (/cube/pose, the task's sites, camera frames) of the state published, not of the
        // one before the last step's integration.
        self.sim.refresh_kinematics();
        let expected_time = self.episode_steps as f64 * self.timestep;
        if (self.sim.time() - expected_time).abs() <= 0.5 * self.timestep {
            return true;
        }
        let targets = self.targets;
        self.reset(self.episode_cube);
        self.targets = targets;
        false
    }

    /// `steps` physics steps; the STS3215 model recomputes its torques before each. Counts them
    /// in the episode's and the world's totals.
    fn physics_steps(&mut self, steps: u64) {
        for _ in 0..steps {
            if self.servos.per_step() {
                self.write_servo_torques();
            }
            self.sim.step();
            self.episode_steps += 1;
        }
        self.total_steps += steps;
    }

    /// Sends the targets to the servos (at the episode's time) and writes the controls.
    fn write_controls(&mut self) {
        let time = self.episode_steps as f64 * self.timestep;
        self.servos.command(time, &self.targets);
        if self.servos.per_step() {
            self.write_servo_torques();
        } else {
            self.write_ctrl(self.targets);
        }
    }

    fn write_servo_torques(&mut self) {
        let time = self.episode_steps as f64 * self.timestep;
        let arm = self.arm_state();
        let torques = self.servos.controls(
            time,
            &self.targets,
            &arm.position,
            &arm.velocity,
            self.timestep,
        );
        self.write_ctrl(torques);
    }

    fn write_ctrl(&mut self, values: JointPositions) {
        let actuator = self.ids.actuator;
        let ctrl = self.sim.ctrl_mut();
        for joint in 0..JOINT_COUNT {
            ctrl[actuator[joint]] = values[joint];
        }
    }

    pub fn arm_state(&self) -> ArmState {
        let qpos = self.sim.qpos();
        let qvel = self.sim.qvel();
        let force = self.sim.actuator_force();
        let mut state = ArmState::default();
        for joint in 0..JOINT_COUNT {
            state.position[joint] = qpos[self.ids.joint_qpos[joint]];
            state.velocity[joint] = qvel[self.ids.joint_dof[joint]];
            state.effort[joint] = force[self.ids.actuator[joint]];
        }
        state
    }

    pub fn cube_pose(&self) -> CubePose {
        let (position, orientation) = self.sim.body_pose(self.ids.cube_body);
        CubePose {
            position,
            orientation,
        }
    }

    pub fn task_observation(&self) -> TaskObservation {
        let vector = |site| Vector3::from(self.sim.site_position(site));
        let (mut fixed_jaw_contact, mut moving_jaw_contact) = (false, false);
        for (first, second) in self.sim.contacts() {
            let other = match (first == self.ids.cube_geom, second == self.ids.cube_geom) {
                (true, false) => second,
                (false, true) => first,
                _ => continue,
            };
            let body = self.sim.geom_body(other);
            fixed_jaw_contact |= body == self.ids.fixed_jaw_body;
            moving_jaw_contact |= body == self.ids.moving_jaw_body;
        }
        let region = |site| OrientedBox {
            center: vector(site),
            rotation: Matrix3::from_row_slice(&self.sim.site_rotation(site)),
            half_extents: Vector3::from(self.sim.site_size(site)),
        };
        TaskObservation {
            gripper_tip: vector(self.ids.gripper_tip_site),
            cube: vector(self.ids.cube_site),
            cube_rest_height: self.cube_rest_height,
            bin_goal: vector(self.ids.bin_goal_site),
            bin_inside: region(self.ids.bin_inside_site),
            place_pad: self.ids.place_pad_site.map_or(OrientedBox::EMPTY, region),
            push_target: Vector3::from(SIM_PUSH_TARGET_IN_WORLD),
            push_target_radius: PUSH_TARGET_RADIUS,
            stack_base: self.ids.stack_base.map(|ids| StackBase {
                centre: Vector3::from(self.sim.body_pose(ids.body).0),
                rest_height: TABLE_TOP_Z + ids.half_edge,
                half_edge: ids.half_edge,
            }),
            fixed_jaw_contact,
            moving_jaw_contact,
        }
    }
}
