//! Domain randomization: each episode draws the cube's size, mass, friction and colour, the
//! table's and bin's colours, the lights, the cameras' poses and fields of view, the servos
//! around the model in use, the command latency and the observation noise, from the ranges of
//! one config file (assets/randomization.toml). Seeded per episode in the core, so so101_sim_node
//! and the in-process envs draw the same episode from the same seed.

pub mod apply;
pub mod config;
pub mod draw;
pub mod fuzzing;
pub mod spec;

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

pub use apply::SceneLook;
pub use config::{ConfigError, RandomizationConfig};
pub use draw::EpisodeDraw;
pub use spec::RandomizationSpec;

/// Mixed into the env's seed so the randomization's stream is not the cube placement's.
const STREAM: u64 = 0x5eed_d0e5_0000_0101;

/// The sequence of episode draws of one env.
#[derive(Debug, Clone)]
pub struct Randomizer {
    pub config: RandomizationConfig,
    episodes: ChaCha8Rng,
}

impl Randomizer {
    pub fn new(config: RandomizationConfig, seed: u64) -> Self {
        Self {
            config,
            episodes: ChaCha8Rng::seed_from_u64(seed ^ STREAM),
        }
    }

    /// Starts the sequence over from `seed` (a reset with a seed).
    pub fn reseed(&mut self, seed: u64) {
        self.episodes = ChaCha8Rng::seed_from_u64(seed ^ STREAM);
    }

    /// The next episode's draw for a scene of `look`.
    pub fn next_draw(&mut self, look: &SceneLook) -> EpisodeDraw {
        let seed = self.episodes.next_u64();
        EpisodeDraw::new(
            &self.config,
            seed,
            look.light_count(),
            look.cameras_on_arm(),
        )
    }
}

/// The observation noise of one episode, drawn step by step from the episode's seed.
#[derive(Debug, Clone)]
pub struct ObservationNoise {
    rng: ChaCha8Rng,
    joint: f64,
    cube: f64,
}

impl ObservationNoise {
    pub fn new(draw: &EpisodeDraw) -> Self {
        Self {
            rng: ChaCha8Rng::seed_from_u64(draw.seed.rotate_left(17) ^ STREAM),
            joint: draw.joint_noise,
            cube: draw.cube_position_noise,
        }
    }

    /// Fresh noise for the joints (rad) and the cube's position (m).
    pub fn sample(&mut self) -> ([f64; 6], [f64; 3]) {
        let mut gaussian = |std: f64| {
            if std > 0.0 {
                Normal::new(0.0, std).map_or(0.0, |normal| normal.sample(&mut self.rng))
            } else {
                0.0
            }
        };
        let joints = std::array::from_fn(|_| gaussian(self.joint));
        let cube = std::array::from_fn(|_| gaussian(self.cube));
        (joints, cube)
    }
}
