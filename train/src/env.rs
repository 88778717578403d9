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
    /// Task-specific figures this step produced, by name (one of the environment's
    /// [`Environment::metric_names`]): the trainer logs the mean of each over a rollout.
    pub metrics: Vec<(&'static str, f64)>,
}

/// An episodic environment with continuous actions.
pub trait Environment: Send {
    /// Values per observation: what the critic reads.
    fn observation_dim(&self) -> usize;
    /// How many leading observation values the actor reads (all by default; fewer when the
    /// environment appends values only the critic sees).
    fn actor_observation_dim(&self) -> usize {
        self.observation_dim()
    }
    fn action_dim(&self) -> usize;
    /// Starts an episode and returns its first observation.
    fn reset(&mut self) -> Vec<f32>;
    /// Applies an action. After a terminated or truncated step the trainer calls `reset`.
    fn step(&mut self, action: &[f32]) -> Transition;
    /// Names of the figures [`Transition::metrics`] may carry, in the order they are logged.
    fn metric_names(&self) -> &'static [&'static str] {
        &[]
    }
}

/// The arm-reach environment's figures: errors at the end of each goal period.
pub const REACH_METRICS: [&str; 2] = ["final_position_error_m", "final_orientation_error_rad"];
/// The whole-body environment's figures: errors at the end of each episode that ran its
/// time, and the fraction of episodes that ended by a fall.
pub const BODY_METRICS: [&str; 3] = [
    "final_position_error_m",
    "final_yaw_error_rad",
    "termination_rate",
];
/// With `[replay]`: the same over fresh episodes only, and the fraction of replayed episodes
/// that ended by a fall.
pub const BODY_REPLAY_METRICS: [&str; 4] = [
    BODY_METRICS[0],
    BODY_METRICS[1],
    BODY_METRICS[2],
    "replayed_termination_rate",
];

/// The arm-reach environment in training: the observation's leading values the skill is
/// trained on ([`crate::arm_reach::ArmReachConfig::observation_dim`]).
impl Environment for crate::arm_reach::ArmReach {
    fn observation_dim(&self) -> usize {
        self.config().observation_dim()
    }

    fn action_dim(&self) -> usize {
        kumi_policies::observation::JOINTS
    }

    fn reset(&mut self) -> Vec<f32> {
        crate::arm_reach::ArmReach::reset(self)[..self.config().observation_dim()].to_vec()
    }

    fn step(&mut self, action: &[f32]) -> Transition {
        let mut a = [0.0_f32; kumi_policies::observation::JOINTS];
        a.copy_from_slice(action);
        let o = crate::arm_reach::ArmReach::step(self, &a);
        Transition {
            observation: o.observation[..self.config().observation_dim()].to_vec(),
            reward: o.reward,
            terminated: o.terminated,
            truncated: o.truncated,
            metrics: if o.goal_ended {
                vec![
                    (REACH_METRICS[0], o.position_error),
                    (REACH_METRICS[1], o.orientation_error),
                ]
            } else {
                Vec::new()
            },
        }
    }

    fn metric_names(&self) -> &'static [&'static str] {
        &REACH_METRICS
    }
}

/// The whole-body environment in training: the policy's observation, noised by
/// `[observation_noise]`, then what only the critic sees (`[critic]`; nothing without it).
impl Environment for crate::whole_body::WholeBody {
    fn observation_dim(&self) -> usize {
        crate::whole_body::WholeBody::observation_dim(self) + self.critic_extras_dim()
    }

    fn actor_observation_dim(&self) -> usize {
        crate::whole_body::WholeBody::observation_dim(self)
    }

    fn action_dim(&self) -> usize {
        self.terms().size()
    }

    fn reset(&mut self) -> Vec<f32> {
        let mut observation = crate::whole_body::WholeBody::reset(self);
        self.add_observation_noise(&mut observation);
        observation.extend(self.critic_extras());
        observation
    }

    fn step(&mut self, action: &[f32]) -> Transition {
        let o = crate::whole_body::WholeBody::step(self, action);
        let mut metrics = Vec::new();
        let ended = o.terminated || o.truncated;
        if ended && o.replayed {
            metrics.push((BODY_REPLAY_METRICS[3], f64::from(u8::from(o.terminated))));
        } else if ended {
            metrics.push((BODY_METRICS[2], f64::from(u8::from(o.terminated))));
        }
        if o.truncated && !o.terminated && !o.replayed {
            metrics.push((BODY_METRICS[0], o.position_error));
            metrics.push((BODY_METRICS[1], o.yaw_error));
        }
        let mut observation = o.observation;
        self.add_observation_noise(&mut observation);
        observation.extend(self.critic_extras());
        Transition {
            observation,
            reward: o.reward,
            terminated: o.terminated,
            truncated: o.truncated,
            metrics,
        }
    }

    fn metric_names(&self) -> &'static [&'static str] {
        if self.replays() {
            &BODY_REPLAY_METRICS
        } else {
            &BODY_METRICS
        }
    }
}
