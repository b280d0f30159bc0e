//! The task environment both front doors step (so101_sim_node over ROS, the Python extension
//! in-process): a world, the task that scores it, and the seeded sequence of cube placements.
//! One source for resets, physics, reward and success, whichever door is used.

use so101_core::{
    expert::{PUSH_TARGET_RADIUS, SIM_PUSH_TARGET_IN_WORLD, SIM_STACK_BASE_IN_WORLD},
    robot::{JointPositions, JOINT_COUNT},
    servo::{ArmServoParams, ServoModelChoice, ServoModelSpec},
};

use crate::{
    cameras::rig::{Cylinder, ViewExtras},
    mujoco::Simulation,
    placement::{CubePlacer, CubeStart, SpawnArea},
    randomization::{
        EpisodeDraw, ObservationNoise, RandomizationConfig, RandomizationSpec, Randomizer,
        SceneLook,
    },
    scene,
    task::{self, TaskKind, TaskOutcome},
    world::{ArmState, CubePose, World, WorldError},
};

/// The distractor of the held-out shift set: a cylinder the size of a cup (m).
pub const DISTRACTOR_RADIUS: f64 = 0.03;
pub const DISTRACTOR_HALF_HEIGHT: f64 = 0.04;

/// push_cube's target as the cameras see it: a white disc on the table, 1 mm thick (a mark, not
/// a body: nothing collides with it).
const PUSH_TARGET_MARK_HALF_HEIGHT: f64 = 0.0005;
const PUSH_TARGET_MARK_RGB: [f32; 3] = [0.92, 0.92, 0.88];

/// Where a reset may put the cube (world frame, m): every point was picked into the bin by a
/// scripted grasp in this scene, and it stays at least 6.5 cm clear of the bin.
pub const CUBE_SPAWN_AREA: SpawnArea = SpawnArea {
    x: (0.18, 0.28),
    y: (-0.08, 0.08),
};

/// Sim time a reset lets the arm settle at home before the episode starts (s): the servos sag
/// under gravity within it (shoulder_lift by ~2 mrad with the STS3215 model, ~6 with gain80), so
/// an episode starts from the pose a recorded one does, not from the model's exact zero.
pub const SETTLE_SECONDS: f64 = 0.3;

/// What the episode is scored by.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TaskSettings {
    pub kind: TaskKind,
    /// The goal tasks (cube_to_bin, lift_cube, place_cube, push_cube, stack_cube): their dense
    /// shaping instead of the sparse reward.
    pub dense_reward: bool,
}

/// Everything observable after a reset or a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Sim time since the environment was made (monotonic across episodes), s.
    pub time: f64,
    pub arm: ArmState,
    pub cube: CubePose,
    pub outcome: TaskOutcome,
}

impl Observation {
    /// The flat vector of the Gymnasium environments: joint positions (6, rad), velocities
    /// (6, rad/s), cube position (3, m, world) and orientation (4, w x y z).
    pub fn state_vector(&self) -> [f64; STATE_SIZE] {
        let mut vector = [0.0; STATE_SIZE];
        vector[..JOINT_COUNT].copy_from_slice(&self.arm.position);
        vector[JOINT_COUNT..2 * JOINT_COUNT].copy_from_slice(&self.arm.velocity);
        vector[2 * JOINT_COUNT..2 * JOINT_COUNT + 3].copy_from_slice(&self.cube.position);
        vector[2 * JOINT_COUNT + 3..].copy_from_slice(&self.cube.orientation);
        vector
    }
}

/// Length of [`Observation::state_vector`].
pub const STATE_SIZE: usize = 2 * JOINT_COUNT + 7;

/// How the simulation departs from the scene as written: the servo model, and the ranges of the
/// domain randomization (none: every episode as the scene is written).
#[derive(Debug, Clone, Default)]
pub struct SimOptions {
    pub servos: ServoModelChoice,
    pub randomization: Option<RandomizationConfig>,
}

impl SimOptions {
    /// The options a user chose (`--servo-params`, `--randomize`, or their Python keywords).
    pub fn from_specs(servos: &ServoModelSpec, randomization: &RandomizationSpec) -> Self {
        Self {
            servos: servos.choice().clone(),
            randomization: randomization.config().cloned(),
        }
    }
}

/// The randomization of an env: its draws, the scene's nominal look and servos, and the current
/// episode's draw and noise.
struct Randomized {
    randomizer: Randomizer,
    look: SceneLook,
    servos: Option<ArmServoParams>,
    draw: Option<EpisodeDraw>,
    noise: Option<ObservationNoise>,
    /// The noise of the current observation: joints (rad) and cube position (m).
    current: ([f64; JOINT_COUNT], [f64; 3]),
}

pub struct TaskEnv {
    world: World,
    settings: TaskSettings,
    placer: CubePlacer,
    randomized: Option<Randomized>,
    /// Physics divergences (MuJoCo reset its state; the episode restarted from its start).
    pub divergences: u64,
}

impl TaskEnv {
    /// Binds the scene at `control_rate` Hz; `seed` starts the sequence of cube placements (a
    /// reset with a seed starts it over).
    pub fn new(
        sim: Simulation,
        control_rate: f64,
        settings: TaskSettings,
        seed: u64,
    ) -> Result<Self, WorldError> {
        Self::with_options(sim, control_rate, settings, seed, SimOptions::default())
    }

    /// As [`TaskEnv::new`], with the servo model (and randomization) of `options`.
    pub fn with_options(
        sim: Simulation,
        control_rate: f64,
        settings: TaskSettings,
        seed: u64,
        options: SimOptions,
    ) -> Result<Self, WorldError> {
        let mut world = World::with_servos(sim, 1.0 / control_rate, options.servos)?;
        if settings.kind == TaskKind::StackCube {
            let [x, y, _] = SIM_STACK_BASE_IN_WORLD;
            world.set_stack_base(Some([x, y]));
        }
        let randomized = options.randomization.map(|config| Randomized {
            randomizer: Randomizer::new(config, seed),
            look: SceneLook::capture(world.simulation()),
            servos: world.servos().params().copied(),
            draw: None,
            noise: None,
            current: ([0.0; JOINT_COUNT], [0.0; 3]),
        });
        Ok(Self {
            world,
            settings,
            placer: CubePlacer::new(CUBE_SPAWN_AREA, seed),
            randomized,
            divergences: 0,
        })
    }

    /// The current episode's randomization draw (none without randomization, or before a reset).
    pub fn draw(&self) -> Option<&EpisodeDraw> {
        self.randomized.as_ref().and_then(|r| r.draw.as_ref())
    }

    /// The folder of real backgrounds the randomization draws from, if any.
    pub fn backgrounds(&self) -> Option<&std::path::Path> {
        self.randomization()?.scene.backgrounds.as_deref()
    }

    /// What the current episode's cameras show beyond the model: push_cube's target, and the
    /// randomization's draw of real backgrounds and its distractor on the table.
    pub fn view_extras(&self) -> ViewExtras {
        let mark = (self.settings.kind == TaskKind::PushCube).then(|| {
            let [x, y, z] = SIM_PUSH_TARGET_IN_WORLD;
            Cylinder {
                centre: [x, y, z + PUSH_TARGET_MARK_HALF_HEIGHT],
                radius: PUSH_TARGET_RADIUS,
                half_height: PUSH_TARGET_MARK_HALF_HEIGHT,
                rgb: PUSH_TARGET_MARK_RGB,
            }
        });
        let Some(draw) = self.draw() else {
            return ViewExtras {
                mark,
                ..ViewExtras::default()
            };
        };
        ViewExtras {
            background: draw.background,
            distractor: draw.distractor.map(|distractor| {
                let [x, y] = distractor.position;
                Cylinder {
                    centre: [x, y, scene::TABLE_TOP_Z + DISTRACTOR_HALF_HEIGHT],
                    radius: DISTRACTOR_RADIUS,
                    half_height: DISTRACTOR_HALF_HEIGHT,
                    rgb: distractor.rgb,
                }
            }),
            mark,
        }
    }

    /// The randomization ranges in use, if any.
    pub fn randomization(&self) -> Option<&RandomizationConfig> {
        self.randomized.as_ref().map(|r| &r.randomizer.config)
    }

    pub fn world(&self) -> &World {
        &self.world
    }

    pub fn world_mut(&mut self) -> &mut World {
        &mut self.world
    }

    pub fn settings(&self) -> TaskSettings {
        self.settings
    }

    /// Dense shaping of cube_to_bin's reward on or off, from the next reward on.
    pub fn set_dense_reward(&mut self, dense: bool) {
        self.settings.dense_reward = dense;
    }

    /// A new episode: the cube at the next placement of the sequence (restarted from `seed` when
    /// given), the arm at home, settled for [`SETTLE_SECONDS`].
    pub fn reset(&mut self, seed: Option<u64>) -> CubeStart {
        if let Some(seed) = seed {
            self.placer = CubePlacer::new(CUBE_SPAWN_AREA, seed);
            if let Some(randomized) = &mut self.randomized {
                randomized.randomizer.reseed(seed);
            }
        }
        let start = self.placer.next_start();
        self.randomize_episode();
        self.world.reset(Some(start));
        self.world.settle(SETTLE_SECONDS);
        self.next_noise();
        start
    }

    /// Draws the next episode's changes and puts them into the world.
    fn randomize_episode(&mut self) {
        let Some(randomized) = &mut self.randomized else {
            return;
        };
        let draw = randomized.randomizer.next_draw(&randomized.look);
        randomized.look.apply(self.world.simulation_mut(), &draw);
        self.world.set_cube_scales(
            draw.cube_size_scale,
            draw.cube_mass_scale,
            draw.cube_friction_scale,
        );
        if let Some(nominal) = randomized.servos {
            self.world.set_servo_params(scaled_servos(&nominal, &draw));
        }
        randomized.noise = Some(ObservationNoise::new(&draw));
        randomized.draw = Some(draw);
    }

    fn next_noise(&mut self) {
        if let Some(randomized) = &mut self.randomized {
            if let Some(noise) = &mut randomized.noise {
                randomized.current = noise.sample();
            }
        }
    }

    /// One control period towards `targets` (clamped to the joint limits; non-finite values keep
    /// the previous target).
    pub fn step(&mut self, targets: &JointPositions) {
        let limits = *self.world.limits();
        let current = self.world.targets_mut();
        for joint in 0..JOINT_COUNT {
            if targets[joint].is_finite() {
                current[joint] = limits[joint].clamp(targets[joint]);
            }
        }
        self.advance();
    }

    /// One control period with the targets as they are; false when the physics diverged.
    pub fn advance(&mut self) -> bool {
        let ok = self.world.advance();
        if !ok {
            self.divergences += 1;
        }
        self.next_noise();
        ok
    }

    /// Reward and success of the current state.
    pub fn outcome(&self) -> TaskOutcome {
        task::evaluate(
            self.settings.kind,
            self.settings.dense_reward,
            &self.world.task_observation(),
        )
    }

    /// What a policy sees: with randomization, joint positions and the cube's position carry
    /// the episode's observation noise (reward and success are of the true state).
    pub fn observe(&self) -> Observation {
        let mut arm = self.world.arm_state();
        let mut cube = self.world.cube_pose();
        if let Some(randomized) = &self.randomized {
            let (joints, position) = randomized.current;
            for (value, noise) in arm.position.iter_mut().zip(joints) {
                *value += noise;
            }
            for (value, noise) in cube.position.iter_mut().zip(position) {
                *value += noise;
            }
        }
        Observation {
            time: self.world.time(),
            arm,
            cube,
            outcome: self.outcome(),
        }
    }
}

/// The nominal servos with one episode's departures.
fn scaled_servos(nominal: &ArmServoParams, draw: &EpisodeDraw) -> ArmServoParams {
    let mut params = *nominal;
    for (servo, change) in params.0.iter_mut().zip(&draw.servos) {
        let mechanics = &mut servo.mechanics;
        mechanics.gain_per_p *= change.gain_scale;
        mechanics.damping_per_d *= change.damping_scale;
        mechanics.damping *= change.damping_scale;
        mechanics.friction *= change.friction_scale;
        mechanics.armature *= change.armature_scale;
        mechanics.latency += change.extra_latency;
    }
    params
}
