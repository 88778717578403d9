//! The interface between environments and the trainer.

/// What one environment step produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Transition {
    /// The observation after the step (before any reset).
    pub observation: Vec<f32>,
    pub reward: f64,
    /// The episode truly ended (no future reward).
    pub terminated: bool,
    /// The episode hit its time limit (the return is bootstrapped).
    pub truncated: bool,
    /// Reaching errors at the end of a goal period (position [m], orientation [rad]), if one
    /// ended at this step: the paper's final errors.
    pub goal_errors: Option<(f64, f64)>,
}

/// An episodic environment with continuous actions.
pub trait Environment: Send {
    fn observation_dim(&self) -> usize;
    fn action_dim(&self) -> usize;
    /// Starts an episode and returns its first observation.
    fn reset(&mut self) -> Vec<f32>;
    /// Applies an action. After a terminated or truncated step the trainer calls `reset`.
    fn step(&mut self, action: &[f32]) -> Transition;
}

impl Environment for crate::arm_reach::ArmReach {
    fn observation_dim(&self) -> usize {
        kumi_policies::observation::OBSERVATION_DIM
    }

    fn action_dim(&self) -> usize {
        kumi_policies::observation::JOINTS
    }

    fn reset(&mut self) -> Vec<f32> {
        crate::arm_reach::ArmReach::reset(self).to_vec()
    }

    fn step(&mut self, action: &[f32]) -> Transition {
        let mut a = [0.0_f32; kumi_policies::observation::JOINTS];
        a.copy_from_slice(action);
        let o = crate::arm_reach::ArmReach::step(self, &a);
        Transition {
            observation: o.observation.to_vec(),
            reward: o.reward,
            terminated: false,
            truncated: o.truncated,
            goal_errors: o
                .goal_ended
                .then_some((o.position_error, o.orientation_error)),
        }
    }
}
