//! The scripted expert as an input source: episode after episode it resets the sim, waits for the
//! cube to settle, plans a pick-and-place from /cube/pose (so101_core::expert), plays it, and judges it
//! by /task/success, announcing each episode on /episode/events so a recorder captures it.

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use so101_core::expert::{cube_yaw, ExpertConfig, Plan, JUDGE_SECONDS, SUCCESS_SHOWN_SECONDS};

use super::{Reading, Request, Source, Tick};
use crate::{controls::Control, motion::Jog};

/// /cube/pose messages to wait for after a reset before planning (0.3 s at the sim's 100 Hz): the
/// cube has settled on the table.
const SETTLE_MESSAGES: u64 = 30;
/// Seconds to wait for the settled cube and the arm's pose before the episode counts as failed.
const SETTLE_TIMEOUT: f64 = 10.0;

/// One finished episode.
#[derive(Debug, Clone, Serialize)]
pub struct EpisodeResult {
    pub episode: u32,
    pub success: bool,
    /// Cube position (world) and yaw the episode started from.
    pub cube: [f64; 4],
    pub note: String,
}

enum State {
    Reset,
    /// Waiting for the cube to settle (and the arm's pose) after a reset.
    Settle {
        after: u64,
        until: f64,
        reset_failures: u64,
    },
    Run {
        plan: Box<Plan>,
        /// The clock when the plan last stepped.
        last: f64,
        cube: [f64; 4],
    },
    Judge {
        until: f64,
        cube: [f64; 4],
        /// When /task/success turned true.
        succeeded_at: Option<f64>,
    },
    Finished,
}

pub struct Expert {
    config: ExpertConfig,
    /// The arm's base in the world frame of /cube/pose.
    base_in_world: Vector3<f64>,
    task: String,
    seed: u64,
    episodes: Option<u32>,
    reset: bool,
    rng: ChaCha8Rng,
    state: State,
    pub results: Vec<EpisodeResult>,
}

impl Expert {
    pub fn new(
        config: ExpertConfig,
        base_in_world: Vector3<f64>,
        task: String,
        seed: u64,
        episodes: Option<u32>,
        reset: bool,
    ) -> Self {
        Self {
            config,
            base_in_world,
            task,
            seed,
            episodes,
            reset,
            rng: ChaCha8Rng::seed_from_u64(seed),
            state: State::Reset,
            results: Vec::new(),
        }
    }

    pub fn successes(&self) -> usize {
        self.results.iter().filter(|result| result.success).count()
    }

    /// Plans the episode for the settled cube and announces it (or fails it when out of reach).
    fn start_episode(
        &mut self,
        position: [f64; 3],
        orientation: [f64; 4],
        targets: &so101_core::robot::JointPositions,
        now: f64,
        controls: &mut Vec<Control>,
    ) {
        let yaw = cube_yaw(orientation);
        let cube = [position[0], position[1], position[2], yaw];
        let in_base = Vector3::from(position) - self.base_in_world;
        match Plan::new(targets, in_base, yaw, &self.config, &mut self.rng) {
            Ok(plan) => {
                let episode = self.results.len() as u64 + 1;
                controls.push(Control::Start {
                    task: Some(self.task.clone()),
                    seed: Some(self.seed.wrapping_mul(1_000_003).wrapping_add(episode)),
                });
                self.state = State::Run {
                    plan: Box::new(plan),
                    last: now,
                    cube,
                };
            }
            Err(error) => self.finish(false, false, cube, error.to_string(), controls),
        }
    }

    /// Ends the episode; `recorded` says whether its start was announced (then its verdict and
    /// stop are too).
    fn finish(
        &mut self,
        recorded: bool,
        success: bool,
        cube: [f64; 4],
        note: String,
        controls: &mut Vec<Control>,
    ) {
        let episode = self.results.len() as u32 + 1;
        tracing::info!(episode, success, %note, cube_x = cube[0], cube_y = cube[1], cube_yaw = cube[3], "expert episode done");
        if recorded {
            controls.push(if success {
                Control::MarkSuccess
            } else {
                Control::MarkFailure
            });
            controls.push(Control::Stop);
        }
        self.results.push(EpisodeResult {
            episode,
            success,
            cube,
            note,
        });
        if self
            .episodes
            .is_some_and(|episodes| self.results.len() as u32 >= episodes)
        {
            tracing::info!(
                episodes = self.results.len(),
                successes = self.successes(),
                "expert finished"
            );
            controls.push(Control::Quit);
            self.state = State::Finished;
        } else {
            self.state = State::Reset;
        }
    }
}

fn hold() -> Request {
    Request::Jog(Jog::STILL)
}

impl Source for Expert {
    fn read(&mut self, tick: &Tick) -> Reading {
        let mut controls = Vec::new();
        let request = match &mut self.state {
            State::Reset => {
                if self.reset {
                    controls.push(Control::ResetSim);
                }
                self.state = State::Settle {
                    after: tick.scene.cube_messages + SETTLE_MESSAGES,
                    until: tick.now + SETTLE_TIMEOUT,
                    reset_failures: tick.scene.reset_failures,
                };
                hold()
            }
            State::Settle {
                after,
                until,
                reset_failures,
            } => {
                let settled = tick.scene.cube_messages >= *after;
                let unknown = [f64::NAN; 4];
                if tick.scene.reset_failures > *reset_failures {
                    // No new episode to play: not recorded, only counted.
                    self.finish(
                        false,
                        false,
                        unknown,
                        "/sim/reset failed".into(),
                        &mut controls,
                    );
                } else if let (true, Some((position, orientation)), Some(targets)) =
                    (settled, tick.scene.cube, tick.scene.targets)
                {
                    self.start_episode(position, orientation, &targets, tick.now, &mut controls);
                } else if tick.now > *until {
                    tracing::warn!("no /cube/pose or /joint_states from the sim: is it running?");
                    let note = "no /cube/pose or /joint_states to plan from".into();
                    self.finish(false, false, unknown, note, &mut controls);
                }
                hold()
            }
            State::Run { plan, last, cube } => {
                let dt = (tick.now - *last).max(0.0);
                *last = tick.now;
                // The plan waits for the arm it sees; the targets stand in until /joint_states does.
                let Some(measured) = tick.scene.measured.or(tick.scene.targets) else {
                    return Reading {
                        request: hold(),
                        controls,
                    };
                };
                let cube_now = tick.scene.cube.map(|(position, orientation)| {
                    (
                        Vector3::from(position) - self.base_in_world,
                        cube_yaw(orientation),
                    )
                });
                let targets = plan.step(dt, &measured, cube_now, &self.config, &mut self.rng);
                if plan.finished() {
                    if plan.regrasps() > 0 {
                        tracing::info!(regrasps = plan.regrasps(), "the expert grasped again");
                    }
                    let cube = *cube;
                    self.state = State::Judge {
                        until: tick.now + JUDGE_SECONDS,
                        cube,
                        succeeded_at: None,
                    };
                }
                Request::Targets(targets)
            }
            State::Judge {
                until,
                cube,
                succeeded_at,
            } => {
                let (until, cube) = (*until, *cube);
                if tick.scene.task_success && succeeded_at.is_none() {
                    *succeeded_at = Some(tick.now);
                }
                if let Some(at) = *succeeded_at {
                    // The episode goes on a moment with the task done, so its recording ends on
                    // the success it is marked with.
                    if tick.now >= at + SUCCESS_SHOWN_SECONDS {
                        self.finish(true, true, cube, "the task succeeded".into(), &mut controls);
                    }
                } else if tick.now > until {
                    let note = match tick.scene.cube {
                        Some(([x, y, z], _)) => {
                            format!(
                                "the task did not succeed: the cube is at ({x:.3}, {y:.3}, {z:.3})"
                            )
                        }
                        None => "the task did not succeed".into(),
                    };
                    self.finish(true, false, cube, note, &mut controls);
                }
                hold()
            }
            State::Finished => hold(),
        };
        Reading { request, controls }
    }

    fn report(&self) -> Option<serde_json::Value> {
        let episodes = self.results.len();
        let successes = self.successes();
        Some(serde_json::json!({
            "episodes": episodes,
            "successes": successes,
            "success_rate": if episodes == 0 { 0.0 } else { successes as f64 / episodes as f64 },
            "results": self.results,
        }))
    }
}
