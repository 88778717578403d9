//! What the arm node reports on `/diagnostics`: what it is doing (tracking a goal, or holding
//! and why) and counters of everything it refused. Pure: the node feeds it events.

use kumi_msgs::diagnostic_msgs::{DiagnosticStatus, KeyValue};

use crate::controller::Hold;

/// Counters and the latest state of one arm node.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Report {
    pub goals_accepted: u64,
    pub goals_rejected: u64,
    pub joint_states_rejected: u64,
    /// Messages that could not be decoded at all.
    pub malformed: u64,
    /// Times the node started holding because its joint states went stale.
    pub stale_holds: u64,
    pub policy_failures: u64,
    /// Times sim time went back (a restarted simulator) and the node started over.
    pub sim_restarts: u64,
    /// Ticks acted on with the previous tick's goal after waiting for the tick's own in vain
    /// (goal sync with a whole-body node).
    pub late_goals: u64,
    /// The latest step's hold, `None` while the policy runs.
    hold: Option<Hold>,
}

impl Report {
    /// Records one control step's outcome; counts a stale hold when it begins.
    pub fn step(&mut self, hold: Option<&Hold>) {
        let was_stale = matches!(self.hold, Some(Hold::Stale { .. }));
        match hold {
            Some(Hold::Stale { .. }) if !was_stale => self.stale_holds += 1,
            Some(Hold::PolicyFailed(_)) => self.policy_failures += 1,
            _ => {}
        }
        self.hold = hold.cloned();
    }

    /// The node's `DiagnosticStatus`, named `kumi arm node: <robot>/<module>`. WARN while it
    /// holds for a reason other than having no goal yet.
    pub fn status(&self, robot: &str, module: &str) -> DiagnosticStatus {
        let (level, message) = match &self.hold {
            None => (DiagnosticStatus::OK, "tracking the goal".to_string()),
            Some(Hold::NoGoal) => (DiagnosticStatus::OK, "holding: no goal yet".to_string()),
            Some(Hold::NoJointState) => (
                DiagnosticStatus::WARN,
                "holding: no joint state yet".to_string(),
            ),
            Some(Hold::Stale { age_s }) => (
                DiagnosticStatus::WARN,
                format!("holding: joint states are {age_s:.2} s old"),
            ),
            Some(Hold::PolicyFailed(e)) => (
                DiagnosticStatus::ERROR,
                format!("holding: policy failed: {e}"),
            ),
        };
        let counters = [
            ("goals_accepted", self.goals_accepted),
            ("goals_rejected", self.goals_rejected),
            ("joint_states_rejected", self.joint_states_rejected),
            ("rejected_malformed", self.malformed),
            ("stale_holds", self.stale_holds),
            ("policy_failures", self.policy_failures),
            ("sim_restarts", self.sim_restarts),
            ("late_goals", self.late_goals),
        ];
        DiagnosticStatus {
            level,
            name: format!("kumi arm node: {robot}/{module}"),
            message,
            hardware_id: format!("{robot}/{module}"),
            values: counters
                .iter()
                .map(|(key, value)| KeyValue {
                    key: key.to_string(),
                    value: value.to_string(),
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn value(status: &DiagnosticStatus, key: &str) -> String {
        status
            .values
            .iter()
            .find(|kv| kv.key == key)
            .map(|kv| kv.value.clone())
            .unwrap()
    }

    #[test]
    fn counts_stale_holds_once_each_and_says_why_it_holds() {
        let mut r = Report::default();
        r.step(Some(&Hold::NoGoal));
        let s = r.status("tricycle", "arm0");
        assert_eq!(
            (s.level, s.message.as_str(), s.name.as_str()),
            (
                DiagnosticStatus::OK,
                "holding: no goal yet",
                "kumi arm node: tricycle/arm0"
            )
        );
        r.step(None);
        r.step(Some(&Hold::Stale { age_s: 0.5 }));
        r.step(Some(&Hold::Stale { age_s: 0.6 }));
        let s = r.status("tricycle", "arm0");
        assert_eq!(s.level, DiagnosticStatus::WARN);
        assert_eq!(s.message, "holding: joint states are 0.60 s old");
        assert_eq!(value(&s, "stale_holds"), "1");
        r.step(None);
        r.step(Some(&Hold::Stale { age_s: 0.3 }));
        r.step(Some(&Hold::PolicyFailed("boom".into())));
        let s = r.status("tricycle", "arm0");
        assert_eq!(
            (value(&s, "stale_holds"), s.level),
            ("2".into(), DiagnosticStatus::ERROR)
        );
        assert_eq!(value(&s, "policy_failures"), "1");
    }
}
