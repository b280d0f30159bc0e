//! The tasks as facts: what every front door (the sim node, the in-process envs, Gymnasium,
//! LeRobot's env type, so101-run-policy, the learning recipes) needs to know about a task, written
//! once here and generated into python/src/so101/contract.py. How a task is scored lives in the
//! simulation core (so101_sim::task); a new task is a variant here, its facts, and its scoring
//! there.

use clap::builder::PossibleValue;

/// The control rate of a policy and of teleoperated demonstrations (Hz): one action and one
/// observation per period, a dataset's fps, every task's default. Not the rates underneath it: the
/// sim node's physics periods, teleop's command stream and the driver's bus cycles each have their
/// own (so101_sim_node, teleop_node, so101_feetech_driver).
pub const CONTROL_RATE_HZ: f64 = 30.0;

/// Which task the episode scores.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TaskKind {
    /// Dense: reward is minus the distance from the gripper tip to the cube.
    TouchCube,
    /// Sparse: reward 1 while the gripper touches the cube.
    TouchCubeSparse,
    /// Sparse: reward 1 once the cube lies in the bin (optional dense shaping).
    CubeToBin,
    /// Sparse: reward 1 while the cube is held in both jaws, lifted (optional dense shaping).
    LiftCube,
    /// Sparse: reward 1 once the cube rests on the pad, let go (optional dense shaping).
    PlaceCube,
    /// Sparse: reward 1 once the cube rests on the marked target, pushed along the table
    /// (optional dense shaping).
    PushCube,
    /// Sparse: reward 1 once the cube rests on top of the second cube, let go (optional dense
    /// shaping).
    StackCube,
}

/// How a task's reward is given.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RewardMode {
    /// 1 when the goal holds, else 0.
    Sparse,
    /// A continuous measure of progress (a distance, or staged shaping).
    Dense,
}

impl RewardMode {
    pub const fn name(self) -> &'static str {
        match self {
            Self::Sparse => "sparse",
            Self::Dense => "dense",
        }
    }
}

/// Everything a front door needs to offer a task.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskFacts {
    /// The name on every command line and in every config ("cube_to_bin").
    pub name: &'static str,
    /// The Gymnasium id of the in-process environment.
    pub gym_id: &'static str,
    /// The task text of a LeRobot dataset's episodes.
    pub description: &'static str,
    /// Steps of an episode at [`TaskFacts::control_rate_hz`] unless the user says otherwise.
    pub episode_steps: u32,
    /// Whether success ends the episode (Gymnasium's `terminated`).
    pub terminates_on_success: bool,
    /// The reward modes the task offers; the first is its default.
    pub reward_modes: &'static [RewardMode],
    /// Its default control rate (Hz).
    pub control_rate_hz: f64,
    /// One line for `--help`.
    pub help: &'static str,
}

impl TaskKind {
    /// Every task, in the order the command lines list them.
    pub const ALL: [TaskKind; 7] = [
        Self::CubeToBin,
        Self::LiftCube,
        Self::PlaceCube,
        Self::PushCube,
        Self::StackCube,
        Self::TouchCube,
        Self::TouchCubeSparse,
    ];

    pub const fn facts(self) -> &'static TaskFacts {
        match self {
            Self::CubeToBin => &CUBE_TO_BIN,
            Self::TouchCube => &TOUCH_CUBE,
            Self::TouchCubeSparse => &TOUCH_CUBE_SPARSE,
            Self::LiftCube => &LIFT_CUBE,
            Self::PlaceCube => &PLACE_CUBE,
            Self::PushCube => &PUSH_CUBE,
            Self::StackCube => &STACK_CUBE,
        }
    }

    pub fn name(self) -> &'static str {
        self.facts().name
    }

    /// The task of a name, also with dashes for underscores ("cube-to-bin").
    pub fn from_name(name: &str) -> Option<Self> {
        let name = name.replace('-', "_");
        Self::ALL.into_iter().find(|kind| kind.name() == name)
    }
}

const CUBE_TO_BIN: TaskFacts = TaskFacts {
    name: "cube_to_bin",
    gym_id: "so101/CubeToBin-v0",
    description: "put the cube in the bin",
    episode_steps: 600,
    terminates_on_success: true,
    reward_modes: &[RewardMode::Sparse, RewardMode::Dense],
    control_rate_hz: CONTROL_RATE_HZ,
    help: "sparse: reward 1 once the cube lies in the bin (dense: staged shaping)",
};

const LIFT_CUBE: TaskFacts = TaskFacts {
    name: "lift_cube",
    gym_id: "so101/LiftCube-v0",
    description: "lift the cube",
    episode_steps: 300,
    terminates_on_success: true,
    reward_modes: &[RewardMode::Sparse, RewardMode::Dense],
    control_rate_hz: CONTROL_RATE_HZ,
    help: "sparse: reward 1 once the cube is held in both jaws 5 cm above the table (dense: staged shaping)",
};

const PLACE_CUBE: TaskFacts = TaskFacts {
    name: "place_cube",
    gym_id: "so101/PlaceCube-v0",
    description: "place the cube on the pad",
    episode_steps: 600,
    terminates_on_success: true,
    reward_modes: &[RewardMode::Sparse, RewardMode::Dense],
    control_rate_hz: CONTROL_RATE_HZ,
    help: "sparse: reward 1 once the cube rests on the pad left of the arm, let go (dense: staged shaping)",
};

const PUSH_CUBE: TaskFacts = TaskFacts {
    name: "push_cube",
    gym_id: "so101/PushCube-v0",
    description: "push the cube onto the target",
    episode_steps: 600,
    terminates_on_success: true,
    reward_modes: &[RewardMode::Sparse, RewardMode::Dense],
    control_rate_hz: CONTROL_RATE_HZ,
    help: "sparse: reward 1 once the cube rests on the round target left of the cube's area, not held (dense: approach, then the cube's distance to the target)",
};

const STACK_CUBE: TaskFacts = TaskFacts {
    name: "stack_cube",
    gym_id: "so101/StackCube-v0",
    description: "stack the red cube on the green cube",
    episode_steps: 600,
    terminates_on_success: true,
    reward_modes: &[RewardMode::Sparse, RewardMode::Dense],
    control_rate_hz: CONTROL_RATE_HZ,
    help: "sparse: reward 1 once the red cube rests on the green cube left of the arm, let go (dense: staged shaping)",
};

const TOUCH_CUBE: TaskFacts = TaskFacts {
    name: "touch_cube",
    gym_id: "so101/TouchCube-v0",
    description: "touch the cube",
    episode_steps: 300,
    terminates_on_success: false,
    reward_modes: &[RewardMode::Dense],
    control_rate_hz: CONTROL_RATE_HZ,
    help: "dense: reward is minus the distance from the gripper tip to the cube",
};

const TOUCH_CUBE_SPARSE: TaskFacts = TaskFacts {
    name: "touch_cube_sparse",
    gym_id: "so101/TouchCubeSparse-v0",
    description: "touch the cube",
    episode_steps: 300,
    terminates_on_success: false,
    reward_modes: &[RewardMode::Sparse],
    control_rate_hz: CONTROL_RATE_HZ,
    help: "sparse: reward 1 while the gripper touches the cube",
};

impl std::fmt::Display for TaskKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for TaskKind {
    type Err = String;

    /// The task's name as on the command line ("cube_to_bin", "touch_cube", ...).
    fn from_str(name: &str) -> Result<Self, String> {
        Self::from_name(name).ok_or_else(|| {
            let known: Vec<_> = Self::ALL.iter().map(|kind| kind.name()).collect();
            format!("unknown task {name:?}: one of {}", known.join(", "))
        })
    }
}

/// clap's choices come from the facts, so `--help` lists every task with its line.
impl clap::ValueEnum for TaskKind {
    fn value_variants<'a>() -> &'a [Self] {
        &Self::ALL
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        let facts = self.facts();
        Some(
            PossibleValue::new(facts.name)
                .alias(facts.name.replace('_', "-"))
                .help(facts.help),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_task_has_distinct_names_and_ids() {
        let mut names: Vec<_> = TaskKind::ALL.iter().map(|kind| kind.name()).collect();
        let mut ids: Vec<_> = TaskKind::ALL
            .iter()
            .map(|kind| kind.facts().gym_id)
            .collect();
        names.sort_unstable();
        names.dedup();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(names.len(), TaskKind::ALL.len());
        assert_eq!(ids.len(), TaskKind::ALL.len());
        for kind in TaskKind::ALL {
            assert!(
                !kind.facts().reward_modes.is_empty(),
                "{kind} offers no reward"
            );
            assert!(kind.facts().episode_steps > 0);
        }
    }

    #[test]
    fn names_parse_back_with_underscores_or_dashes() {
        for kind in TaskKind::ALL {
            assert_eq!(kind.name().parse::<TaskKind>(), Ok(kind));
            assert_eq!(kind.name().replace('_', "-").parse::<TaskKind>(), Ok(kind));
            assert_eq!(
                <TaskKind as clap::ValueEnum>::from_str(kind.name(), false),
                Ok(kind)
            );
        }
        let refused = "pick_cube".parse::<TaskKind>().unwrap_err();
        assert!(refused.contains("cube_to_bin") && refused.contains("touch_cube_sparse"));
    }
}
