//! One control tick's state, gathered from messages that arrive one by one: the base odometry
//! and each module's joint states. Pure: the node feeds it messages and asks when to act.
//!
//! In simulation every message of a tick carries the same stamp, so the node acts once per
//! tick on exactly the state training would have seen (all of it from the same step). On
//! hardware the drivers stamp independently: once a new odometry message has waited `wait_s`
//! the node acts on the latest of each input, provided none is older than `stale_after_s`.

use kumi_msgs::builtin_interfaces::Time;
use nalgebra::{Isometry3, Vector3};

/// The base as odometry reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaseState {
    /// The base link's pose in `<robot>/odom`.
    pub pose_w: Isometry3<f64>,
    /// The base's linear velocity [m/s] in `<robot>/odom`.
    pub linear_velocity_w: Vector3<f64>,
    /// The base's angular velocity [rad/s] in `<robot>/odom` (the turn governor reads its z).
    pub angular_velocity_w: Vector3<f64>,
}

/// One module's joints, in the module's actuator order.
#[derive(Debug, Clone, PartialEq)]
pub struct ModuleState {
    /// [rad]
    pub q: Vec<f64>,
    /// [rad/s]
    pub qd: Vec<f64>,
}

/// The state one decision is made on.
#[derive(Debug, Clone, PartialEq)]
pub struct Snapshot {
    /// The odometry's stamp (every input's, in simulation).
    pub stamp: Time,
    pub base: BaseState,
    /// Indexed like the modules [`Tick::new`] was given.
    pub modules: Vec<ModuleState>,
    /// Every input carried the odometry's stamp (one simulated step's state).
    pub synchronous: bool,
}

/// What to do now.
#[derive(Debug, Clone, PartialEq)]
pub enum Due {
    /// Nothing new, or a tick still gathering.
    Wait,
    Act(Snapshot),
    /// A new odometry message, but `input` is missing or `age_s` old: hold.
    Stale {
        input: String,
        age_s: f64,
    },
}

#[derive(Debug, Clone)]
struct Latest<T> {
    stamp: Time,
    value: T,
    /// When it arrived [s, wall].
    arrived_s: f64,
}

/// Gathers ticks for a fixed list of modules.
#[derive(Debug, Clone)]
pub struct Tick {
    modules: Vec<String>,
    base: Option<Latest<BaseState>>,
    joints: Vec<Option<Latest<ModuleState>>>,
    last_decided: Option<Time>,
}

impl Tick {
    pub fn new(modules: Vec<String>) -> Self {
        let joints = vec![None; modules.len()];
        Self {
            modules,
            base: None,
            joints,
            last_decided: None,
        }
    }

    pub fn base(&mut self, stamp: Time, value: BaseState, arrived_s: f64) {
        self.base = Some(Latest {
            stamp,
            value,
            arrived_s,
        });
    }

    /// Module `index`'s joint state.
    pub fn joints(&mut self, index: usize, stamp: Time, value: ModuleState, arrived_s: f64) {
        self.joints[index] = Some(Latest {
            stamp,
            value,
            arrived_s,
        });
    }

    /// Module `index`'s latest joint state still holds at `arrived_s` (a lazy publisher that
    /// is alive but has nothing new: Motion Stack's `joint_read` of still joints).
    pub fn refresh(&mut self, index: usize, arrived_s: f64) {
        if let Some(j) = &mut self.joints[index] {
            j.arrived_s = arrived_s;
        }
    }

    /// Decide again on the latest tick (a new target arrived while simulated time stands
    /// still, or between ticks).
    pub fn decide_again(&mut self) {
        self.last_decided = None;
    }

    /// Seconds [wall] since the latest odometry message arrived; `None` before the first.
    pub fn base_age_s(&self, now_s: f64) -> Option<f64> {
        self.base.as_ref().map(|b| now_s - b.arrived_s)
    }

    /// Forgets everything (a restarted simulator: its stamps start over).
    pub fn forget(&mut self) {
        self.base = None;
        self.joints.iter_mut().for_each(|j| *j = None);
        self.last_decided = None;
    }

    /// Whether to act at `now_s` [s, wall], and on what. Decides at most once per odometry
    /// stamp.
    pub fn due(&mut self, now_s: f64, wait_s: f64, stale_after_s: f64) -> Due {
        let Some(base) = &self.base else {
            return Due::Wait;
        };
        if self.last_decided == Some(base.stamp) {
            return Due::Wait;
        }
        let same_tick = self
            .joints
            .iter()
            .all(|j| j.as_ref().is_some_and(|j| j.stamp == base.stamp));
        if !same_tick && now_s - base.arrived_s < wait_s {
            return Due::Wait;
        }
        self.last_decided = Some(base.stamp);
        if !same_tick {
            for (name, joints) in self.modules.iter().zip(&self.joints) {
                let age_s = joints
                    .as_ref()
                    .map_or(f64::INFINITY, |j| now_s - j.arrived_s);
                if age_s > stale_after_s {
                    return Due::Stale {
                        input: format!("{name} joint states"),
                        age_s,
                    };
                }
            }
        }
        Due::Act(Snapshot {
            stamp: base.stamp,
            base: base.value,
            modules: self
                .joints
                .iter()
                .map(|j| j.as_ref().expect("checked above").value.clone())
                .collect(),
            synchronous: same_tick,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(ns: u32) -> Time {
        Time {
            sec: 0,
            nanosec: ns,
        }
    }

    fn base() -> BaseState {
        BaseState {
            pose_w: Isometry3::identity(),
            linear_velocity_w: Vector3::zeros(),
            angular_velocity_w: Vector3::zeros(),
        }
    }

    fn joints(v: f64) -> ModuleState {
        ModuleState {
            q: vec![v],
            qd: vec![0.0],
        }
    }

    #[test]
    fn acts_once_per_tick_when_every_input_of_the_tick_is_in() {
        let mut tick = Tick::new(vec!["arm0".into(), "wheel0".into()]);
        assert_eq!(tick.due(0.0, 0.03, 0.5), Due::Wait);
        tick.base(t(1), base(), 0.0);
        tick.joints(0, t(1), joints(1.0), 0.0);
        assert_eq!(tick.due(0.001, 0.03, 0.5), Due::Wait, "wheel0 missing");
        tick.joints(1, t(1), joints(2.0), 0.002);
        let Due::Act(s) = tick.due(0.002, 0.03, 0.5) else {
            panic!("complete tick")
        };
        assert_eq!(
            (s.stamp, s.modules[1].q[0], s.synchronous),
            (t(1), 2.0, true)
        );
        assert_eq!(tick.due(0.003, 0.03, 0.5), Due::Wait, "once per tick");
        tick.decide_again();
        assert!(matches!(tick.due(0.003, 0.03, 0.5), Due::Act(s) if s.stamp == t(1)));
        assert_eq!(tick.base_age_s(0.01), Some(0.01));
        // The next tick's joint states first, then its odometry.
        tick.joints(0, t(2), joints(3.0), 0.033);
        tick.joints(1, t(2), joints(4.0), 0.033);
        assert_eq!(tick.due(0.034, 0.03, 0.5), Due::Wait, "old odometry");
        tick.base(t(2), base(), 0.034);
        assert!(matches!(tick.due(0.034, 0.03, 0.5), Due::Act(s) if s.modules[0].q[0] == 3.0));
    }

    #[test]
    fn unsynchronised_inputs_act_on_the_latest_after_the_wait_unless_stale() {
        let mut tick = Tick::new(vec!["arm0".into()]);
        tick.joints(0, t(5), joints(1.0), 0.0);
        tick.base(t(7), base(), 0.01);
        assert_eq!(tick.due(0.02, 0.03, 0.5), Due::Wait, "still waiting");
        assert!(matches!(tick.due(0.05, 0.03, 0.5), Due::Act(s) if !s.synchronous));
        tick.base(t(9), base(), 1.0);
        match tick.due(1.1, 0.03, 0.5) {
            Due::Stale { input, age_s } => {
                assert_eq!(input, "arm0 joint states");
                assert!((age_s - 1.1).abs() < 1e-12);
            }
            other => panic!("{other:?}"),
        }
        // A module never heard from is stale too.
        let mut tick = Tick::new(vec!["arm0".into()]);
        tick.base(t(1), base(), 0.0);
        assert!(
            matches!(tick.due(1.0, 0.03, 0.5), Due::Stale { age_s, .. } if age_s.is_infinite())
        );
        // A lazy publisher alive: its last joint state holds.
        tick.joints(0, t(1), joints(1.0), 0.0);
        tick.base(t(2), base(), 5.0);
        tick.refresh(0, 5.0);
        assert!(matches!(tick.due(5.1, 0.03, 0.5), Due::Act(_)));
        tick.forget();
        assert_eq!(tick.due(2.0, 0.03, 0.5), Due::Wait);
    }
}
