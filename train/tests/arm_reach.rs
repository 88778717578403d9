//! The arm-reach environment behaves as the paper's section IV-A says.

use std::sync::Arc;

use kumi_model::{assemble, load_morphology, ModuleLibrary, RobotModel};
use kumi_train::arm_reach::{ArmReach, ArmReachConfig, EnvError};

fn model(name: &str) -> Arc<RobotModel> {
    let library = ModuleLibrary::shipped();
    Arc::new(assemble(
        &load_morphology(name, &library).unwrap(),
        &library,
    ))
}

fn env(seed: u64) -> ArmReach {
    ArmReach::new(model("arm"), ArmReachConfig::default(), seed).unwrap()
}

#[test]
fn only_a_fixed_single_arm_is_accepted() {
    assert!(matches!(
        ArmReach::new(model("dragon"), ArmReachConfig::default(), 0),
        Err(EnvError::NotASingleArm(_))
    ));
}

#[test]
fn reset_draws_joints_and_goals_in_range() {
    let mut e = env(1);
    for _ in 0..20 {
        let obs = e.reset();
        assert!(
            obs[..7].iter().all(|q| q.abs() <= 0.5 + 1e-3),
            "initial joints {:?}",
            &obs[..7]
        );
        let g = e.goal().position_b;
        assert!(
            (-0.1..=0.6).contains(&g.x)
                && (-0.3..=0.3).contains(&g.y)
                && (0.6..=1.3).contains(&g.z),
            "{g}"
        );
        // The observed goal is the goal plus a little noise.
        assert!((obs[14] as f64 - g.x).abs() < 0.05 && (obs[16] as f64 - g.z).abs() < 0.05);
        assert!(obs[17] >= 0.0, "quaternion written with w >= 0");
    }
}

#[test]
fn zero_action_holds_and_a_saturated_action_moves_one_slew_per_step() {
    let mut e = env(2);
    let start = e.reset();
    let mut out = None;
    for _ in 0..30 {
        out = Some(e.step(&[0.0; 7]));
    }
    let held = out.unwrap().observation;
    for j in 0..7 {
        assert!(
            (held[j] - start[j]).abs() < 0.02,
            "joint{} drifted from {} to {}",
            j + 1,
            start[j],
            held[j]
        );
    }
    // +1 on joint1 for 10 steps: 10 x 0.05 rad.
    for _ in 0..10 {
        out = Some(e.step(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]));
    }
    for _ in 0..30 {
        out = Some(e.step(&[0.0; 7]));
    }
    let moved = f64::from(out.unwrap().observation[0] - held[0]);
    assert!(
        (moved - 10.0 * e.skill().increment_scale[0]).abs() < 0.02,
        "joint1 moved {moved} rad"
    );
}

#[test]
fn goals_change_every_4_s_and_episodes_end_at_12_s() {
    let mut e = env(3);
    e.reset();
    let mut goal_ends = Vec::new();
    for k in 1..=360 {
        let before = e.goal();
        let o = e.step(&[0.0; 7]);
        if o.goal_ended {
            goal_ends.push(k);
            assert_ne!(before, e.goal(), "a new goal after the period");
        }
        assert_eq!(o.truncated, k == 360);
        assert!(o.reward.is_finite());
        assert!(
            o.position_error >= 0.0
                && (0.0..=std::f64::consts::PI + 1e-9).contains(&o.orientation_error)
        );
    }
    assert_eq!(goal_ends, vec![120, 240, 360]);
}

#[test]
fn the_same_seed_gives_the_same_episode() {
    let run = |seed| {
        let mut e = env(seed);
        let mut obs = vec![e.reset()];
        for k in 0..60 {
            let a = [((k % 7) as f32 - 3.0) / 3.0; 7];
            obs.push(e.step(&a).observation);
        }
        obs
    };
    assert_eq!(run(5), run(5));
    assert_ne!(run(5), run(6));
}

#[test]
fn the_observation_is_the_world_state_and_the_noisy_goal() {
    let mut e = env(4);
    e.reset();
    let o = e.step(&[0.3, -0.2, 0.1, 0.0, 0.5, -0.5, 1.0]);
    assert_eq!(
        o.observation,
        e.observation(),
        "the step returns what observation() builds"
    );
    // Values 22-28: how far the targets lead the joints.
    let q = e.world().joint_positions();
    let lead: Vec<f32> = (0..7).map(|j| (e.targets()[j] - q[j]) as f32).collect();
    assert_eq!(&o.observation[21..28], lead.as_slice());
    assert!(
        lead.iter().any(|l| l.abs() > 1e-4),
        "the targets lead the moving joints"
    );
    let tool = e.tool_pose_b();
    let (p, r) = e.errors();
    assert!((p - (tool.translation.vector - e.goal().position_b).norm()).abs() < 1e-12);
    assert!(r >= 0.0);
    // Values 29-34: the observed goal less the tool, which forward kinematics of the measured
    // angles puts where the simulator has it, to within the servos' compliance.
    let to_goal = e.observed_goal().position_b - tool.translation.vector;
    for i in 0..3 {
        assert!(
            (f64::from(o.observation[28 + i]) - to_goal[i]).abs() < 2e-3,
            "{:?} against {to_goal:?}",
            &o.observation[28..31]
        );
    }
    let turn = (e.observed_goal().orientation_b * tool.rotation.inverse()).angle();
    let observed = nalgebra::Vector3::from_fn(|i, _| f64::from(o.observation[31 + i]));
    assert!(
        (observed.norm() - turn).abs() < 2e-3,
        "{observed:?} against {turn}"
    );
}

#[test]
fn the_tool_error_is_observed_only_after_the_lead_and_the_joint_step_after_it() {
    use kumi_train::arm_reach::SkillObservation;
    let config = |targets_lead, tool_error, joint_step| ArmReachConfig {
        observation: SkillObservation {
            targets_lead,
            tool_error,
            joint_step,
        },
        ..ArmReachConfig::default()
    };
    let dim =
        |c: ArmReachConfig| ArmReach::new(model("arm"), c, 0).map(|e| e.config().observation_dim());
    assert_eq!(dim(config(false, false, false)).unwrap(), 21);
    assert_eq!(dim(config(true, false, false)).unwrap(), 28);
    assert_eq!(dim(config(true, true, false)).unwrap(), 34);
    assert_eq!(dim(config(true, true, true)).unwrap(), 41);
    for skipped in [config(false, true, false), config(true, false, true)] {
        let err = dim(skipped).unwrap_err().to_string();
        assert!(err.contains("needs"), "{err}");
    }
}

#[test]
fn the_joint_step_leads_the_arm_to_a_reachable_goal() {
    // Following the observed step (at most the skill's largest increment per control step)
    // brings the tool to a goal the arm can reach: the feature means what it says.
    use kumi_policies::kinematics::ToolKinematics;
    use kumi_policies::observation::{build, OBSERVATION_DIM, TOOL_DIM};
    let arm = model("arm");
    let fk = ToolKinematics::new(&arm, &arm.modules[0]).unwrap();
    let tool_pose_b = |q: &[f64; 7]| fk.tool_pose_b(q);
    let target = [0.4, -0.6, 0.3, -1.2, 0.2, 0.8, -0.3];
    let pose = fk.tool_pose_b(&target);
    let goal = kumi_policies::observation::Goal {
        position_b: pose.translation.vector,
        orientation_b: pose.rotation,
    };
    let mut q = [0.0; 7];
    for _ in 0..300 {
        let obs = build(&q, &[0.0; 7], &q, &goal, &tool_pose_b, fk.limits_rad());
        for j in 0..7 {
            q[j] += f64::from(obs[TOOL_DIM + j]).clamp(-0.05, 0.05);
        }
    }
    let obs = build(&q, &[0.0; 7], &q, &goal, &tool_pose_b, fk.limits_rad());
    let error_m = f64::from(obs[28])
        .hypot(f64::from(obs[29]))
        .hypot(f64::from(obs[30]));
    assert!(error_m < 1e-3, "{error_m} m left, at {q:?}");
    assert!(
        obs[TOOL_DIM..OBSERVATION_DIM]
            .iter()
            .all(|s| s.abs() < 1e-3),
        "{obs:?}"
    );
}

#[test]
fn working_poses_are_the_home_tool_poses_of_every_shipped_arm_module() {
    use kumi_policies::kinematics::ToolKinematics;
    use kumi_train::arm_reach::GoalConfig;
    let config = |spread_rad| GoalConfig {
        paper_box_weight: 0.0,
        spread_rad,
        working_configurations: vec!["minimal".into(), "dragon".into(), "tricycle".into()],
        working_start_weight: 0.0,
    };
    let goals = config(0.0).resolve().unwrap();
    // The manipulators of the three robots share one home; Dragon's second arm stands straight;
    // Tricycle's three legs differ in their last joint: five distinct configurations.
    assert_eq!(goals.centres.len(), 5, "{:?}", goals.centres);
    // With no spread, a working goal is exactly one module's home tool pose, by the arm's own
    // kinematics; a Tricycle leg's tool stands at about (0.85, 0, 0.76) m, outside the paper's box.
    let arm = model("arm");
    let fk = ToolKinematics::new(&arm, &arm.modules[0]).unwrap();
    let leg = fk.tool_pose_b(&goals.centres[2]).translation.vector;
    assert!(
        (leg - nalgebra::Vector3::new(0.85, 0.0, 0.76)).norm() < 0.05,
        "leg tool at home: {leg:?}"
    );
    let mut e = ArmReach::new(
        arm.clone(),
        ArmReachConfig {
            goals: goals.clone(),
            ..ArmReachConfig::default()
        },
        3,
    )
    .unwrap();
    for _ in 0..20 {
        e.reset();
        let g = e.goal().position_b;
        assert!(
            goals
                .centres
                .iter()
                .any(|q| (fk.tool_pose_b(q).translation.vector - g).norm() < 1e-9),
            "goal {g:?} is not a home tool pose"
        );
    }
    // Bad settings and unknown robots are refused with a message.
    let mut bad = config(0.5);
    bad.paper_box_weight = 1.5;
    assert!(bad
        .resolve()
        .unwrap_err()
        .to_string()
        .contains("paper_box_weight"));
    let mut unknown = config(0.5);
    unknown.working_configurations = vec!["no-such-robot".into()];
    assert!(unknown
        .resolve()
        .unwrap_err()
        .to_string()
        .contains("no-such-robot"));
}

#[test]
fn working_starts_begin_at_a_module_home_with_the_first_goal_around_it() {
    use kumi_policies::kinematics::ToolKinematics;
    use kumi_train::arm_reach::GoalConfig;
    let goals = GoalConfig {
        paper_box_weight: 0.0,
        spread_rad: 0.0,
        working_configurations: vec!["tricycle".into()],
        working_start_weight: 1.0,
    }
    .resolve()
    .unwrap();
    let arm = model("arm");
    let fk = ToolKinematics::new(&arm, &arm.modules[0]).unwrap();
    let mut e = ArmReach::new(
        arm.clone(),
        ArmReachConfig {
            goals: goals.clone(),
            ..ArmReachConfig::default()
        },
        4,
    )
    .unwrap();
    for _ in 0..20 {
        let obs = e.reset();
        // No spread: the episode starts exactly at one centre and its goal is that centre's
        // home tool pose, so the skill starts on its goal.
        let q: [f64; 7] = std::array::from_fn(|j| f64::from(obs[j]));
        let centre = goals
            .centres
            .iter()
            .find(|c| c.iter().zip(&q).all(|(a, b)| (a - b).abs() < 1e-5))
            .unwrap_or_else(|| panic!("start {q:?} is no centre"));
        let home = fk.tool_pose_b(centre).translation.vector;
        assert!((e.goal().position_b - home).norm() < 1e-9);
    }
}

#[test]
fn the_evaluation_counts_action_values_past_the_clip() {
    use kumi_train::evaluate::evaluate;
    // One episode (three goals); a relay of +-2 lies past the clip in every value, a policy
    // of +-0.5 in none, and one of (2, 0.5, 0.5, ...) in one value of seven.
    let share = |action: [f32; 7]| {
        evaluate(model("arm"), ArmReachConfig::default(), 3, 1, || {
            Ok(move |_: &_| Ok::<_, String>(action))
        })
        .unwrap()
        .action_values_past_limit
    };
    assert_eq!(share([2.0, -2.0, 2.0, -2.0, 2.0, -2.0, 2.0]), 1.0);
    assert_eq!(share([0.5, -0.5, 0.5, -0.5, 0.5, -0.5, 0.5]), 0.0);
    assert!((share([2.0, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5]) - 1.0 / 7.0).abs() < 1e-12);
}

#[test]
fn the_evaluation_measures_how_calmly_a_policy_holds() {
    use kumi_train::evaluate::evaluate;
    // A relay (the largest increment, one way then the other) reverses every joint at every
    // step of the hold window at full increment; a policy that commands nothing holds still,
    // its tool settled within a second of each goal's start (it only sags at the start).
    let relay = evaluate(model("arm"), ArmReachConfig::default(), 3, 1, || {
        let mut k = 0_usize;
        Ok(move |_: &_| {
            k += 1;
            Ok::<_, String>([if k.is_multiple_of(2) { 1.5 } else { -1.5 }; 7])
        })
    })
    .unwrap();
    assert_eq!(relay.hold_increment_share, 1.0);
    assert_eq!(relay.hold_reversal_share, 1.0);
    let still = evaluate(model("arm"), ArmReachConfig::default(), 3, 1, || {
        Ok(move |_: &_| Ok::<_, String>([0.0; 7]))
    })
    .unwrap();
    assert_eq!(
        (still.hold_increment_share, still.hold_reversal_share),
        (0.0, 0.0)
    );
    let settle = still.settle_time_s;
    assert!(settle.p90 <= 1.0 && settle.mean >= 0.0, "{settle:?}");
}

/// Places the arm's joints a thousand turns past their limits: the limits fling them back, and
/// the next step blows the physics up.
fn set_up_a_blow_up(e: &mut ArmReach) {
    e.world_mut().reset(&kumi_worlds::RobotState {
        base_pose_w: nalgebra::Isometry3::identity(),
        joint_positions: vec![6.0e3; 7],
    });
}

#[test]
fn a_step_whose_physics_blew_up_ends_the_episode_scoring_nothing() {
    // As in the whole-body environment: a world that blew up ends the episode (training resets
    // it, evaluation stops it) instead of feeding NaN to the skill and the reward.
    for engine in kumi_worlds::available_engines() {
        let config = ArmReachConfig {
            engine,
            ..ArmReachConfig::default()
        };
        let mut e = ArmReach::new(model("arm"), config, 3).unwrap();
        e.reset();
        let sound = e.step(&[0.0; 7]);
        assert!(!sound.terminated && sound.reward > 0.0, "{engine}");
        set_up_a_blow_up(&mut e);
        let lost = e.step(&[0.0; 7]);
        assert!(e.world().diverged(), "{engine}: the world did not blow up");
        assert!(lost.terminated && !lost.goal_ended, "{engine}");
        assert_eq!(
            (lost.reward, lost.observation),
            (0.0, [0.0; kumi_policies::observation::OBSERVATION_DIM]),
            "{engine}"
        );
        assert!(
            lost.position_error.is_nan() && lost.orientation_error.is_nan(),
            "{engine}"
        );
        // Stepping on regardless scores nothing more and steps nothing.
        let t_s = e.world().time();
        assert!(e.step(&[1.0; 7]).terminated, "{engine}");
        assert_eq!(e.world().time(), t_s, "{engine}: a lost world was stepped");
        e.reset();
        assert!(
            !e.world().diverged() && !e.step(&[0.0; 7]).terminated,
            "{engine}"
        );
    }
}

#[test]
fn an_evaluation_episode_stops_where_its_physics_blew_up() {
    use kumi_train::evaluate::run_episode;
    let mut policy = |_: &[f32; kumi_policies::observation::OBSERVATION_DIM]| {
        Ok::<_, String>([2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    };
    let mut e = env(5);
    let obs = e.reset();
    let whole = run_episode(&mut e, obs, 360, &mut policy).unwrap();
    assert_eq!((whole.goals.len(), whole.diverged), (3, false));
    assert_eq!(
        (whole.action_values, whole.action_values_past_limit),
        (360 * 7, 360)
    );
    let obs = e.reset();
    let goal = run_episode(&mut e, obs, 120, &mut policy).unwrap();
    assert_eq!(goal.goals.len(), 1);
    set_up_a_blow_up(&mut e);
    // The first step blows up: its action is counted, no goal ends, nothing NaN is kept.
    let cut = run_episode(&mut e, obs, 360, &mut policy).unwrap();
    assert!(cut.diverged);
    assert_eq!((cut.goals.len(), cut.action_values), (0, 7));
}

#[test]
fn tool_loads_are_drawn_as_configured() {
    use kumi_train::arm_reach::ToolLoad;
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    let tool_w = Vector3::new(0.1, -0.2, 1.3);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    // No load draws nothing: the random stream is the one without a [load] section.
    let none = ToolLoad::default();
    let mut twin = rng.clone();
    assert_eq!(none.draw(&mut rng, &tool_w), kumi_worlds::Load::NONE);
    assert_eq!(rng.random::<u64>(), twin.random::<u64>());
    // Every goal loaded: forces within the bound, in every direction.
    let forces = ToolLoad {
        share: 1.0,
        max_force_n: 50.0,
        ..ToolLoad::default()
    };
    let drawn: Vec<_> = (0..400).map(|_| forces.draw(&mut rng, &tool_w)).collect();
    assert!(drawn
        .iter()
        .all(|l| l.force_w.norm() <= 50.0 && l.stiffness_n_m == 0.0));
    assert!(drawn.iter().filter(|l| l.force_w.norm() > 25.0).count() > 150);
    let mean: Vector3<f64> = drawn.iter().map(|l| l.force_w).sum::<Vector3<f64>>() / 400.0;
    assert!(mean.norm() < 5.0, "forces lean {mean:?} N on average");
    // Every goal held where the tool stands.
    let held = ToolLoad {
        anchored_share: 1.0,
        stiffness_n_m: [1000.0, 3000.0],
        ..ToolLoad::default()
    };
    let l = held.draw(&mut rng, &tool_w);
    assert_eq!(l.anchor_w, tool_w);
    assert!((1000.0..=3000.0).contains(&l.stiffness_n_m));
    // Bad settings are refused by the environment, with the section named.
    for bad in [
        ToolLoad {
            share: 1.5,
            ..forces
        },
        ToolLoad {
            max_force_n: -1.0,
            ..forces
        },
        ToolLoad {
            stiffness_n_m: [3000.0, 1000.0],
            ..held
        },
    ] {
        let config = ArmReachConfig {
            load: bad,
            ..ArmReachConfig::default()
        };
        let err = ArmReach::new(model("arm"), config, 0).err().unwrap();
        assert!(err.to_string().starts_with("[load]:"), "{err}");
    }
}

#[test]
fn a_held_tool_does_not_follow_its_targets() {
    use kumi_train::arm_reach::ToolLoad;
    // A third of the largest increments on every joint for 1 s: free, the tool travels; held
    // by a stiff spring where it stood, it moves a fifth as far or less (the straight arm
    // pushes hard along its length), and the targets run ahead of the joints.
    let travel = |load: ToolLoad| {
        let config = ArmReachConfig {
            load,
            ..ArmReachConfig::default()
        };
        let mut e = ArmReach::new(model("arm"), config, 2).unwrap();
        e.reset();
        let start = e.tool_pose_b().translation.vector;
        for _ in 0..30 {
            e.step(&[0.3; 7]);
        }
        let q = e.world().joint_positions();
        let lead = e
            .targets()
            .iter()
            .zip(&q)
            .map(|(t, q)| (t - q).abs())
            .fold(0.0, f64::max);
        ((e.tool_pose_b().translation.vector - start).norm(), lead)
    };
    let (free, free_lead) = travel(ToolLoad::default());
    let (held, held_lead) = travel(ToolLoad {
        anchored_share: 1.0,
        stiffness_n_m: [20_000.0, 20_000.0],
        ..ToolLoad::default()
    });
    assert!(
        free > 0.2 && held < 0.2 * free,
        "free {free} m, held {held} m"
    );
    assert!(
        held_lead > 5.0 * free_lead,
        "lead free {free_lead}, held {held_lead} rad"
    );
}

#[test]
fn a_step_prior_adds_the_step_follower_to_the_networks_action() {
    use kumi_policies::skill::ArmSkill;
    use kumi_train::arm_reach::{step_prior, with_prior, SkillAction, SkillObservation};
    let arm = model("arm");
    let plain_config = ArmReachConfig {
        observation: SkillObservation {
            targets_lead: true,
            tool_error: true,
            joint_step: true,
        },
        ..ArmReachConfig::default()
    };
    let residual_config = ArmReachConfig {
        action: SkillAction {
            step_prior_gain: 0.3,
        },
        ..plain_config.clone()
    };
    let mut plain = ArmReach::new(arm.clone(), plain_config.clone(), 4).unwrap();
    let mut residual = ArmReach::new(arm.clone(), residual_config, 4).unwrap();
    let prior = step_prior(0.3, &ArmSkill::new(&arm.modules[0], 30.0).unwrap());
    let mut obs = plain.reset();
    assert_eq!(residual.reset(), obs);
    // The network's output plus the follower's part: the same arm, bit for bit.
    for k in 0..60 {
        let network = [
            0.1 * (k as f32 * 0.3).sin(),
            -0.05,
            0.0,
            0.02,
            0.0,
            -0.1,
            0.05,
        ];
        let p = plain.step(&with_prior(&network, &obs, &prior));
        let r = residual.step(&network);
        assert_eq!(p.observation, r.observation, "step {k}");
        obs = p.observation;
    }
    // With a silent network the follower alone closes on the goal.
    let mut follower = ArmReach::new(
        arm.clone(),
        ArmReachConfig {
            action: SkillAction {
                step_prior_gain: 0.3,
            },
            ..plain_config.clone()
        },
        9,
    )
    .unwrap();
    follower.reset();
    let before = follower.step(&[0.0; 7]).position_error;
    let mut after = before;
    for _ in 0..100 {
        after = follower.step(&[0.0; 7]).position_error;
    }
    assert!(
        after < 0.3 * before && after < 0.05,
        "{before} m -> {after} m"
    );
    // A prior needs the step in the observation, and a finite, non-negative gain.
    for (joint_step, gain) in [(false, 0.3), (true, -0.1), (true, f64::NAN)] {
        let config = ArmReachConfig {
            observation: SkillObservation {
                joint_step,
                ..plain_config.observation
            },
            action: SkillAction {
                step_prior_gain: gain,
            },
            ..plain_config.clone()
        };
        let err = ArmReach::new(arm.clone(), config, 1)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("step_prior_gain"), "{err}");
    }
}
