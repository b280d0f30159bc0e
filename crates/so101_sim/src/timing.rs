//! How control periods map onto physics steps.

/// Number of physics steps in control period `index` (counting from 0) so that period k ends at the
/// step nearest to (k + 1) * period: rates that do not divide the physics rate (30 Hz on 2 ms
/// steps) alternate between neighbouring step counts instead of drifting.
pub fn steps_in_period(index: u64, period: f64, timestep: f64) -> u64 {
    let end_step = |k: u64| (k as f64 * period / timestep).round() as u64;
    end_step(index + 1) - end_step(index)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn periods_follow_the_control_rate_without_drift() {
        assert!((0..1000).all(|k| steps_in_period(k, 0.01, 0.002) == 5));
        let thirty_hz: Vec<u64> = (0..3000)
            .map(|k| steps_in_period(k, 1.0 / 30.0, 0.002))
            .collect();
        assert!(thirty_hz.iter().all(|steps| *steps == 16 || *steps == 17));
        // After 100 s exactly 50000 steps: no drift.
        assert_eq!(thirty_hz.iter().sum::<u64>(), 50_000);
    }
}
