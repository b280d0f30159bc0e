use serde::{Deserialize, Serialize};

/// builtin_interfaces/Time: seconds and nanoseconds since an epoch (the Unix epoch, or sim start).
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}
crate::ros_message!(
    Time,
    "builtin_interfaces",
    "Time",
    "int32 sec\nuint32 nanosec\n"
);

/// builtin_interfaces/Duration: a signed span of seconds and nanoseconds (nanosec < 1e9).
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
pub struct Duration {
    pub sec: i32,
    pub nanosec: u32,
}
crate::ros_message!(
    Duration,
    "builtin_interfaces",
    "Duration",
    "int32 sec\nuint32 nanosec\n"
);

impl Duration {
    pub fn from_secs_f64(secs: f64) -> Self {
        let Time { sec, nanosec } = Time::from_secs_f64(secs);
        Self { sec, nanosec }
    }

    pub fn as_secs_f64(self) -> f64 {
        Time {
            sec: self.sec,
            nanosec: self.nanosec,
        }
        .as_secs_f64()
    }
}

impl Time {
    /// Time from nanoseconds; saturates at the limits of the `int32` seconds field.
    pub fn from_nanos(nanos: i64) -> Self {
        let sec = nanos.div_euclid(1_000_000_000);
        let nanosec = nanos.rem_euclid(1_000_000_000) as u32;
        match i32::try_from(sec) {
            Ok(sec) => Self { sec, nanosec },
            Err(_) if sec < 0 => Self {
                sec: i32::MIN,
                nanosec: 0,
            },
            Err(_) => Self {
                sec: i32::MAX,
                nanosec: 999_999_999,
            },
        }
    }

    pub fn from_secs_f64(secs: f64) -> Self {
        Self::from_nanos((secs * 1e9).round() as i64)
    }

    pub fn to_nanos(self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }

    pub fn as_secs_f64(self) -> f64 {
        self.to_nanos() as f64 * 1e-9
    }

    /// Wall-clock time now.
    pub fn now() -> Self {
        let since_epoch = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        Self::from_nanos(since_epoch.as_nanos().min(i64::MAX as u128) as i64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nanos_round_trip_including_negative() {
        for nanos in [
            0,
            1,
            999_999_999,
            1_000_000_000,
            1_234_567_890_123,
            -1,
            -1_500_000_000,
        ] {
            assert_eq!(Time::from_nanos(nanos).to_nanos(), nanos);
        }
        assert_eq!(
            Time::from_nanos(-1),
            Time {
                sec: -1,
                nanosec: 999_999_999
            }
        );
        assert_eq!(
            Time::from_secs_f64(0.01),
            Time {
                sec: 0,
                nanosec: 10_000_000
            }
        );
    }

    #[test]
    fn out_of_range_saturates() {
        assert_eq!(Time::from_nanos(i64::MAX).sec, i32::MAX);
        assert_eq!(Time::from_nanos(i64::MIN).sec, i32::MIN);
    }
}
