//! `builtin_interfaces`.

use serde::{Deserialize, Serialize};

use crate::ros_message;

/// `builtin_interfaces/Time`: seconds and nanoseconds since the epoch (or since the start of
/// simulation, on `/clock`). Decoding refuses `nanosec` of a second or more: no ROS client
/// sends one, and junk bytes read as a time would otherwise move a node's clock.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "TimeFields")]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}
ros_message!(Time, "builtin_interfaces", "Time");

/// [`Time`] as it is on the wire, before its check.
#[derive(Deserialize)]
struct TimeFields {
    sec: i32,
    nanosec: u32,
}

impl TryFrom<TimeFields> for Time {
    type Error = String;

    fn try_from(t: TimeFields) -> Result<Self, String> {
        if t.nanosec >= 1_000_000_000 {
            return Err(format!(
                "builtin_interfaces/Time nanosec {} is not below one second",
                t.nanosec
            ));
        }
        Ok(Self {
            sec: t.sec,
            nanosec: t.nanosec,
        })
    }
}

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

    #[test]
    fn a_time_of_a_second_or_more_in_nanoseconds_is_refused() {
        use crate::cdr::{from_bytes, ByteOrder};
        let mut ok = 7_i32.to_le_bytes().to_vec();
        ok.extend(999_999_999_u32.to_le_bytes());
        let t: Time = from_bytes(&ok, ByteOrder::Little).unwrap();
        assert_eq!((t.sec, t.nanosec), (7, 999_999_999));
        // Eight bytes of 'A' (junk on /clock) read as a time: refused.
        let junk = [0x41_u8; 8];
        let err = from_bytes::<Time>(&junk, ByteOrder::Little).unwrap_err();
        assert!(err.to_string().contains("not below one second"), "{err}");
    }
}
