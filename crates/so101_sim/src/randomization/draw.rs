//! One episode's draw from the configured ranges: pure, from a seed, so every door that resets
//! with the same seed gets the same episode.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use so101_core::robot::JOINT_COUNT;

use super::config::{RandomizationConfig, Range};

/// How one servo departs from the model in use.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ServoDraw {
    pub gain_scale: f64,
    pub damping_scale: f64,
    pub friction_scale: f64,
    pub armature_scale: f64,
    /// Added to the model's latency, s.
    pub extra_latency: f64,
}

/// One light's change: direction offset (before normalising) and intensity factor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LightDraw {
    pub direction_offset: [f64; 3],
    pub intensity_scale: f64,
}

/// One camera's change: position offset (m, in its body's frame) and field-of-view offset (deg).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CameraDraw {
    pub position_offset: [f64; 3],
    pub fovy_offset: f64,
}

/// Where the distractor stands (world frame, m; on the table beside the cube's spawn area, clear of
/// it by more than the distractor's radius and on the far side from the bin) and its colour.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DistractorDraw {
    pub position: [f64; 2],
    pub rgb: [f32; 3],
}

/// The distractor's area on the table: x, y ranges (m).
pub const DISTRACTOR_AREA: [Range; 2] = [[0.08, 0.38], [0.13, 0.28]];
/// Its colour's range on each of r, g, b: never the key colour of real backgrounds.
const DISTRACTOR_COLOUR: Range = [0.1, 0.9];

/// Everything one episode changes. Colours are offsets added to the scene's r, g, b.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EpisodeDraw {
    /// The seed this draw came from (and the observation noise of the episode).
    pub seed: u64,
    pub cube_size_scale: f64,
    pub cube_mass_scale: f64,
    pub cube_friction_scale: f64,
    pub cube_colour_offset: [f32; 3],
    pub table_colour_offset: [f32; 3],
    pub bin_colour_offset: [f32; 3],
    pub lights: Vec<LightDraw>,
    pub ambient: f32,
    /// In the order of [`so101_core::contract::CAMERA_NAMES`].
    pub cameras: Vec<CameraDraw>,
    pub servos: [ServoDraw; JOINT_COUNT],
    /// Standard deviations of the observation noise (rad, m).
    pub joint_noise: f64,
    pub cube_position_noise: f64,
    /// Which real backgrounds the fixed cameras show (with `scene.backgrounds`; drawn after the
    /// rest, so a config without it draws as before).
    pub background: Option<u64>,
    /// The distractor (with `scene.distractor`; drawn last).
    pub distractor: Option<DistractorDraw>,
}

/// Cameras fixed to a link move less than those on the table: their offset is this fraction.
pub const MOVING_CAMERA_JITTER_FRACTION: f64 = 0.2;

impl EpisodeDraw {
    /// The draw of `seed`: `lights` lights; `cameras` says per camera whether it rides the arm.
    pub fn new(config: &RandomizationConfig, seed: u64, lights: usize, cameras: &[bool]) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let rng = &mut rng;
        let cube_size_scale = uniform(rng, config.cube.size_scale);
        let cube_mass_scale = uniform(rng, config.cube.mass_scale);
        let cube_friction_scale = uniform(rng, config.cube.friction_scale);
        let cube_colour_offset = colour(rng, config.cube.colour_jitter);
        let table_colour_offset = colour(rng, config.scene.table_colour_jitter);
        let bin_colour_offset = colour(rng, config.scene.bin_colour_jitter);
        let lights = (0..lights)
            .map(|_| LightDraw {
                direction_offset: vector(rng, config.lighting.direction_jitter),
                intensity_scale: uniform(rng, config.lighting.intensity_scale),
            })
            .collect();
        let ambient = uniform(rng, config.lighting.ambient) as f32;
        let cameras = cameras
            .iter()
            .map(|on_arm| {
                let fraction = if *on_arm {
                    MOVING_CAMERA_JITTER_FRACTION
                } else {
                    1.0
                };
                CameraDraw {
                    position_offset: vector(rng, fraction * config.cameras.position_jitter),
                    fovy_offset: symmetric(rng, config.cameras.fovy_jitter),
                }
            })
            .collect();
        let servos = std::array::from_fn(|_| ServoDraw {
            gain_scale: uniform(rng, config.servos.gain_scale),
            damping_scale: uniform(rng, config.servos.damping_scale),
            friction_scale: uniform(rng, config.servos.friction_scale),
            armature_scale: uniform(rng, config.servos.armature_scale),
            extra_latency: uniform(rng, config.servos.latency),
        });
        let background = config.scene.backgrounds.as_ref().map(|_| rng.gen::<u64>());
        let distractor = config.scene.distractor.then(|| DistractorDraw {
            position: DISTRACTOR_AREA.map(|range| uniform(rng, range)),
            rgb: std::array::from_fn(|_| uniform(rng, DISTRACTOR_COLOUR) as f32),
        });
        Self {
            seed,
            cube_size_scale,
            cube_mass_scale,
            cube_friction_scale,
            cube_colour_offset,
            table_colour_offset,
            bin_colour_offset,
            lights,
            ambient,
            cameras,
            servos,
            joint_noise: config.observation.joint_noise,
            cube_position_noise: config.observation.cube_position_noise,
            background,
            distractor,
        }
    }
}

fn uniform(rng: &mut ChaCha8Rng, [low, high]: Range) -> f64 {
    if low == high {
        low
    } else {
        rng.gen_range(low..=high)
    }
}

fn symmetric(rng: &mut ChaCha8Rng, amount: f64) -> f64 {
    uniform(rng, [-amount, amount])
}

fn vector(rng: &mut ChaCha8Rng, amount: f64) -> [f64; 3] {
    std::array::from_fn(|_| symmetric(rng, amount))
}

fn colour(rng: &mut ChaCha8Rng, amount: f64) -> [f32; 3] {
    std::array::from_fn(|_| symmetric(rng, amount) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_seed_gives_the_same_draw_and_another_seed_another() {
        let config = RandomizationConfig::defaults();
        let cameras = [false, false, true];
        let a = EpisodeDraw::new(&config, 7, 2, &cameras);
        assert_eq!(a, EpisodeDraw::new(&config, 7, 2, &cameras));
        assert_ne!(a, EpisodeDraw::new(&config, 8, 2, &cameras));
    }

    #[test]
    fn backgrounds_and_the_distractor_are_drawn_after_the_rest() {
        let plain = RandomizationConfig::defaults();
        let mut shifted = plain.clone();
        shifted.scene.backgrounds = Some("backgrounds".into());
        shifted.scene.distractor = true;
        for seed in 0..200 {
            let (a, b) = (
                EpisodeDraw::new(&plain, seed, 2, &[false]),
                EpisodeDraw::new(&shifted, seed, 2, &[false]),
            );
            assert_eq!((a.background, a.distractor), (None, None));
            // Everything else as without them: a file adding them changes nothing else.
            let extras = |draw: &EpisodeDraw| EpisodeDraw {
                background: None,
                distractor: None,
                ..draw.clone()
            };
            assert_eq!(extras(&b), a);
            let distractor = b.distractor.unwrap();
            assert!(b.background.is_some());
            for (value, [low, high]) in distractor.position.iter().zip(DISTRACTOR_AREA) {
                assert!((low..=high).contains(value));
            }
            assert!(distractor.rgb.iter().all(|c| (0.1..=0.9).contains(c)));
        }
    }

    #[test]
    fn draws_stay_inside_the_configured_ranges_and_cover_them() {
        let config = RandomizationConfig::defaults();
        let draws: Vec<_> = (0..2000)
            .map(|seed| EpisodeDraw::new(&config, seed, 2, &[false, false, true]))
            .collect();
        let check = |name: &str, values: Vec<f64>, [low, high]: Range| {
            let min = values.iter().copied().fold(f64::INFINITY, f64::min);
            let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            assert!(
                min >= low && max <= high,
                "{name}: {min}..{max} outside {low}..{high}"
            );
            // 2,000 uniform draws come within 1 % of each end.
            let slack = 0.01 * (high - low);
            assert!(
                min <= low + slack && max >= high - slack,
                "{name}: {min}..{max}"
            );
        };
        check(
            "cube size",
            draws.iter().map(|d| d.cube_size_scale).collect(),
            config.cube.size_scale,
        );
        check(
            "cube mass",
            draws.iter().map(|d| d.cube_mass_scale).collect(),
            config.cube.mass_scale,
        );
        check(
            "gain",
            draws.iter().map(|d| d.servos[1].gain_scale).collect(),
            config.servos.gain_scale,
        );
        check(
            "latency",
            draws.iter().map(|d| d.servos[5].extra_latency).collect(),
            config.servos.latency,
        );
        check(
            "ambient",
            draws.iter().map(|d| f64::from(d.ambient)).collect(),
            config.lighting.ambient,
        );
        let jitter = config.cameras.position_jitter;
        check(
            "top camera x",
            draws
                .iter()
                .map(|d| d.cameras[0].position_offset[0])
                .collect(),
            [-jitter, jitter],
        );
        let wrist = MOVING_CAMERA_JITTER_FRACTION * jitter;
        check(
            "wrist camera z",
            draws
                .iter()
                .map(|d| d.cameras[2].position_offset[2])
                .collect(),
            [-wrist, wrist],
        );
        let colour = config.cube.colour_jitter;
        check(
            "cube red",
            draws
                .iter()
                .map(|d| f64::from(d.cube_colour_offset[0]))
                .collect(),
            [-colour - 1e-6, colour + 1e-6],
        );
    }
}
