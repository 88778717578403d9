//! The whole-body environment: built from any morphology, its frozen-skill term feeds each arm
//! module exactly what the skill was trained on, episodes end as the paper's section IV-B says.

use std::sync::Arc;

use kumi_model::{assemble, load_morphology, ModuleLibrary, RobotModel};
use kumi_policies::kinematics::ToolKinematics;
use kumi_policies::observation::{self, Goal, LEAD_DIM};
use kumi_terms::action::{GoalBounds, JointBounds};
use kumi_train::arm_reach::{ArmReach, ArmReachConfig};
use kumi_train::body_reward::{rock_penalty, turn_penalty, BodyWeights, PenaltyWeights};
use kumi_train::replay::ReplayConfig;
use kumi_train::whole_body::{ArmControl, TaskConfig, WholeBody, WholeBodyConfig};
use kumi_worlds::{default_training_engine, home_joint_positions, RobotState};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

fn model(name: &str) -> Arc<RobotModel> {
    let library = ModuleLibrary::shipped();
    Arc::new(assemble(
        &load_morphology(name, &library).unwrap(),
        &library,
    ))
}

fn skill() -> Vec<u8> {
    std::fs::read(kumi_runtime::shipped_arm_policy()).unwrap()
}

fn config(tilt_limit_rad: f64) -> WholeBodyConfig {
    WholeBodyConfig {
        engine: default_training_engine(),
        task: TaskConfig {
            episode_s: 1.0,
            tilt_limit_rad,
            target_xy_m: 3.0,
            target_z_m: [0.9, 1.5],
            initial_xy_m: 0.5,
        },
        weights: BodyWeights {
            w_p1: 1.0,
            w_p2: 1.0,
            w_o: 0.2,
            w_v: 1e-4,
            w_a: 0.005,
            alive: 0.0,
            fall: 0.0,
            tilt: 0.0,
            turn: 0.0,
            rock: 0.0,
            airborne: 0.0,
        },
        penalty: PenaltyWeights::default(),
        observation: Default::default(),
        push: None,
        replay: None,
        randomize: None,
        critic: Default::default(),
        observation_noise: Default::default(),
        arms: ArmControl::Skill(GoalBounds {
            manipulator_position_m: 0.25,
            manipulator_rotation_rad: 0.5,
            leg_position_m: 0.1,
            leg_roll_rad: 0.5,
            wheel_velocity_rad_s: None,
            wheel_acceleration_rad_s2: None,
            lateral_acceleration_m_s2: None,
        }),
    }
}

#[test]
fn each_module_sees_what_the_arm_reach_environment_builds_bit_for_bit() {
    // The arm-reach environment draws a joint state; the same angles are put on each arm
    // module of Tricycle in turn. The skill observation the whole-body term builds for that
    // module, for a goal in its base frame, must equal the arm-reach observation's bits, and
    // the tool pose in the module's base frame must agree (the goal frame is the same frame).
    let reach_model = model("arm");
    let mut reach = ArmReach::new(reach_model.clone(), ArmReachConfig::default(), 5).unwrap();
    reach.reset();
    let q_reach = reach.world().joint_positions();
    let qd_reach = reach.world().joint_velocities();
    let tool_reach = reach.tool_pose_b();
    let goal = Goal {
        position_b: Vector3::new(0.5, -0.1, 0.9),
        orientation_b: UnitQuaternion::from_euler_angles(0.3, -0.2, 0.1),
    };
    let q_arm: [f64; 7] = std::array::from_fn(|j| q_reach[j]);
    let fk = ToolKinematics::new(&reach_model, &reach_model.modules[0]).unwrap();
    let expected = observation::build(
        &q_arm,
        &std::array::from_fn(|j| qd_reach[j]),
        &reach.targets(),
        &goal,
        &|q| fk.tool_pose_b(q),
        fk.limits_rad(),
    );
    // The arm-reach environment's own observation is the same function's, for its own goal.
    assert_eq!(
        reach.observation(),
        observation::build(
            &q_arm,
            &std::array::from_fn(|j| qd_reach[j]),
            &reach.targets(),
            &reach.observed_goal(),
            &|q| fk.tool_pose_b(q),
            fk.limits_rad(),
        )
    );

    let tricycle = model("tricycle");
    let mut env = WholeBody::new(tricycle.clone(), config(0.785), &skill(), 1).unwrap();
    let arms: Vec<String> = env.terms().arms().map(|a| a.module.clone()).collect();
    assert_eq!(arms, ["arm0", "leg0", "leg1", "leg2"]);
    for (k, module) in arms.iter().enumerate() {
        let range = env.world().module_range(module).unwrap();
        let mut q = home_joint_positions(&tricycle);
        q[range].copy_from_slice(&q_reach);
        env.world_mut().reset(&RobotState {
            base_pose_w: Isometry3::from_parts(
                Translation3::new(0.3, -0.2, 1.0),
                UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3),
            ),
            joint_positions: q,
        });
        let goals = vec![goal; arms.len()];
        let built = env.skill_observations(&goals)[k];
        // Table I's values and the lead, bit for bit; the tool's error is forward kinematics
        // through the module's mount on Tricycle, which may round its last bits otherwise.
        assert_eq!(
            built[..LEAD_DIM]
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>(),
            expected[..LEAD_DIM]
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>(),
            "module {module}"
        );
        for (b, e) in built[LEAD_DIM..].iter().zip(&expected[LEAD_DIM..]) {
            assert!(
                (b - e).abs() < 1e-6,
                "module {module}: {built:?} against {expected:?}"
            );
        }
        let m = tricycle.module(module).unwrap();
        let world = env.world();
        let tool_b = world.link_pose(&m.root_link).unwrap().inverse()
            * world.link_pose(m.ee_link.as_ref().unwrap()).unwrap();
        let d = (tool_b.translation.vector - tool_reach.translation.vector).norm();
        let r = tool_b.rotation.angle_to(&tool_reach.rotation);
        assert!(
            d < 1e-6 && r < 1e-6,
            "{module}: tool pose differs by {d} m, {r} rad"
        );
    }
}

#[test]
fn each_environment_draws_its_own_physics_and_bad_ranges_are_refused() {
    use kumi_train::randomize::RandomizeConfig;
    let randomized = |ground_friction: [f64; 2]| WholeBodyConfig {
        randomize: Some(RandomizeConfig {
            ground_friction: Some(ground_friction),
            mujoco_contact_time_s: Some([0.02, 0.04]),
        }),
        ..config(1.5)
    };
    let plain = WholeBody::new(model("tricycle"), config(1.5), &skill(), 5).unwrap();
    assert_eq!(plain.world().config().ground_friction, 1.0);
    assert_eq!(plain.world().config().mujoco_contact_time_s, None);
    let frictions: Vec<f64> = [5, 6]
        .into_iter()
        .map(|seed| {
            let env = WholeBody::new(model("tricycle"), randomized([0.5, 1.5]), &skill(), seed);
            let sim = *env.unwrap().world().config();
            assert!((0.02..=0.04).contains(&sim.mujoco_contact_time_s.unwrap()));
            sim.ground_friction
        })
        .collect();
    assert!(
        frictions.iter().all(|f| (0.5..=1.5).contains(f)),
        "{frictions:?}"
    );
    assert_ne!(frictions[0], frictions[1], "two seeds, two worlds");
    let refused = WholeBody::new(model("tricycle"), randomized([1.5, 0.5]), &skill(), 5);
    let message = refused
        .err()
        .expect("an empty range is refused")
        .to_string();
    assert!(
        message.starts_with("invalid [randomize] ground_friction: "),
        "the message names the section and the range, nothing else: {message}"
    );
}

#[test]
fn pushes_shove_the_robot_on_their_schedule_and_leave_the_task_alone() {
    // Every 0.1 s (3 control steps at 30 Hz), the velocity jumping by up to 0.5 m/s.
    let pushed = WholeBodyConfig {
        push: Some(kumi_train::whole_body::PushConfig {
            interval_s: [0.1, 0.1],
            velocity_m_s: 0.5,
            tip_rad_s: 0.0,
        }),
        ..config(1.5)
    };
    let mut plain = WholeBody::new(model("tricycle"), config(1.5), &skill(), 5).unwrap();
    let mut shoved = WholeBody::new(model("tricycle"), pushed, &skill(), 5).unwrap();
    let (a, b) = (plain.reset(), shoved.reset());
    assert_eq!(a, b, "the same seed: the same start and target");
    assert_eq!(plain.target(), shoved.target());
    let hold = vec![0.0; plain.terms().size()];
    for step in 1..=3 {
        let (a, b) = (plain.step(&hold), shoved.step(&hold));
        assert_eq!(
            a.observation, b.observation,
            "no push before step 4 ({step})"
        );
    }
    let (v_plain, _) = plain.world().base_twist_w();
    let (a, b) = (plain.step(&hold), shoved.step(&hold));
    assert_ne!(
        a.observation, b.observation,
        "the first push comes on step 4"
    );
    let (v_shoved, _) = shoved.world().base_twist_w();
    let (v_after, _) = plain.world().base_twist_w();
    let jump = (v_shoved - v_after).xy().norm();
    assert!(
        jump > 0.01 && jump < 0.5 * 2f64.sqrt(),
        "the pushed base's horizontal velocity differs by {jump} m/s (before: {v_plain:?})"
    );
}

#[test]
fn a_replayed_episode_goes_on_from_its_moment_bit_for_bit() {
    // Every step tilts past 1e-9 rad, and with before_s 0 the moment kept is the step's own:
    // an episode keeps its first step, and a reset replays a kept moment once there is one
    // (all but one in a million: the probability must stay below 1; this seed replays).
    let replaying = WholeBodyConfig {
        replay: Some(ReplayConfig {
            tilt_rad: 1e-9,
            before_s: 0.0,
            probability: 0.999_999,
            capacity: 4,
        }),
        ..config(1.5)
    };
    let mut env = WholeBody::new(model("tricycle"), replaying, &skill(), 9).unwrap();
    assert!(env.replays());
    let first = env.reset(); // nothing kept yet: a fresh start
    let drive: Vec<f32> = (0..env.terms().size())
        .map(|i| 0.3 * ((i % 3) as f32 - 1.0))
        .collect();
    let original: Vec<_> = (0..6).map(|_| env.step(&drive)).collect();
    assert!(original.iter().all(|s| !s.replayed && !s.terminated));
    let target = env.target();

    let resumed = env.reset();
    assert_eq!(
        resumed, original[0].observation,
        "it starts where step 1 ended"
    );
    assert_ne!(resumed, first);
    assert_eq!(env.target(), target, "with the same target");
    for expected in &original[1..] {
        let s = env.step(&drive);
        assert!(s.replayed);
        assert_eq!(s.observation, expected.observation);
        assert_eq!(s.reward.to_bits(), expected.reward.to_bits());
    }
}

#[test]
fn the_base_angular_velocity_slot_follows_table_iii_in_the_base_frame() {
    let spinning = WholeBodyConfig {
        observation: kumi_terms::ObservationOptions {
            base_angular_velocity: true,
            ..Default::default()
        },
        ..config(1.5)
    };
    let mut plain = WholeBody::new(model("tricycle"), config(1.5), &skill(), 3).unwrap();
    let mut with = WholeBody::new(model("tricycle"), spinning, &skill(), 3).unwrap();
    assert_eq!(with.observation_dim(), plain.observation_dim() + 3);
    let (a, b) = (plain.reset(), with.reset());
    assert_eq!(
        b[..a.len()],
        a[..],
        "the same seed: Table III's slots are the same"
    );
    let turn = vec![0.7; with.terms().size()];
    for _ in 0..10 {
        let (a, b) = (plain.step(&turn).observation, with.step(&turn).observation);
        assert_eq!(b[..a.len()], a[..]);
        let (_, w_w) = with.world().base_twist_w();
        let w_b = with.world().base_pose().rotation.inverse() * w_w;
        let expected: Vec<f32> = w_b.iter().map(|v| *v as f32).collect();
        assert_eq!(b[a.len()..], expected[..]);
    }
    assert!(
        with.observation()[plain.observation_dim()..]
            .iter()
            .any(|w| w.abs() > 1e-3),
        "a robot driven for 10 steps turns or rocks"
    );
}

#[test]
fn the_arm_joint_angle_slot_holds_each_arm_modules_angles_in_the_terms_order() {
    let angles = WholeBodyConfig {
        observation: kumi_terms::ObservationOptions {
            arm_joint_angles: true,
            ..Default::default()
        },
        ..config(1.5)
    };
    let mut plain = WholeBody::new(model("tricycle"), config(1.5), &skill(), 3).unwrap();
    let mut with = WholeBody::new(model("tricycle"), angles, &skill(), 3).unwrap();
    assert_eq!(with.observation_dim(), plain.observation_dim() + 4 * 7);
    let (a, b) = (plain.reset(), with.reset());
    assert_eq!(b[..a.len()], a[..]);
    let arms: Vec<String> = with.terms().arms().map(|a| a.module.clone()).collect();
    let reach = vec![0.5; with.terms().size()];
    for _ in 0..5 {
        let (a, b) = (
            plain.step(&reach).observation,
            with.step(&reach).observation,
        );
        assert_eq!(b[..a.len()], a[..]);
        let q = with.world().joint_positions();
        let expected: Vec<f32> = arms
            .iter()
            .flat_map(|m| q[with.world().module_range(m).unwrap()].to_vec())
            .map(|v| v as f32)
            .collect();
        assert_eq!(b[a.len()..], expected[..]);
    }
}

#[test]
fn what_only_the_critic_sees_follows_the_policys_observation_and_the_world() {
    use kumi_train::env::Environment;
    use kumi_train::whole_body::CriticObservation;
    let privileged = WholeBodyConfig {
        critic: CriticObservation {
            base_angular_velocity: true,
            base_height: true,
            arm_joint_state: true,
            wheel_modules_off_ground: true,
        },
        ..config(1.5)
    };
    let mut plain = WholeBody::new(model("tricycle"), config(1.5), &skill(), 3).unwrap();
    let mut with = WholeBody::new(model("tricycle"), privileged, &skill(), 3).unwrap();
    // The policy's observation is unchanged: the contract, evaluation and the node never see
    // the extras. Training's view appends them: 3 + 1 + 2 x 28 + 1.
    let policy_dim = plain.observation_dim();
    assert_eq!(with.observation_dim(), policy_dim);
    assert_eq!(Environment::actor_observation_dim(&with), policy_dim);
    assert_eq!(Environment::observation_dim(&with), policy_dim + 61);
    assert_eq!(Environment::observation_dim(&plain), policy_dim);
    let (a, b) = (
        Environment::reset(&mut plain),
        Environment::reset(&mut with),
    );
    assert_eq!(b.len(), policy_dim + 61);
    assert_eq!(b[..policy_dim], a[..], "the same seed: the same episode");
    let arms: Vec<String> = with.terms().arms().map(|a| a.module.clone()).collect();
    let turn = vec![0.7; with.terms().size()];
    let mut heights = Vec::new();
    for _ in 0..10 {
        let a = Environment::step(&mut plain, &turn).observation;
        let b = Environment::step(&mut with, &turn).observation;
        assert_eq!(b[..policy_dim], a[..]);
        assert_eq!(b[..policy_dim], with.observation()[..]);
        // An independent reading of the world, in CriticObservation's order.
        let world = with.world();
        let pose = world.base_pose();
        let w_b = pose.rotation.inverse() * world.base_twist_w().1;
        let mut expected: Vec<f32> = w_b.iter().map(|v| *v as f32).collect();
        expected.push(pose.translation.z as f32);
        for values in [world.joint_positions(), world.joint_velocities()] {
            for m in &arms {
                expected.extend(
                    values[world.module_range(m).unwrap()]
                        .iter()
                        .map(|v| *v as f32),
                );
            }
        }
        expected.push(world.wheel_modules_off_ground() as f32);
        assert_eq!(b[policy_dim..], expected[..]);
        heights.push(pose.translation.z);
    }
    assert!(
        heights.iter().all(|z| (0.5..2.0).contains(z)),
        "{heights:?}"
    );
}

#[test]
fn sizes_follow_the_morphology_and_episodes_time_out() {
    for (name, obs, act) in [("minimal", 19, 7), ("dragon", 26, 12), ("tricycle", 37, 21)] {
        let mut env = WholeBody::new(model(name), config(1.5), &skill(), 2).unwrap();
        assert_eq!(env.observation_dim(), obs, "{name}");
        assert_eq!(env.terms().size(), act, "{name}");
        let first = env.reset();
        assert_eq!(first.len(), obs);
        // Gravity in the base frame of a robot standing level, and no previous action.
        assert!((first[5] + 1.0).abs() < 0.05, "{name}: {first:?}");
        assert!(first[obs - act..].iter().all(|a| *a == 0.0));
        // Targets within the task's ranges.
        let t = env.target();
        assert!(t.position_w.x.abs() <= 3.0 && (0.9..=1.5).contains(&t.position_w.z));
        let zero = vec![0.0; act];
        let mut last = None;
        for _ in 0..30 {
            last = Some(env.step(&zero));
        }
        let last = last.unwrap();
        assert!(
            last.truncated && !last.terminated,
            "{name}: 1 s at 30 Hz is 30 steps"
        );
        assert_eq!(last.observation.len(), obs);
        assert!(last.reward.is_finite());
    }
}

#[test]
fn the_flat_baseline_is_the_same_environment_with_joint_targets_and_the_arms_state() {
    // the paper's section V-C: every arm joint's target (7 per arm module) and a velocity per wheel
    // module; the observation is the upper level's plus every arm joint's angle and velocity.
    let flat = |engine_config: WholeBodyConfig| WholeBodyConfig {
        arms: ArmControl::Joints(JointBounds {
            joint_scale_rad: 0.5,
            wheel_velocity_rad_s: None,
            wheel_acceleration_rad_s2: None,
            lateral_acceleration_m_s2: None,
        }),
        ..engine_config
    };
    for (name, obs, act, arm_joints) in [
        ("minimal", 34, 8, 7),
        ("dragon", 58, 16, 14),
        ("tricycle", 103, 31, 28),
    ] {
        // The flat baseline needs no skill: junk bytes are never read.
        let mut env = WholeBody::new(model(name), flat(config(1.5)), b"no skill", 2).unwrap();
        assert_eq!(env.observation_dim(), obs, "{name}");
        assert_eq!(env.terms().size(), act, "{name}");
        assert_eq!(env.reset().len(), obs);
        let step = env.step(&vec![0.0; act]);
        let (q, qd) = (
            env.world().joint_positions(),
            env.world().joint_velocities(),
        );
        let arm: Vec<usize> = env
            .world()
            .servos()
            .actuators()
            .iter()
            .enumerate()
            .filter(|(_, a)| a.mode == kumi_model::ActuatorMode::Position)
            .map(|(i, _)| i)
            .collect();
        assert_eq!(arm.len(), arm_joints);
        let tail = &step.observation[obs - 2 * arm_joints..];
        let expected: Vec<f32> = arm
            .iter()
            .map(|&i| q[i] as f32)
            .chain(arm.iter().map(|&i| qd[i] as f32))
            .collect();
        assert_eq!(tail, &expected[..], "{name}");
        // A zero action holds every arm joint's target at home.
        let home = home_joint_positions(env.world().model());
        for &i in &arm {
            assert_eq!(env.world().commands()[i], home[i], "{name}: joint {i}");
        }
    }
}

#[test]
fn the_penalty_terms_see_the_legs_and_contacts_of_the_world() {
    // Eq. 5 from the world's leg tool poses; Eq. 6 off for a robot standing on its wheels.
    let mut c = config(1.5);
    c.penalty = PenaltyWeights {
        w_ori: 2.0,
        w_c: 0.5,
    };
    let tricycle = model("tricycle");
    let mut env = WholeBody::new(tricycle.clone(), c, &skill(), 4).unwrap();
    env.reset();
    let step = env.step(&[0.0; 21]);
    let angles = kumi_train::evaluate_body::leg_angles(&tricycle, env.world());
    assert_eq!(angles.len(), 3);
    let expected = 2.0 * (-angles.iter().sum::<f64>()).exp();
    assert!(
        (step.terms.leg_orientation - expected).abs() < 1e-12,
        "{step:?}"
    );
    assert!(step.terms.leg_orientation > 0.0);
    let contact = kumi_train::evaluate_body::ContactRule::new(&tricycle).any(env.world());
    assert_eq!(step.terms.contact, if contact { -0.5 } else { 0.0 });
    // Without weights, neither term is computed.
    let mut plain = WholeBody::new(tricycle, config(1.5), &skill(), 4).unwrap();
    plain.reset();
    let step = plain.step(&[0.0; 21]);
    assert_eq!((step.terms.leg_orientation, step.terms.contact), (0.0, 0.0));
}

#[test]
fn a_tilt_past_the_limit_terminates() {
    // A limit the standing robot already exceeds after settling cannot be met: with a limit of
    // zero every step is a fall.
    let mut env = WholeBody::new(model("tricycle"), config(1e-9), &skill(), 3).unwrap();
    env.reset();
    let step = env.step(&[0.0; 21]);
    assert!(step.terminated);
    assert_eq!(step.terms.fall, 0.0, "no fall weight, no fall penalty");

    // With a fall weight, the falling step carries it, and a standing step does not.
    let mut weighted = config(1e-9);
    weighted.weights.fall = 20.0;
    let mut env = WholeBody::new(model("tricycle"), weighted.clone(), &skill(), 3).unwrap();
    env.reset();
    let step = env.step(&[0.0; 21]);
    assert!(step.terminated);
    assert_eq!(step.terms.fall, -20.0);
    weighted.task.tilt_limit_rad = 1.0;
    let mut env = WholeBody::new(model("tricycle"), weighted, &skill(), 3).unwrap();
    env.reset();
    let step = env.step(&[0.0; 21]);
    assert!(!step.terminated);
    assert_eq!(step.terms.fall, 0.0);
}

/// Runs Tricycle twice from the same seed with the same actions, once with `weigh` applied to
/// the reward weights: unweighted no step carries the term (`term` of the step's terms);
/// weighted each step carries `expected` of the world after that step, the rewards differ by
/// the term alone (the same physics), and the robot pays something over 30 steps.
fn assert_a_term_follows_the_world(
    weigh: impl Fn(&mut BodyWeights),
    term: impl Fn(&kumi_train::body_reward::BodyTerms) -> f64,
    expected: impl Fn(&WholeBody) -> f64,
) {
    assert_a_term_follows_the_world_after(|_| {}, weigh, term, expected);
}

/// As [`assert_a_term_follows_the_world`], with `prepare` applied to both robots after their
/// reset.
fn assert_a_term_follows_the_world_after(
    prepare: impl Fn(&mut WholeBody),
    weigh: impl Fn(&mut BodyWeights),
    term: impl Fn(&kumi_train::body_reward::BodyTerms) -> f64,
    expected: impl Fn(&WholeBody) -> f64,
) {
    let mut weighted = config(1.5);
    weigh(&mut weighted.weights);
    let action = [0.6_f32; 21];
    let mut plain = WholeBody::new(model("tricycle"), config(1.5), &skill(), 5).unwrap();
    let mut env = WholeBody::new(model("tricycle"), weighted, &skill(), 5).unwrap();
    plain.reset();
    env.reset();
    prepare(&mut plain);
    prepare(&mut env);
    let mut paid = 0.0;
    for _ in 0..30 {
        let unweighted = plain.step(&action);
        assert_eq!(term(&unweighted.terms), 0.0);
        let step = env.step(&action);
        let value = term(&step.terms);
        assert_eq!(value, expected(&env));
        assert!(
            (step.reward - unweighted.reward - value).abs() < 1e-12,
            "{} - {} is not the term {value}",
            step.reward,
            unweighted.reward,
        );
        paid += value;
    }
    assert!(paid < -1e-4, "the term cost nothing over 30 steps: {paid}");
}

#[test]
fn the_turn_penalty_follows_the_bases_speed_and_yaw_rate() {
    // A robot that drives while its legs steer pays it.
    assert_a_term_follows_the_world(
        |w| w.turn = 2.0,
        |t| t.turn,
        |env| {
            let (v_w, w_w) = env.world().base_twist_w();
            turn_penalty(2.0, v_w.xy().norm(), w_w.z)
        },
    );
}

#[test]
fn the_rock_penalty_follows_the_bases_roll_and_pitch_rates() {
    // The base's angular velocity in its own frame; a robot that lurches off with its legs'
    // goals thrown pays it.
    assert_a_term_follows_the_world(
        |w| w.rock = 2.0,
        |t| t.rock,
        |env| {
            let (_, w_w) = env.world().base_twist_w();
            rock_penalty(2.0, &(env.world().base_pose().rotation.inverse() * w_w))
        },
    );
}

#[test]
fn the_airborne_penalty_counts_the_wheel_modules_off_the_ground() {
    // Tricycle's wheel modules are wheel0..wheel2; one is down when any of its links is. Tossed
    // up at 1.5 m/s, the robot leaves the ground for about 0.3 s and lands.
    assert_a_term_follows_the_world_after(
        |env| {
            let up = Vector3::new(0.0, 0.0, 1.5);
            env.world_mut().push(&up, &Vector3::zeros());
        },
        |w| w.airborne = 2.0,
        |t| t.airborne,
        |env| {
            let down = env.world().ground_contacts();
            let off = ["wheel0/", "wheel1/", "wheel2/"]
                .iter()
                .filter(|m| !down.iter().any(|l| l.starts_with(*m)))
                .count();
            -2.0 * off as f64
        },
    );
}

#[test]
fn a_bad_task_or_skill_is_refused_naming_what_is_wrong() {
    let err = WholeBody::new(model("arm"), config(1.0), &skill(), 0);
    assert!(
        err.is_ok(),
        "the single arm has one manipulator and no wheels"
    );
    let mut bad = config(1.0);
    bad.task.target_z_m = [1.5, 0.9];
    let err = WholeBody::new(model("tricycle"), bad, &skill(), 0)
        .err()
        .unwrap();
    let message = err.to_string();
    assert!(message.starts_with("invalid [task]: "), "{message}");
    assert!(message.contains("target_z_m"), "{message}");
    let err = WholeBody::new(model("tricycle"), config(1.0), b"not onnx", 0)
        .err()
        .unwrap();
    let message = err.to_string();
    assert!(message.starts_with("the skill: "), "{message}");
    assert!(message.contains("not an ONNX model"), "{message}");
    let mut replay = config(1.0);
    replay.replay = Some(kumi_train::replay::ReplayConfig {
        tilt_rad: 1.2,
        before_s: 1.0,
        probability: 0.5,
        capacity: 8,
    });
    let err = WholeBody::new(model("tricycle"), replay, &skill(), 0)
        .err()
        .expect("a replay tilt past the task's limit is refused");
    let message = err.to_string();
    assert!(message.starts_with("invalid [replay]: "), "{message}");
}

/// How far [m] the tool may stray from a goal the skill starts on (a fixed arm at `home` with
/// the goal its own home tool pose): in the first second and typically (the median) over 3 s;
/// and at most, over 3 s.
const EXCURSION_BOUND_M: f64 = 0.1;
const EXCURSION_MAX_M: f64 = 0.3;

/// The tool's distance [m] from the goal at each of 90 steps (3 s).
fn excursion_from_home(home: [f64; 7]) -> Vec<f64> {
    use kumi_policies::skill::ArmSkill;
    let arm = model("arm");
    let sim = kumi_worlds::SimConfig::for_model(&arm);
    let mut world = kumi_worlds::build(default_training_engine(), arm.clone(), sim).unwrap();
    let module = &arm.modules[0];
    let contract = ArmSkill::new(module, sim.control_hz).unwrap();
    let mut policy = kumi_runtime::SkillPolicy::from_bytes(
        skill(),
        "skill",
        &contract,
        kumi_runtime::BackendChoice::Tract,
    )
    .unwrap();
    let kinematics = ToolKinematics::new(&arm, module).unwrap();
    let pose = kinematics.tool_pose_b(&home);
    let goal = Goal {
        position_b: pose.translation.vector,
        orientation_b: pose.rotation,
    };
    world.reset(&RobotState {
        base_pose_w: Isometry3::identity(),
        joint_positions: home.to_vec(),
    });
    let mut excursions = Vec::new();
    for _ in 0..90 {
        let (q, qd, targets) = (
            world.joint_positions(),
            world.joint_velocities(),
            world.commands(),
        );
        let q: [f64; 7] = std::array::from_fn(|j| q[j]);
        let obs = observation::build(
            &q,
            &std::array::from_fn(|j| qd[j]),
            &std::array::from_fn(|j| targets[j]),
            &goal,
            &|q| kinematics.tool_pose_b(q),
            kinematics.limits_rad(),
        );
        let action = policy.act(&obs).unwrap();
        world
            .apply_increments(&module.name, &contract.increments(&action))
            .unwrap();
        world.step();
        let tool = world.link_pose(&module.root_link).unwrap().inverse()
            * world.link_pose(module.ee_link.as_ref().unwrap()).unwrap();
        excursions.push((tool.translation.vector - goal.position_b).norm());
    }
    excursions
}

#[test]
fn the_shipped_skill_holds_every_module_at_its_home() {
    // The upper level's zero action asks each module for its home tool pose, where it already
    // stands. A skill trained only from starts near zero swung a leg's elbow through 1.5 rad
    // first (excursions of 0.33-0.44 m) and Tricycle collapsed: the skill must hold instead.
    // It holds, but not still: on some machines (AMD EPYC with AVX-512; the skill's model card,
    // policies/arm_reach/README.md) Tricycle's leg2 dithers with a growing swing that reaches
    // 0.22 m near the end of the 3 s, where others stay within 0.1 m: the closed loop is
    // chaotic, and floating-point kernels that differ in their last bits send it elsewhere. The
    // bounds hold the start and the typical excursion to 0.1 m and the largest to 0.3 m, below
    // that skill's 0.33-0.44 m swing, on every machine.
    let library = ModuleLibrary::shipped();
    for robot in ["minimal", "dragon", "tricycle"] {
        let m = assemble(&load_morphology(robot, &library).unwrap(), &library);
        for module in m.modules.iter().filter(|m| m.home.len() == 7) {
            let home = std::array::from_fn(|j| module.home[j]);
            let mut excursions = excursion_from_home(home);
            let first_s = excursions[..30].iter().copied().fold(0.0, f64::max);
            excursions.sort_by(f64::total_cmp);
            let (median, worst) = (excursions[45], excursions[89]);
            assert!(
                first_s < EXCURSION_BOUND_M
                    && median < EXCURSION_BOUND_M
                    && worst < EXCURSION_MAX_M,
                "{robot}/{}: the tool strays from the home goal it started on by {first_s:.3} m \
                 in the first second, {median:.3} m at the median and {worst:.3} m at most",
                module.name
            );
        }
    }
}

#[test]
fn minimal_and_dragon_stand_for_a_whole_episode_on_the_zero_action() {
    // The zero action: every module asked for its home tool pose, wheels still. Over the
    // skill, the robot must stay up for the paper's 12 s episode. (Tricycle stands on three
    // legs that each wander a few centimetres around their goals under the skill: it rocks
    // and, left alone, tips past 0.5 rad after about 5 s; balancing it is the upper policy's
    // job.)
    for robot in ["minimal", "dragon"] {
        let mut c = config(0.5);
        c.task.episode_s = 12.0;
        let mut env = WholeBody::new(model(robot), c, &skill(), 4).unwrap();
        env.reset();
        let zero = vec![0.0; env.terms().size()];
        let mut steps = 0;
        loop {
            let out = env.step(&zero);
            steps += 1;

            assert!(
                !out.terminated,
                "{robot} tilted past 0.5 rad after {steps} steps on the zero action"
            );
            if out.truncated {
                break;
            }
        }
        assert_eq!(steps, 360);
    }
}

/// Mean final distance [m] of the tool to its target over `episodes` episodes of the
/// deterministic policy, on fresh environments (seeded apart from training's).
fn final_distance(
    trainer: &kumi_train::ppo::trainer::Trainer<WholeBody>,
    make: &dyn Fn(u64) -> WholeBody,
    episodes: u64,
) -> f64 {
    use kumi_train::env::Environment;
    let mut sum = 0.0;
    for k in 0..episodes {
        let mut env = make(1000 + k);
        let mut obs = Environment::reset(&mut env);
        loop {
            let tr = Environment::step(&mut env, &trainer.act(&obs));
            if tr.terminated || tr.truncated {
                let d = tr
                    .metrics
                    .iter()
                    .find(|(name, _)| *name == "final_position_error_m")
                    .map(|(_, v)| *v)
                    .expect("the last step reports the final error");
                sum += d;
                break;
            }
            obs = tr.observation;
        }
    }
    sum / episodes as f64
}

/// PPO iterations of the tiny task (480 steps each).
const ITERATIONS: usize = 80;

#[test]
fn a_tiny_whole_body_task_is_learnt() {
    // Minimal, 2 s episodes, the target within 0.8 m of a base that starts at the origin: the
    // untrained policy barely moves (measured: MuJoCo 1.24 m -> 0.57 m after 80 iterations,
    // rapier 1.23 m -> 0.75 m after 30); driving toward the target (forward or back, the one way a
    // lone wheel module goes) and reaching with the arm must bring the tool closer.
    let mut body = config(0.6);
    body.task = TaskConfig {
        episode_s: 2.0,
        tilt_limit_rad: 0.6,
        target_xy_m: 0.8,
        target_z_m: [0.9, 1.1],
        initial_xy_m: 0.0,
    };
    body.weights.w_o = 0.0;
    let skill = skill();
    let robot = model("minimal");
    let make = |seed: u64| WholeBody::new(robot.clone(), body.clone(), &skill, seed).unwrap();
    let config = kumi_train::ppo::trainer::PpoConfig {
        seed: 1,
        num_envs: 8,
        rollout_steps: 60,
        total_steps: 0,
        hidden: vec![32, 32],
        learning_rate: 3e-3,
        epochs: 4,
        minibatches: 4,
        entropy_coef: 0.0,
        ..Default::default()
    };
    let mut trainer =
        kumi_train::ppo::trainer::Trainer::new(config, (0..8).map(make).collect()).unwrap();
    let before = final_distance(&trainer, &make, 8);
    for _ in 0..ITERATIONS {
        trainer.iterate();
    }
    let after = final_distance(&trainer, &make, 8);
    eprintln!(
        "{}: final distance to the target {before:.3} m untrained, {after:.3} m after {} steps",
        body.engine,
        ITERATIONS * 480
    );
    assert!(
        after < before * 0.8,
        "not learnt: {before:.3} m -> {after:.3} m"
    );
}

#[test]
fn the_observed_tool_pose_is_the_worlds_while_the_robot_moves() {
    // The policy sees the tool through forward kinematics of the joint angles from the base
    // pose (as the whole-body node computes it); the reward measures the world's tool link.
    // They must agree for every robot, also while the robot drives and its arms move.
    for name in ["minimal", "dragon", "tricycle"] {
        let mut env = WholeBody::new(model(name), config(1.5), &skill(), 3).unwrap();
        let act = env.terms().size();
        let mut worst: f64 = 0.0;
        for step in 0..20 {
            let action: Vec<f32> = (0..act)
                .map(|i| ((i * 7 + step * 3) % 11) as f32 / 5.5 - 1.0)
                .collect();
            env.step(&action);
            let (seen, real) = (env.observed_tool_pose_w(), env.tool_pose_w());
            worst = worst.max((seen.translation.vector - real.translation.vector).norm());
        }
        println!("{name}: observed tool at most {worst:.2e} m from the world's");
        assert!(worst < 1e-3, "{name}: {worst} m");
    }
}

#[test]
fn a_wheel_acceleration_ramps_the_commanded_wheel_velocities_from_each_episodes_start() {
    // 3 rad/s^2 at 30 Hz: the wheels are commanded 0.1 rad/s more each control step toward
    // the policy's full speed, and a new episode starts them again from 0.
    let mut config = config(1.5);
    if let ArmControl::Skill(bounds) = &mut config.arms {
        bounds.wheel_acceleration_rad_s2 = Some(3.0);
    }
    let mut env = WholeBody::new(model("tricycle"), config, &skill(), 3).unwrap();
    let wheel_commands = |env: &WholeBody| -> Vec<f64> {
        let world = env.world();
        let modes = world.servos().actuators().iter().map(|a| a.mode);
        modes
            .zip(world.commands())
            .filter(|(mode, _)| *mode == kumi_model::ActuatorMode::Velocity)
            .map(|(_, c)| c.abs())
            .collect()
    };
    let full = vec![1.0_f32; env.terms().size()];
    for episode in 0..2 {
        env.reset();
        for step in 1..=3 {
            env.step(&full);
            let want = 0.1 * f64::from(step);
            let commands = wheel_commands(&env);
            assert_eq!(commands.len(), 6);
            assert!(
                commands.iter().all(|c| (c - want).abs() < 1e-9),
                "episode {episode}, step {step}: {commands:?}"
            );
        }
    }
}

#[test]
fn unset_wheel_bounds_leave_a_configs_serialisation_as_it_was() {
    // Exported policies record a fingerprint of their config's values: configs written before
    // the wheel bounds existed must serialise as they did.
    let ArmControl::Skill(bounds) = config(1.0).arms else {
        panic!("over the skill")
    };
    let text = serde_json::to_string(&bounds).unwrap();
    assert!(
        !text.contains("wheel_") && !text.contains("lateral"),
        "{text}"
    );
    let flat = JointBounds {
        joint_scale_rad: 0.5,
        wheel_velocity_rad_s: None,
        wheel_acceleration_rad_s2: None,
        lateral_acceleration_m_s2: None,
    };
    let text = serde_json::to_string(&flat).unwrap();
    assert!(
        !text.contains("wheel_") && !text.contains("lateral"),
        "{text}"
    );
    let ramped = GoalBounds {
        wheel_acceleration_rad_s2: Some(3.0),
        ..bounds
    };
    let text = serde_json::to_string(&ramped).unwrap();
    assert!(text.contains("\"wheel_acceleration_rad_s2\":3.0"), "{text}");
    let governed = GoalBounds {
        lateral_acceleration_m_s2: Some(0.1),
        ..bounds
    };
    let text = serde_json::to_string(&governed).unwrap();
    assert!(text.contains("\"lateral_acceleration_m_s2\":0.1"), "{text}");
}

#[test]
fn training_noise_moves_only_the_noised_slots_and_never_the_episode() {
    use kumi_train::env::Environment;
    use kumi_train::noise::ObservationNoise;
    use kumi_train::whole_body::CriticObservation;
    let noise = ObservationNoise::from_pairs;
    let critic = CriticObservation {
        base_height: true,
        ..Default::default()
    };
    let noised = WholeBodyConfig {
        observation_noise: noise(&[("tool_to_target", 0.05), ("wheel_velocities", 0.3)]),
        critic,
        ..config(1.5)
    };
    let mut plain = WholeBody::new(
        model("tricycle"),
        WholeBodyConfig {
            critic,
            ..config(1.5)
        },
        &skill(),
        4,
    )
    .unwrap();
    let mut with = WholeBody::new(model("tricycle"), noised, &skill(), 4).unwrap();
    // Which values are noised: tool_to_target's 3 and the 6 wheels' velocities, by the slots.
    let mut noised_values = vec![false; with.observation_dim()];
    let mut at = 0;
    for slot in with.slots() {
        if ["tool_to_target", "wheel_velocities"].contains(&slot.name) {
            noised_values[at..at + slot.size].fill(true);
        }
        at += slot.size;
    }
    assert_eq!(noised_values.iter().filter(|n| **n).count(), 9);
    let check = |seen: &[f32], env: &WholeBody| {
        let exact = env.observation();
        for (i, (s, e)) in seen.iter().zip(&exact).enumerate() {
            assert_eq!(s != e, noised_values[i], "value {i}: {s} against {e}");
            assert!((s - e).abs() < 0.3 * 6.0, "value {i}: {s} against {e}");
        }
        assert_eq!(
            seen[exact.len()..],
            env.critic_extras()[..],
            "the critic's extras are exact"
        );
    };
    let seen = Environment::reset(&mut with);
    check(&seen, &with);
    Environment::reset(&mut plain);
    let action = vec![0.5; with.terms().size()];
    for _ in 0..10 {
        let seen = Environment::step(&mut with, &action).observation;
        check(&seen, &with);
        Environment::step(&mut plain, &action);
        // The noise has its own stream: the same seed, the same episode, bit for bit.
        assert_eq!(with.observation(), plain.observation());
        assert_eq!(with.target(), plain.target());
    }
    // After 10 steps' draws of noise, the next episode is still the one without noise draws.
    Environment::reset(&mut with);
    Environment::reset(&mut plain);
    assert_eq!(with.target(), plain.target());
    assert_eq!(with.observation(), plain.observation());

    let typo = WholeBodyConfig {
        observation_noise: noise(&[("tool_to_targets", 0.05)]),
        ..config(1.5)
    };
    let Err(e) = WholeBody::new(model("tricycle"), typo, &skill(), 4) else {
        panic!("a misspelt slot was accepted");
    };
    assert!(e.to_string().contains("`tool_to_targets`"), "{e}");
}

#[test]
fn a_step_whose_physics_blew_up_ends_the_episode_with_the_fall_penalty_alone() {
    // A rapier world that blew up once gave a training batch rewards summing to -3.6e20 through
    // the joint-speed penalty (docs/notebook/tricycle_whole_body_runs.md). Either engine flags
    // the blow-up, and the environment scores nothing from the lost state.
    let mut c = config(1.5);
    c.weights.fall = 20.0;
    c.weights.alive = 0.5;
    for engine in kumi_worlds::available_engines() {
        c.engine = engine;
        let mut env = WholeBody::new(model("tricycle"), c.clone(), &skill(), 6).unwrap();
        let dim = env.observation_dim();
        env.reset();
        let zero = vec![0.0; env.terms().size()];
        let sound = env.step(&zero);
        assert!(!env.world().diverged() && !sound.terminated, "{engine}");
        let absurd = Vector3::new(1e15, -1e15, 1e15);
        env.world_mut().push(&absurd, &absurd);
        let lost = env.step(&zero);
        assert!(
            env.world().diverged(),
            "{engine}: an absurd shove did not blow up"
        );
        assert!(lost.terminated, "{engine}: the episode went on");
        assert_eq!(lost.reward, -20.0, "{engine}: {:?}", lost.terms);
        assert_eq!(lost.observation, vec![0.0; dim], "{engine}");
        assert!(
            lost.position_error.is_nan() && lost.yaw_error.is_nan(),
            "{engine}"
        );
        env.reset();
        assert!(
            !env.world().diverged(),
            "{engine}: a reset left it diverged"
        );
        assert!(!env.step(&zero).terminated, "{engine}");
    }
}
