//! Rate-limited warnings for anything that could fire every tick.

use std::time::{Duration, Instant};

/// Lets a message through at most once per `period`, and counts what it held back.
#[derive(Debug)]
pub struct RateLimited {
    period: Duration,
    last: Option<Instant>,
    suppressed: u64,
}

impl RateLimited {
    pub fn new(period: Duration) -> Self {
        Self {
            period,
            last: None,
            suppressed: 0,
        }
    }

    /// `Some(n)` when a message may be logged now, with `n` messages suppressed since the last
    /// one; `None` otherwise.
    pub fn check(&mut self, now: Instant) -> Option<u64> {
        match self.last {
            Some(last) if now.duration_since(last) < self.period => {
                self.suppressed += 1;
                None
            }
            _ => {
                self.last = Some(now);
                Some(std::mem::take(&mut self.suppressed))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lets_one_through_per_period_and_counts_the_rest() {
        let t0 = Instant::now();
        let mut r = RateLimited::new(Duration::from_secs(1));
        assert_eq!(r.check(t0), Some(0));
        assert_eq!(r.check(t0 + Duration::from_millis(10)), None);
        assert_eq!(r.check(t0 + Duration::from_millis(900)), None);
        assert_eq!(r.check(t0 + Duration::from_millis(1001)), Some(2));
    }
}
