//! PPO learns a tiny task in seconds: a point on a line must move to a target.

use kumi_train::env::{Environment, Transition};
use kumi_train::ppo::trainer::{PpoConfig, Trainer};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Observation (x, target); action moves x by 0.1 * clip(a, -1, 1); reward -|x - target|.
struct PointReach {
    x: f32,
    target: f32,
    t: usize,
    rng: ChaCha8Rng,
}

impl Environment for PointReach {
    fn observation_dim(&self) -> usize {
        2
    }

    fn action_dim(&self) -> usize {
        1
    }

    fn reset(&mut self) -> Vec<f32> {
        self.x = self.rng.random_range(-1.0..1.0);
        self.target = self.rng.random_range(-1.0..1.0);
        self.t = 0;
        vec![self.x, self.target]
    }

    fn step(&mut self, action: &[f32]) -> Transition {
        self.x += 0.1 * action[0].clamp(-1.0, 1.0);
        self.t += 1;
        Transition {
            observation: vec![self.x, self.target],
            reward: -f64::from((self.x - self.target).abs()),
            terminated: false,
            truncated: self.t >= 20,
            metrics: Vec::new(),
        }
    }
}

/// `n` environments at x = 0, environment `i` drawing its targets from seed `first_seed + i`.
fn point_reaches(n: u64, first_seed: u64) -> Vec<PointReach> {
    (0..n)
        .map(|i| PointReach {
            x: 0.0,
            target: 0.0,
            t: 0,
            rng: ChaCha8Rng::seed_from_u64(first_seed + i),
        })
        .collect()
}

fn trainer(seed: u64) -> Trainer<PointReach> {
    let envs = point_reaches(8, seed * 100);
    let config = PpoConfig {
        seed,
        num_envs: 8,
        rollout_steps: 64,
        total_steps: 0,
        hidden: vec![32, 32],
        learning_rate: 3e-3,
        epochs: 4,
        minibatches: 4,
        entropy_coef: 0.0,
        ..PpoConfig::default()
    };
    Trainer::new(config, envs).unwrap()
}

#[test]
fn reward_improves_on_a_tiny_task() {
    let mut t = trainer(1);
    let first = t.iterate().mean_step_reward;
    let mut last = first;
    for _ in 0..24 {
        last = t.iterate().mean_step_reward;
    }
    // A policy that does nothing scores about -0.67 per step; one that walks straight to the
    // target about -0.25. Training must close most of that gap.
    assert!(first < -0.5, "the untrained policy should be poor: {first}");
    assert!(
        last > -0.35,
        "PPO did not learn: mean step reward {first:.3} -> {last:.3}"
    );
}

#[test]
fn a_noise_schedule_brings_the_action_std_down_to_its_final_value() {
    let envs = point_reaches(8, 0);
    // Four iterations of 512 steps; the cap falls from -0.5 right away to -2.0 at the end.
    let config = PpoConfig {
        num_envs: 8,
        rollout_steps: 64,
        total_steps: 4 * 512,
        hidden: vec![16],
        entropy_coef: 0.05, // pushes the noise up: only the cap brings it down
        anneal_after: 0.0,
        final_log_std: Some(-2.0),
        ..PpoConfig::default()
    };
    let mut t = Trainer::new(config, envs).unwrap();
    let stds: Vec<f64> = (0..4).map(|_| t.iterate().action_std).collect();
    for (k, std) in stds.iter().enumerate() {
        let cap = (-0.5 - 1.5 * (k + 1) as f64 / 4.0).exp();
        assert!(
            *std <= cap + 1e-6,
            "iteration {k}: std {std} above the cap {cap}"
        );
    }
    assert!((stds[3] - (-2.0f64).exp()).abs() < 1e-6, "{stds:?}");
}

#[test]
fn training_is_reproducible_for_a_seed() {
    let run = |seed| {
        let mut t = trainer(seed);
        (0..3)
            .map(|_| t.iterate().mean_step_reward)
            .collect::<Vec<_>>()
    };
    assert_eq!(run(7), run(7));
    assert_ne!(run(7), run(8));
}

#[test]
fn a_checkpoint_restores_the_policy_exactly() {
    let dir = std::env::temp_dir().join(format!("kumi-ckpt-{}", std::process::id()));
    let mut a = trainer(3);
    for _ in 0..3 {
        a.iterate();
    }
    a.save_checkpoint(&dir).unwrap();
    let mut b = trainer(4);
    assert_ne!(a.act(&[0.3, -0.4]), b.act(&[0.3, -0.4]));
    b.load_checkpoint(&dir).unwrap();
    assert_eq!(
        a.act(&[0.3, -0.4]),
        b.act(&[0.3, -0.4]),
        "same deterministic action"
    );
    assert_eq!((b.iteration, b.env_steps), (3, 3 * 8 * 64));
    assert_eq!(a.norm, b.norm);
    // A checkpoint from another network shape is refused with a clear error.
    let envs = point_reaches(2, 0);
    let mut other = Trainer::new(
        PpoConfig {
            hidden: vec![8],
            ..PpoConfig::default()
        },
        envs,
    )
    .unwrap();
    let err = other.load_checkpoint(&dir).unwrap_err().to_string();
    assert!(err.contains("values, the network"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn without_updates_the_policy_does_not_move() {
    // Learning rate 0: every minibatch sees the rollout's own policy, so the measured KL
    // divergence and the clipped fraction are 0 (a check on the bookkeeping of old log-probs).
    let mut t = trainer(3);
    t.learner.config.learning_rate = 0.0;
    let mut t = Trainer::new(t.learner.config.clone(), point_reaches(8, 0)).unwrap();
    for _ in 0..3 {
        let s = t.iterate();
        assert!(s.approx_kl.abs() < 1e-6, "KL {}", s.approx_kl);
        assert_eq!(s.clip_fraction, 0.0);
    }
}

#[test]
fn training_gives_the_same_bits_on_one_thread_or_two() {
    // Minibatches are cut into fixed blocks whatever the thread count, and their gradients are
    // summed in order: the thread count must not change a single bit.
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut t = trainer(5);
            // Minibatches of 512 rows: four blocks in parallel.
            t.learner.config.minibatches = 1;
            for _ in 0..2 {
                t.iterate();
            }
            (t.learner.net.clone(), t.act(&[0.3, -0.4]))
        })
    };
    assert_eq!(run(1), run(2));
}
