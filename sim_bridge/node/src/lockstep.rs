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
}

impl Lockstep {
    /// Records an accepted command from `module` for the current tick.
    pub fn received(&mut self, module: &str) {
        self.received.insert(module.to_string());
        self.started = true;
    }

    /// The step may run: something was received and everything expected has arrived.
    pub fn ready(&self) -> bool {
        !self.received.is_empty() && self.expected.is_subset(&self.received)
    }

    /// After a step: next tick expects the modules that spoke this tick. A module that stayed
    /// silent (the step ran on the timeout) is no longer waited for until it speaks again.
    pub fn stepped(&mut self) {
        self.expected = std::mem::take(&mut self.received);
    }

    /// Commands have begun: the timeout applies. Before the first command the bridge waits
    /// (simulated time stands still).
    pub fn active(&self) -> bool {
        self.started
    }

    /// Modules the bridge is waiting for.
    pub fn missing(&self) -> Vec<String> {
        self.expected.difference(&self.received).cloned().collect()
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
}
