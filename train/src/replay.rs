//! Replayed starts: training episodes that begin where earlier ones were about to tip over.
//!
//! A policy that falls once in a hundred episodes meets the states that lead to a fall about as
//! rarely, and PPO learns little from them. With `[replay]` each environment keeps, whenever
//! its base tilts past `tilt_rad`, the moment it was in `before_s` seconds earlier, and starts
//! a share of its later episodes from one of those moments instead of a fresh start: the policy
//! drives on from there with the same target, and is paid, as ever, for standing and reaching.
//! (The restarts of "backward" curricula and failure replay; evaluation never replays.)

use std::collections::VecDeque;

use rand::Rng;

/// `[replay]` in a whole-body config (training only; none when the section is absent).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct ReplayConfig {
    /// An episode whose base tilts past this [rad] has its moment from `before_s` earlier kept
    /// (once per episode).
    pub tilt_rad: f64,
    /// How long before that tilt the kept moment was [s] (the episode's start if it is younger,
    /// unless that start was itself a kept moment: a replay does not keep its own start again).
    pub before_s: f64,
    /// The chance, in [0, 1), that a reset starts from a kept moment when there is one (below 1,
    /// so that fresh starts, and the task's figures measured on them, go on).
    pub probability: f64,
    /// Moments kept per environment; past it the oldest goes.
    pub capacity: usize,
}

impl ReplayConfig {
    /// Refuses settings that cannot work, naming them: `tilt_limit_rad` is the task's, where
    /// an episode ends (a tilt at or past it is never seen standing).
    pub fn check(&self, tilt_limit_rad: f64) -> Result<(), String> {
        let ok = self.tilt_rad > 0.0
            && self.tilt_rad < tilt_limit_rad
            && self.before_s >= 0.0
            && self.before_s.is_finite()
            && (0.0..1.0).contains(&self.probability)
            && self.capacity > 0;
        if ok {
            Ok(())
        } else {
            Err(format!(
                "invalid [replay]: tilt_rad must be positive and below the task's tilt limit \
                 ({tilt_limit_rad} rad), before_s at least 0 [s], probability within [0, 1) and \
                 capacity at least 1: {self:?}"
            ))
        }
    }
}

/// One environment's replay: the moments of its current episode, and those it keeps.
/// Generic over the moment (`M`: whatever restores the environment), so that its rules are
/// tested without physics.
#[derive(Debug, Clone)]
pub struct Replay<M> {
    config: ReplayConfig,
    /// Moments in the window: `before_s` at the control rate, plus the current one.
    window: usize,
    history: VecDeque<M>,
    kept: VecDeque<M>,
    kept_this_episode: bool,
    /// Whether the episode started from a kept moment and that start is still the window's
    /// oldest moment.
    replayed_start_in_window: bool,
}

impl<M: Clone> Replay<M> {
    pub fn new(config: ReplayConfig, control_hz: f64) -> Self {
        Self {
            config,
            window: (config.before_s * control_hz).round() as usize + 1,
            history: VecDeque::new(),
            kept: VecDeque::new(),
            kept_this_episode: false,
            replayed_start_in_window: false,
        }
    }

    /// An episode starts at `first`: a fresh start, or a kept moment (`replayed`).
    pub fn start_episode(&mut self, first: M, replayed: bool) {
        self.history.clear();
        self.history.push_back(first);
        self.kept_this_episode = false;
        self.replayed_start_in_window = replayed;
    }

    /// The episode has reached `moment`, its base tilted by `tilt_rad`: the moment from
    /// `before_s` earlier is kept the first time the tilt passes the limit (unless it is the
    /// replayed start, kept already).
    pub fn record(&mut self, moment: M, tilt_rad: f64) {
        self.history.push_back(moment);
        if self.history.len() > self.window {
            self.history.pop_front();
            self.replayed_start_in_window = false;
        }
        if tilt_rad >= self.config.tilt_rad && !self.kept_this_episode {
            self.kept_this_episode = true;
            if self.replayed_start_in_window {
                return;
            }
            let earlier = self.history.front().expect("just pushed").clone();
            self.kept.push_back(earlier);
            if self.kept.len() > self.config.capacity {
                self.kept.pop_front();
            }
        }
    }

    /// Where the next episode starts: a kept moment, drawn uniformly, with the configured
    /// probability; none (a fresh start) otherwise or while none is kept.
    pub fn draw_start(&self, rng: &mut impl Rng) -> Option<M> {
        if self.kept.is_empty() || rng.random::<f64>() >= self.config.probability {
            return None;
        }
        let i = rng.random_range(0..self.kept.len());
        Some(self.kept[i].clone())
    }

    /// How many moments are kept.
    pub fn kept(&self) -> usize {
        self.kept.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    const CONFIG: ReplayConfig = ReplayConfig {
        tilt_rad: 0.3,
        before_s: 1.0,
        probability: 0.5,
        capacity: 2,
    };

    /// A fresh episode of `steps` steps (moments numbered from `start`) tilting from `tip`.
    fn episode(replay: &mut Replay<usize>, start: usize, steps: usize, tip: usize) {
        replayed_episode(replay, start, steps, tip, false);
    }

    fn replayed_episode(
        replay: &mut Replay<usize>,
        start: usize,
        steps: usize,
        tip: usize,
        replayed: bool,
    ) {
        replay.start_episode(start, replayed);
        for step in 1..=steps {
            let tilt = if step >= tip { 0.4 } else { 0.1 };
            replay.record(start + step, tilt);
        }
    }

    #[test]
    fn a_tilt_keeps_the_moment_before_s_earlier_once_per_episode() {
        let mut replay = Replay::new(CONFIG, 30.0);
        episode(&mut replay, 0, 100, 50);
        // Step 50 tilted past 0.3 rad: the moment 1 s (30 steps) earlier is step 20; the steps
        // that go on tilting keep nothing more.
        assert_eq!(replay.kept.iter().copied().collect::<Vec<_>>(), [20]);
        // A young episode keeps its start.
        episode(&mut replay, 1000, 100, 10);
        assert_eq!(replay.kept.iter().copied().collect::<Vec<_>>(), [20, 1000]);
        // Past the capacity the oldest goes; an episode that stands keeps nothing.
        episode(&mut replay, 2000, 100, 200);
        episode(&mut replay, 3000, 40, 31);
        assert_eq!(
            replay.kept.iter().copied().collect::<Vec<_>>(),
            [1000, 3001]
        );
    }

    #[test]
    fn a_replayed_start_is_not_kept_again() {
        let mut replay = Replay::new(CONFIG, 30.0);
        episode(&mut replay, 0, 100, 50);
        // Replayed from moment 20 and tipping within 1 s: its start is kept already.
        replayed_episode(&mut replay, 20, 100, 25, true);
        assert_eq!(replay.kept.iter().copied().collect::<Vec<_>>(), [20]);
        // Tipping later, the moment 1 s before is a new one.
        replayed_episode(&mut replay, 20, 100, 40, true);
        assert_eq!(replay.kept.iter().copied().collect::<Vec<_>>(), [20, 30]);
        // Exactly 1 s after a replayed start, the window's oldest moment is that start.
        replayed_episode(&mut replay, 500, 100, 30, true);
        assert_eq!(replay.kept.iter().copied().collect::<Vec<_>>(), [20, 30]);
        replayed_episode(&mut replay, 500, 100, 31, true);
        assert_eq!(replay.kept.iter().copied().collect::<Vec<_>>(), [30, 501]);
    }

    #[test]
    fn resets_replay_kept_moments_at_the_configured_rate() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut replay = Replay::new(CONFIG, 30.0);
        assert_eq!(replay.draw_start(&mut rng), None, "nothing kept yet");
        episode(&mut replay, 0, 100, 50);
        episode(&mut replay, 1000, 100, 60);
        let draws: Vec<_> = (0..4000).map(|_| replay.draw_start(&mut rng)).collect();
        let replayed = draws.iter().flatten().count();
        assert!(
            (1800..2200).contains(&replayed),
            "{replayed} of 4000 at 0.5"
        );
        for kept in [20, 1030] {
            let n = draws.iter().flatten().filter(|&&m| m == kept).count();
            assert!(n > 800, "moment {kept} drawn {n} times of {replayed}");
        }
        let never: Replay<usize> = Replay::new(
            ReplayConfig {
                probability: 0.0,
                ..CONFIG
            },
            30.0,
        );
        assert_eq!(never.draw_start(&mut rng), None);
    }

    #[test]
    fn bad_replay_settings_are_refused() {
        for bad in [
            ReplayConfig {
                tilt_rad: 0.0,
                ..CONFIG
            },
            ReplayConfig {
                before_s: -1.0,
                ..CONFIG
            },
            ReplayConfig {
                probability: 1.0,
                ..CONFIG
            },
            ReplayConfig {
                tilt_rad: 0.785,
                ..CONFIG
            },
            ReplayConfig {
                probability: f64::NAN,
                ..CONFIG
            },
            ReplayConfig {
                capacity: 0,
                ..CONFIG
            },
        ] {
            let error = bad.check(0.785).unwrap_err();
            assert!(error.contains("[replay]"), "{error}");
        }
        CONFIG.check(0.785).unwrap();
    }
}
