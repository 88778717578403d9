//! Lockstep gating: the bridge advances one control step when every module that is being
//! commanded has sent its command for the current tick, or when the timeout passes. Pure.

use std::collections::BTreeSet;

/// Which modules are commanded and which have spoken this tick.
#[derive(Debug, Default, Clone)]
pub struct Lockstep {
    /// Modules that sent a command for the previous tick: the bridge waits for them.
    expected: BTreeSet<String>,
    /// Modules that sent a command since the last step.
    received: BTreeSet<String>,
}

impl Lockstep {
    /// Records an accepted command from `module` for the current tick.
    pub fn received(&mut self, module: &str) {
        self.received.insert(module.to_string());
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

    /// Some module is being commanded: the timeout applies. Before the first command, and after
    /// every controller has gone quiet, the bridge waits (simulated time stands still).
    pub fn active(&self) -> bool {
        !self.expected.is_empty() || !self.received.is_empty()
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
        // Everyone goes quiet: after one timeout step the bridge idles.
        l.stepped();
        assert!(l.active());
        l.stepped();
        assert!(!l.active());
    }
}
