//! The body of the cargo-fuzz target (fuzz/) over the randomization TOML, shared with the corpus
//! replay test (tests/fuzz_corpus.rs) so the two cannot drift. It never panics on any input.

use super::{draw::EpisodeDraw, ObservationNoise, RandomizationConfig};

/// A user's randomization file: an accepted one writes back to itself, and every episode drawn
/// from it stays finite and inside its ranges.
pub fn randomization_toml(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(config) = RandomizationConfig::from_toml(text, "fuzz") else {
        return;
    };
    let written = toml::to_string(&config).expect("a config serializes");
    assert_eq!(
        RandomizationConfig::from_toml(&written, "written").ok(),
        Some(config.clone()),
        "{written}"
    );
    for seed in [0, 1, u64::MAX] {
        let draw = EpisodeDraw::new(&config, seed, 2, &[false, false, true]);
        let inside = |value: f64, [low, high]: [f64; 2]| value >= low && value <= high;
        assert!(inside(draw.cube_size_scale, config.cube.size_scale));
        assert!(inside(draw.cube_mass_scale, config.cube.mass_scale));
        assert!(inside(draw.cube_friction_scale, config.cube.friction_scale));
        for servo in &draw.servos {
            assert!(inside(servo.gain_scale, config.servos.gain_scale));
            assert!(inside(servo.extra_latency, config.servos.latency));
        }
        assert!(draw.ambient.is_finite());
        for light in &draw.lights {
            assert!(light.direction_offset.iter().all(|v| v.is_finite()));
            assert!(light.intensity_scale.is_finite());
        }
        for camera in &draw.cameras {
            assert!(camera.position_offset.iter().all(|v| v.is_finite()));
            assert!(camera.fovy_offset.is_finite());
        }
        let colours = [
            draw.cube_colour_offset,
            draw.table_colour_offset,
            draw.bin_colour_offset,
        ];
        assert!(colours.iter().flatten().all(|v| v.is_finite()));
        let (joints, cube) = ObservationNoise::new(&draw).sample();
        assert!(joints.iter().chain(&cube).all(|v| v.is_finite()));
    }
}
