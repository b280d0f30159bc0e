//! When a camera's next frame is due, in sim time.

/// Frames at a fixed rate of sim time: frame k is taken at the first control-period end at or
/// after `start + k / rate`, so the long-run rate is exact even where a frame period is not a whole
/// number of control periods (30 Hz on 100 Hz control alternates 3 and 4 periods).
#[derive(Debug, Clone)]
pub struct FrameClock {
    period: f64,
    next_due: f64,
    /// How early a control-period end may be and still count as a frame instant: a period ends at
    /// the physics step nearest its ideal end, up to half a step before it, so a camera at the
    /// control rate (30 Hz on 2 ms steps) still gets a frame every period.
    tolerance: f64,
}

impl FrameClock {
    /// `timestep`: the physics step (s) that control periods are counted in.
    pub fn new(rate: f64, start: f64, timestep: f64) -> Self {
        Self {
            period: 1.0 / rate,
            next_due: start,
            tolerance: timestep / 2.0 + 1e-9,
        }
    }

    /// Whether a frame is due at `time`; when it is, the next one is scheduled. A clock that has
    /// fallen more than a period behind (a rate above the control rate) restarts from `time`.
    pub fn take_due(&mut self, time: f64) -> bool {
        if time + self.tolerance < self.next_due {
            return false;
        }
        self.next_due += self.period;
        if self.next_due + self.tolerance <= time {
            self.next_due = time + self.period;
        }
        true
    }

    /// Frames from now on come at `rate` per second of sim time (the next one stays where it was
    /// scheduled).
    pub fn set_rate(&mut self, rate: f64) {
        self.period = 1.0 / rate;
    }

    /// The next frame is due at `time` (a new episode starts with a frame of every camera).
    pub fn restart(&mut self, time: f64) {
        self.next_due = time;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(rate: f64, control_rate: f64, seconds: f64) -> Vec<f64> {
        let mut clock = FrameClock::new(rate, 0.0, 0.002);
        let periods = (seconds * control_rate).round() as u64;
        (0..=periods)
            .map(|k| k as f64 / control_rate)
            .filter(|time| clock.take_due(*time))
            .collect()
    }

    #[test]
    fn thirty_hz_on_a_hundred_hz_control_loop_is_exact_over_time() {
        let times = frames(30.0, 100.0, 10.0);
        assert_eq!(times.len(), 301); // t = 0 and 300 more in 10 s
        for pair in times.windows(2) {
            let gap = pair[1] - pair[0];
            assert!(
                (gap - 0.03).abs() < 1e-6 || (gap - 0.04).abs() < 1e-6,
                "{gap}"
            );
        }
    }

    #[test]
    fn a_rate_dividing_the_control_rate_is_regular() {
        let times = frames(10.0, 100.0, 1.0);
        assert_eq!(times.len(), 11);
        assert!(times
            .windows(2)
            .all(|pair| (pair[1] - pair[0] - 0.1).abs() < 1e-9));
    }

    #[test]
    fn a_rate_above_the_control_rate_gives_one_frame_per_period() {
        assert_eq!(frames(500.0, 100.0, 1.0).len(), 101);
    }

    #[test]
    fn restart_makes_a_frame_due_at_once() {
        let mut clock = FrameClock::new(10.0, 0.0, 0.002);
        assert!(clock.take_due(0.0));
        assert!(!clock.take_due(0.05));
        clock.restart(0.05);
        assert!(clock.take_due(0.05));
        assert!(!clock.take_due(0.1));
        assert!(clock.take_due(0.15));
    }

    #[test]
    fn a_camera_at_a_control_rate_off_the_physics_grid_gets_a_frame_every_period() {
        // 30 Hz control on 2 ms physics steps: period k ends at the step nearest k/30 s, which is
        // up to 1 ms early (k = 2 ends at 66 ms, before 66.7 ms).
        let timestep = 0.002;
        let mut clock = FrameClock::new(30.0, 0.0, timestep);
        let end_of = |k: u64| (k as f64 / 30.0 / timestep).round() * timestep;
        for k in 0..300 {
            assert!(
                clock.take_due(end_of(k)),
                "no frame at the end of period {k}"
            );
        }
    }
}
