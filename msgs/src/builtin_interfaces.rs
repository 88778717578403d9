//! `builtin_interfaces`.

use serde::{Deserialize, Serialize};

use crate::ros_message;

/// `builtin_interfaces/Time`: seconds and nanoseconds since the epoch (or since the start of
/// simulation, on `/clock`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}
ros_message!(Time, "builtin_interfaces", "Time");

impl Time {
    /// The time `seconds` [s] after zero, rounded to the nanosecond; negative or non-finite
    /// input gives zero.
    pub fn from_seconds(seconds: f64) -> Self {
        if !seconds.is_finite() || seconds <= 0.0 {
            return Self::default();
        }
        let total = (seconds * 1e9).round() as u64;
        Self {
            sec: (total / 1_000_000_000).min(i32::MAX as u64) as i32,
            nanosec: (total % 1_000_000_000) as u32,
        }
    }

    /// Seconds [s] since zero.
    pub fn seconds(&self) -> f64 {
        f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_round_trip_to_the_nanosecond() {
        let t = Time::from_seconds(12.345_678_901);
        assert_eq!((t.sec, t.nanosec), (12, 345_678_901));
        assert!((t.seconds() - 12.345_678_901).abs() < 1e-9);
        assert_eq!(Time::from_seconds(-1.0), Time::default());
        assert_eq!(Time::from_seconds(f64::NAN), Time::default());
    }
}
