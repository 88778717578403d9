//! When the arm node acts, as a pure state machine.
//!
//! Sim time: once per new joint state (once per simulated control step, what the bridge's
//! lockstep waits for), or once per control period of `/clock` when joint states stop (to
//! publish holds). Wall time: at the control rate. Switching time base forgets the times kept
//! so far: comparing sim seconds with wall seconds would stall the node.

/// The node's schedule.
#[derive(Debug, Clone)]
pub struct Schedule {
    period_s: f64,
    sim: bool,
    last_acted_stamp: f64,
    last_step_at: f64,
    fresh: bool,
}

impl Schedule {
    /// A schedule at `control_hz` [Hz], starting in wall time.
    pub fn new(control_hz: f64) -> Self {
        Self {
            period_s: 1.0 / control_hz,
            sim: false,
            last_acted_stamp: f64::NEG_INFINITY,
            last_step_at: f64::NEG_INFINITY,
            fresh: false,
        }
    }

    /// Sets the time base; returns true when it changed.
    pub fn use_sim_time(&mut self, sim: bool) -> bool {
        if sim == self.sim {
            return false;
        }
        self.sim = sim;
        self.forget();
        true
    }

    /// Forgets the times kept so far (the time base changed, or sim time went back).
    pub fn forget(&mut self) {
        self.last_acted_stamp = f64::NEG_INFINITY;
        self.last_step_at = f64::NEG_INFINITY;
        self.fresh = false;
    }

    pub fn sim(&self) -> bool {
        self.sim
    }

    /// A joint state newer than the last one acted on has arrived.
    pub fn fresh(&self) -> bool {
        self.fresh
    }

    /// A joint state measured at `t` [s] (in the current time base) arrived.
    pub fn joint_state(&mut self, t: f64) {
        self.fresh |= t > self.last_acted_stamp;
    }

    /// Whether to act at `now` [s]; if so, records it, with `measured_at` the time of the
    /// joint state acted on.
    pub fn due(&mut self, now: f64, measured_at: Option<f64>) -> bool {
        // A tolerance of 1e-9 s absorbs rounding in stamps built from step counts.
        let period_elapsed = now - self.last_step_at >= self.period_s - 1e-9;
        let due = if self.sim {
            // Without a new joint state, act (to hold) only once the latest is two periods
            // old: one period after it, the next tick's joint state may still be on its way
            // behind the clock, and acting on the old one would answer that tick for it.
            let missing = measured_at.is_none_or(|t| now - t >= 2.0 * self.period_s - 1e-9);
            self.fresh || (period_elapsed && missing)
        } else {
            period_elapsed
        };
        if due {
            self.last_step_at = now;
            if let Some(t) = measured_at {
                self.last_acted_stamp = t;
            }
            self.fresh = false;
        }
        due
    }
}

/// Goal synchronisation with a whole-body node. It stamps each goal with the stamp of the
/// state it chose the goal from, so the arm node can act on a tick's joint states with the goal
/// of the same tick, as the skill did in training, instead of the previous tick's. Waiting is
/// bounded: after `wait_s` [s, wall] the node acts on the goal it has.
#[derive(Debug, Clone)]
pub struct GoalSync {
    wait_s: f64,
    /// The joint stamp being waited on and since when [s, wall].
    waiting: Option<(f64, f64)>,
}

/// What [`GoalSync::check`] decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sync {
    /// The goal is of this tick (or newer), or there is no goal to wait for: act.
    Ready,
    /// Wait for this tick's goal.
    Wait,
    /// Waited `wait_s` in vain: act on the goal there is.
    Late,
}

impl GoalSync {
    pub fn new(wait_s: f64) -> Self {
        Self {
            wait_s,
            waiting: None,
        }
    }

    /// Whether to act on the joint state stamped `joint_stamp_s` [s] with the goal stamped
    /// `goal_stamp_s` (`None`: no goal yet, nothing to wait for), at `wall_s` [s].
    pub fn check(&mut self, joint_stamp_s: f64, goal_stamp_s: Option<f64>, wall_s: f64) -> Sync {
        let behind = goal_stamp_s.is_some_and(|g| g < joint_stamp_s);
        if !behind {
            self.waiting = None;
            return Sync::Ready;
        }
        match self.waiting {
            Some((stamp, since)) if stamp == joint_stamp_s => {
                if wall_s - since >= self.wait_s {
                    self.waiting = None;
                    Sync::Late
                } else {
                    Sync::Wait
                }
            }
            _ => {
                self.waiting = Some((joint_stamp_s, wall_s));
                if self.wait_s <= 0.0 {
                    self.waiting = None;
                    Sync::Late
                } else {
                    Sync::Wait
                }
            }
        }
    }
}

/// Sim time as the node knows it: the newest of `/clock` and the joint-state stamps. A `/clock`
/// that goes back means a new simulator (a restarted bridge): time starts over from it.
#[derive(Debug, Clone, Default)]
pub struct SimClock {
    now_s: Option<f64>,
}

/// How far `/clock` may go back [s] before it counts as a restart. Sim time is the newest of
/// `/clock` and the joint-state stamps, which come from different DDS writers: on a loaded
/// machine a tick's `/clock` can arrive after the next tick's joint state (measured in the
/// flood test: a "restart" of one tick). A restarted simulator starts over from 0, so a
/// tolerance of a quarter second (7.5 ticks) misses only restarts within that of the start.
pub const BACKWARDS_TOLERANCE_S: f64 = 0.25;

impl SimClock {
    /// A `/clock` message at `t_s`; returns the time it replaced when time went back.
    pub fn clock(&mut self, t_s: f64) -> Option<f64> {
        match self.now_s {
            Some(now) if t_s < now - BACKWARDS_TOLERANCE_S => {
                self.now_s = Some(t_s);
                Some(now)
            }
            _ => {
                self.stamp(t_s);
                None
            }
        }
    }

    /// A joint state stamped `t_s` [s]: stamped in the future of `/clock`, it means the clock
    /// has not arrived yet, so it is the newest time there is.
    pub fn stamp(&mut self, t_s: f64) {
        self.now_s = Some(self.now_s.map_or(t_s, |c| c.max(t_s)));
    }

    /// Sim time [s]; `None` before anything arrived.
    pub fn now_s(&self) -> Option<f64> {
        self.now_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sim_time_acts_once_per_new_joint_state() {
        let mut s = Schedule::new(30.0);
        s.use_sim_time(true);
        s.joint_state(0.0);
        assert!(s.due(0.0, Some(0.0)));
        // The same stamp again, clock unchanged: wait.
        s.joint_state(0.0);
        assert!(!s.due(0.0, Some(0.0)));
        // The next step's joint state: act at once.
        s.joint_state(1.0 / 30.0);
        assert!(s.due(1.0 / 30.0, Some(1.0 / 30.0)));
        // The clock moved on a period but the tick's joint state has not arrived: wait for it.
        assert!(!s.due(2.0 / 30.0, Some(1.0 / 30.0)));
        // No joint states for two periods: act once per period (to hold).
        assert!(s.due(3.0 / 30.0, Some(1.0 / 30.0)));
        assert!(!s.due(3.5 / 30.0, Some(1.0 / 30.0)));
        assert!(s.due(4.0 / 30.0, Some(1.0 / 30.0)));
    }

    #[test]
    fn goal_sync_waits_for_the_goal_of_the_same_tick_but_not_forever() {
        let mut g = GoalSync::new(0.1);
        assert_eq!(
            g.check(1.0, None, 0.0),
            Sync::Ready,
            "no goal: nothing to wait for"
        );
        assert_eq!(g.check(1.0, Some(1.0), 0.0), Sync::Ready);
        assert_eq!(g.check(2.0, Some(1.0), 0.0), Sync::Wait);
        assert_eq!(g.check(2.0, Some(1.0), 0.05), Sync::Wait);
        assert_eq!(g.check(2.0, Some(2.0), 0.06), Sync::Ready);
        assert_eq!(g.check(3.0, Some(2.0), 1.0), Sync::Wait);
        assert_eq!(g.check(3.0, Some(2.0), 1.1), Sync::Late);
        // A new tick starts its own wait.
        assert_eq!(g.check(4.0, Some(2.0), 1.15), Sync::Wait);
        assert_eq!(GoalSync::new(0.0).check(4.0, Some(2.0), 0.0), Sync::Late);
    }

    #[test]
    fn wall_time_acts_at_the_control_rate() {
        let mut s = Schedule::new(10.0);
        assert!(s.due(5.0, None));
        s.joint_state(5.01);
        assert!(!s.due(5.05, Some(5.01)));
        assert!(s.due(5.1, Some(5.01)));
    }

    #[test]
    fn a_clock_that_goes_back_restarts_sim_time() {
        let mut c = SimClock::default();
        assert_eq!(c.now_s(), None);
        assert_eq!(c.clock(100.0), None);
        // A joint state of the new bridge arrives before its clock: time does not go back yet.
        c.stamp(0.0);
        assert_eq!(c.now_s(), Some(100.0));
        // Its clock does: the old time is reported and forgotten.
        assert_eq!(c.clock(0.0), Some(100.0));
        assert_eq!(c.now_s(), Some(0.0));
        c.stamp(1.0 / 30.0);
        assert_eq!(
            c.clock(1.0 / 30.0 - 1e-9),
            None,
            "rounding is not a restart"
        );
        assert_eq!(c.now_s(), Some(1.0 / 30.0));
        // A tick's clock arriving after the next ticks' joint states is no restart either.
        c.stamp(4.0 / 30.0);
        assert_eq!(c.clock(2.0 / 30.0), None, "late, not back");
        assert_eq!(c.now_s(), Some(4.0 / 30.0));
        // After a restart the schedule acts on the first joint state of the new time.
        let mut s = Schedule::new(30.0);
        s.use_sim_time(true);
        s.joint_state(100.0);
        assert!(s.due(100.0, Some(100.0)));
        s.joint_state(0.0);
        assert!(
            !s.due(0.0, Some(0.0)),
            "without forgetting, it would wait 100 s"
        );
        s.forget();
        s.joint_state(0.0);
        assert!(s.due(0.0, Some(0.0)));
    }

    #[test]
    fn switching_to_sim_time_forgets_wall_times() {
        // Wall time ran for 3.5 s before the first /clock (sim time 0): the node must act on
        // the next joint state, not wait for sim time to pass 3.5 s.
        let mut s = Schedule::new(30.0);
        s.joint_state(3.5);
        assert!(s.due(3.5, Some(3.5)));
        assert!(s.use_sim_time(true));
        assert!(!s.use_sim_time(true));
        s.joint_state(0.0);
        assert!(s.due(0.0, Some(0.0)));
    }
}
