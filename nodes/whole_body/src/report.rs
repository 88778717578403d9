//! What the whole-body node reports on `/diagnostics`: what it is doing (driving to the
//! target, or holding and why) and counters of everything it refused. Pure.

use kumi_msgs::diagnostic_msgs::{DiagnosticStatus, KeyValue};

use crate::controller::Hold;

/// Counters and the latest state of one whole-body node.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Report {
    pub targets_accepted: u64,
    pub targets_rejected: u64,
    pub joint_states_rejected: u64,
    pub odometry_rejected: u64,
    /// Messages that could not be decoded at all.
    pub malformed: u64,
    /// Times the node started holding because an input went stale.
    pub stale_holds: u64,
    pub policy_failures: u64,
    /// Times the base tipped over (past the policy's tilt limit) and the node stopped driving.
    pub tipped_over: u64,
    /// Times sim time went back (a restarted simulator) and the node started over.
    pub sim_restarts: u64,
    /// Decisions made on a complete tick (every input with the same stamp).
    pub synchronous_ticks: u64,
    /// Decisions made on the latest of each input after waiting for the rest of a tick.
    pub unsynchronised_ticks: u64,
    /// The latest tool position error [m] and absolute yaw error [rad], with a target.
    pub errors: Option<(f64, f64)>,
    /// Stamp [s] of the first tick the policy ran on with the current target.
    pub target_since_s: Option<f64>,
    /// From a tick's odometry arriving to the commands computed from it being published [s]:
    /// count, sum and largest.
    latency: (u64, f64, f64),
    hold: Option<Hold>,
}

impl Report {
    /// Records one decision's latency [s].
    pub fn latency(&mut self, seconds: f64) {
        self.latency.0 += 1;
        self.latency.1 += seconds;
        self.latency.2 = self.latency.2.max(seconds);
    }

    /// Records one decision's hold; counts a stale hold when it begins.
    pub fn step(&mut self, hold: Option<&Hold>) {
        let was_stale = matches!(self.hold, Some(Hold::Stale { .. }));
        match hold {
            Some(Hold::Stale { .. }) if !was_stale => self.stale_holds += 1,
            Some(Hold::PolicyFailed(_)) => self.policy_failures += 1,
            _ => {}
        }
        self.hold = hold.cloned();
    }

    /// The node's `DiagnosticStatus`, named `kumi whole-body node: <robot>`. WARN while it
    /// holds for a reason other than having no target yet.
    pub fn status(&self, robot: &str) -> DiagnosticStatus {
        let (level, message) = match &self.hold {
            None => (
                DiagnosticStatus::OK,
                "driving the tool to the target".into(),
            ),
            Some(Hold::NoTarget) => (DiagnosticStatus::OK, "holding: no target yet".into()),
            Some(Hold::Waiting { input }) => {
                (DiagnosticStatus::WARN, format!("holding: no {input} yet"))
            }
            Some(Hold::Stale { input, age_s }) => (
                DiagnosticStatus::WARN,
                format!("holding: {input} are {age_s:.2} s old"),
            ),
            Some(Hold::PolicyFailed(e)) => (
                DiagnosticStatus::ERROR,
                format!("holding: policy failed: {e}"),
            ),
            Some(h @ Hold::TippedOver { .. }) => (DiagnosticStatus::ERROR, format!("holding: {h}")),
        };
        let mut values: Vec<(&str, String)> = [
            ("targets_accepted", self.targets_accepted),
            ("targets_rejected", self.targets_rejected),
            ("joint_states_rejected", self.joint_states_rejected),
            ("odometry_rejected", self.odometry_rejected),
            ("rejected_malformed", self.malformed),
            ("stale_holds", self.stale_holds),
            ("policy_failures", self.policy_failures),
            ("tipped_over", self.tipped_over),
            ("sim_restarts", self.sim_restarts),
            ("synchronous_ticks", self.synchronous_ticks),
            ("unsynchronised_ticks", self.unsynchronised_ticks),
        ]
        .iter()
        .map(|(k, v)| (*k, v.to_string()))
        .collect();
        if self.latency.0 > 0 {
            let mean_ms = 1e3 * self.latency.1 / self.latency.0 as f64;
            values.push(("decision_latency_mean_ms", format!("{mean_ms:.2}")));
            values.push((
                "decision_latency_max_ms",
                format!("{:.2}", 1e3 * self.latency.2),
            ));
        }
        if let Some(t) = self.target_since_s {
            values.push(("target_since_s", format!("{t:.9}")));
        }
        if let Some((p, y)) = self.errors {
            values.push(("position_error_m", format!("{p:.4}")));
            values.push(("yaw_error_rad", format!("{y:.4}")));
        }
        DiagnosticStatus {
            level,
            name: format!("kumi whole-body node: {robot}"),
            message,
            hardware_id: robot.to_string(),
            values: values
                .into_iter()
                .map(|(key, value)| KeyValue {
                    key: key.to_string(),
                    value,
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn says_why_it_holds_and_counts_stale_holds_once() {
        let mut r = Report::default();
        r.step(Some(&Hold::NoTarget));
        assert_eq!(r.status("t").message, "holding: no target yet");
        let stale = Hold::Stale {
            input: "odometry messages".into(),
            age_s: 0.7,
        };
        r.step(Some(&stale));
        r.step(Some(&stale));
        let s = r.status("t");
        assert_eq!(s.level, DiagnosticStatus::WARN);
        assert_eq!(s.message, "holding: odometry messages are 0.70 s old");
        assert_eq!(r.stale_holds, 1);
        r.latency(0.002);
        r.latency(0.004);
        let s = r.status("t");
        assert!(s
            .values
            .iter()
            .any(|kv| kv.key == "decision_latency_mean_ms" && kv.value == "3.00"));
        assert!(s
            .values
            .iter()
            .any(|kv| kv.key == "decision_latency_max_ms" && kv.value == "4.00"));
        let tipped = Hold::TippedOver {
            tilt_rad: 0.9,
            limit_rad: 0.785,
        };
        r.step(Some(&tipped));
        r.tipped_over += 1;
        let s = r.status("t");
        assert_eq!(s.level, DiagnosticStatus::ERROR);
        assert_eq!(
            s.message,
            "holding: tipped over: the base tilted 0.900 rad, past the policy's 0.785 rad; send a different target to go on"
        );
        assert!(s
            .values
            .iter()
            .any(|kv| kv.key == "tipped_over" && kv.value == "1"));
        r.errors = Some((0.1, 0.2));
        r.step(None);
        let s = r.status("t");
        assert!(s
            .values
            .iter()
            .any(|kv| kv.key == "position_error_m" && kv.value == "0.1000"));
    }
}
