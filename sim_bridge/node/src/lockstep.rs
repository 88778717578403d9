//! Lockstep gating: the bridge advances one control step when every module that is being
//! commanded has sent its command for the current tick, or when the timeout passes. Pure.
//!
//! Before the first command simulated time stands still, so a run always starts from the same
//! state. Once commands have begun it never stands still again: when every controller goes
//! quiet (a node died), the bridge steps once per timeout, so sim time goes on, the silent
//! modules' commands go stale and they hold, and a restarted node finds a running clock.

use std::collections::BTreeSet;

/// Which modules are commanded and which have spoken this tick.
#[derive(Debug, Default, Clone)]
pub struct Lockstep {
    /// Modules that sent a command for the previous tick: the bridge waits for them.
    expected: BTreeSet<String>,
    /// Modules that sent a command since the last step.
    received: BTreeSet<String>,
    /// Some command has arrived since the bridge started.
    started: bool,
    /// A step has run.
    stepped: bool,
    /// Modules whose first command the first step waits for however long it takes (the
    /// launch knows which nodes it started; discovery may not have found them all yet).
    required_first: BTreeSet<String>,
}

impl Lockstep {
    /// Records an accepted command from `module` for the current tick.
    pub fn received(&mut self, module: &str) {
        self.received.insert(module.to_string());
        self.started = true;
    }

    /// Before the first step: the modules whose command topics have a publisher now. The first
    /// step waits for all of them (or the timeout), so that a run does not start on whichever
    /// node happened to answer first.
    pub fn expect_first(&mut self, modules: impl IntoIterator<Item = String>) {
        if !self.stepped {
            self.expected = modules.into_iter().collect();
        }
    }

    /// Modules the first step waits for without a timeout, whether or not their publishers
    /// have been discovered yet.
    pub fn require_first(&mut self, modules: impl IntoIterator<Item = String>) {
        self.required_first = modules.into_iter().collect();
    }

    /// The step may run: something was received and everything expected has arrived.
    pub fn ready(&self) -> bool {
        !self.received.is_empty()
            && self.expected.is_subset(&self.received)
            && self.first_complete()
    }

    /// Before the first step: every required module has sent its first command (after it:
    /// always).
    fn first_complete(&self) -> bool {
        self.stepped || self.required_first.is_subset(&self.received)
    }

    /// A step may run on the timeout: commands have begun and the first step is not waiting
    /// for a required module.
    pub fn may_time_out(&self) -> bool {
        self.started && self.first_complete()
    }

    /// After a step: next tick expects the modules that spoke this tick. A module that stayed
    /// silent (the step ran on the timeout) is no longer waited for until it speaks again.
    pub fn stepped(&mut self) {
        self.stepped = true;
        self.expected = std::mem::take(&mut self.received);
    }

    /// Commands have begun: the timeout applies. Before the first command the bridge waits
    /// (simulated time stands still).
    pub fn active(&self) -> bool {
        self.started
    }

    /// Modules the bridge is waiting for.
    pub fn missing(&self) -> Vec<String> {
        let required = (!self.stepped).then_some(&self.required_first);
        self.expected
            .iter()
            .chain(required.into_iter().flatten())
            .filter(|m| !self.received.contains(*m))
            .cloned()
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_for_every_module_that_spoke_last_tick() {
        let mut l = Lockstep::default();
        assert!(
            !l.ready() && !l.active(),
            "nothing commanded yet: wait, no timeout"
        );
        l.received("arm0");
        l.received("leg0");
        assert!(l.ready());
        l.stepped();
        l.received("arm0");
        assert!(!l.ready());
        assert_eq!(l.missing(), vec!["leg0".to_string()]);
        l.received("leg0");
        assert!(l.ready());
        // leg0 goes silent: the step runs on the timeout, then only arm0 is awaited.
        l.stepped();
        l.received("arm0");
        assert!(!l.ready());
        l.stepped();
        l.received("arm0");
        assert!(l.ready());
        // Everyone goes quiet (a node died): the bridge keeps stepping on the timeout, waiting
        // for nobody, so that sim time goes on and the silent modules hold.
        l.stepped();
        assert_eq!(l.missing(), vec!["arm0".to_string()]);
        l.stepped();
        assert!(l.active() && !l.ready() && l.missing().is_empty());
    }

    #[test]
    fn the_first_step_waits_for_every_module_with_a_publisher() {
        let mut l = Lockstep::default();
        l.expect_first(["arm0".to_string(), "wheel0".to_string()]);
        l.received("wheel0");
        assert!(!l.ready(), "arm0's node is up: its first answer is awaited");
        assert!(l.active(), "and the timeout applies");
        l.received("arm0");
        assert!(l.ready());
        l.stepped();
        l.expect_first(["arm0".to_string()]);
        l.received("arm0");
        assert!(!l.ready(), "after the first step only who spoke counts");
    }

    #[test]
    fn the_first_step_waits_without_timeout_for_every_required_module() {
        let mut l = Lockstep::default();
        l.require_first(["arm0".to_string(), "leg0".to_string()]);
        // leg0's publisher is not discovered yet: only arm0 is expected from discovery.
        l.expect_first(["arm0".to_string()]);
        l.received("arm0");
        assert!(
            !l.ready(),
            "leg0's node was launched: its first command is awaited"
        );
        assert!(!l.may_time_out(), "however long it takes");
        assert_eq!(l.missing(), vec!["leg0".to_string()]);
        l.received("leg0");
        assert!(l.ready() && l.may_time_out());
        l.stepped();
        l.received("arm0");
        assert!(!l.ready(), "then who spoke last tick is awaited, as always");
        assert!(l.may_time_out(), "with the timeout");
        l.stepped();
        l.stepped();
        assert!(
            l.missing().is_empty(),
            "the requirement was for the first step only"
        );
    }
}
