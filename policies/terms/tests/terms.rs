//! The action terms on the shipped robots: Table V's sizes, scaling, clipping and the contract.

use kumi_model::{assemble, load_morphology, ModuleLibrary, RobotModel, Role};
use kumi_policies::rotation::orientation_error;
use kumi_terms::action::{turn_governor, ActionTerms, GoalBounds, JointBounds, Term, WheelRamp};
use kumi_terms::contract::{self, ContractMismatch};
use kumi_terms::ObservationOptions;
use nalgebra::Vector3;

fn robot(name: &str) -> RobotModel {
    let library = ModuleLibrary::shipped();
    assemble(&load_morphology(name, &library).unwrap(), &library)
}

/// Table III's slots, no optional one.
const NONE: ObservationOptions = ObservationOptions {
    base_angular_velocity: false,
    arm_joint_angles: false,
};

const BOUNDS: GoalBounds = GoalBounds {
    manipulator_position_m: 0.25,
    manipulator_rotation_rad: 0.5,
    leg_position_m: 0.1,
    leg_roll_rad: 0.4,
    wheel_velocity_rad_s: None,
    wheel_acceleration_rad_s2: None,
    lateral_acceleration_m_s2: None,
};

#[test]
fn goal_sizes_are_table_v() {
    // Table V: goal values per morphology (6, 10, 18), plus one velocity per wheel module.
    for (name, goals, wheels) in [("minimal", 6, 1), ("dragon", 10, 2), ("tricycle", 18, 3)] {
        let terms = ActionTerms::new(&robot(name), &BOUNDS).unwrap();
        let arm_values: usize = terms.arms().map(|a| a.width()).sum();
        assert_eq!(arm_values, goals, "{name}");
        assert_eq!(terms.wheels().count(), wheels, "{name}");
        assert_eq!(terms.size(), goals + wheels);
        assert_eq!(terms.names().len(), terms.size());
    }
}

#[test]
fn zero_action_is_the_home_tool_pose_and_bounds_scale_offsets() {
    let model = robot("tricycle");
    let terms = ActionTerms::new(&model, &BOUNDS).unwrap();
    let zero = terms.commands(&vec![0.0; terms.size()]).unwrap();
    for (goal, arm) in zero.goals.iter().zip(terms.arms()) {
        assert_eq!(goal.position_b, arm.home_tool_b.translation.vector);
        assert!(orientation_error(&goal.orientation_b, &arm.home_tool_b.rotation) < 1e-7);
    }
    // Tricycle's legs hold their tools at about (0.85, 0, 0.76) m in their base frames.
    let leg = terms.arms().find(|a| a.module == "leg0").unwrap();
    let home = leg.home_tool_b.translation.vector;
    assert!(
        (home.x - 0.847).abs() < 0.01 && (home.z - 0.758).abs() < 0.01,
        "{home}"
    );

    // Saturated, over-saturated and non-finite values: clipped to the bounds, NaN holds home.
    let mut action = vec![0.0_f32; terms.size()];
    action[0] = 1.0; // arm0 dx
    action[1] = 7.0; // arm0 dy, clipped to 1
    action[2] = f32::NAN; // arm0 dz: 0
    action[5] = -1.0; // arm0 rz: -0.5 rad about the base z axis
    action[9] = 0.5; // leg0 roll (arm0 takes 0..6, leg0 6..10): 0.2 rad
    let wheel_at = terms.size() - 3;
    action[wheel_at] = -2.0; // wheel0: the negative limit
    let c = terms.commands(&action).unwrap();
    let arm0 = terms.arms().next().unwrap();
    let d = c.goals[0].position_b - arm0.home_tool_b.translation.vector;
    assert!(
        (d - nalgebra::Vector3::new(0.25, 0.25, 0.0)).norm() < 1e-12,
        "{d}"
    );
    let turn = c.goals[0].orientation_b * arm0.home_tool_b.rotation.inverse();
    assert!((turn.scaled_axis() - nalgebra::Vector3::new(0.0, 0.0, -0.5)).norm() < 1e-12);
    let roll = leg.home_tool_b.rotation.inverse() * c.goals[1].orientation_b;
    assert!((roll.scaled_axis() - nalgebra::Vector3::new(0.2, 0.0, 0.0)).norm() < 1e-12);
    let wheel = terms.wheels().next().unwrap();
    assert!(wheel.scale_rad_s > 0.0 && wheel.scale_rad_s.is_finite());
    assert_eq!(c.wheel_velocities[0], -wheel.scale_rad_s);
    assert_eq!(c.wheel_velocities[1], 0.0);

    assert!(terms.commands(&[0.0; 3]).is_err());
}

#[test]
fn terms_follow_the_morphology_order_and_roles() {
    let terms = ActionTerms::new(&robot("dragon"), &BOUNDS).unwrap();
    let order: Vec<_> = terms.terms.iter().map(|t| t.module().to_string()).collect();
    assert_eq!(order, ["front_wheel", "arm0", "leg0", "rear_wheel"]);
    let roles: Vec<_> = terms.arms().map(|a| a.role).collect();
    assert_eq!(roles, [Role::Manipulator, Role::Leg]);
    assert!(matches!(terms.terms[0], Term::Wheel(_)));
    assert!(terms
        .describe()
        .starts_with("front_wheel:wheel:1:velocity_rad_s="));
    assert!(terms
        .describe()
        .contains("arm0:manipulator:6:position_m=0.25:rotation_rad=0.5;leg0:leg:4:position_m=0.1:roll_rad=0.4"));
    // A bound that cannot scale anything is refused by name.
    let bad = GoalBounds {
        leg_roll_rad: f64::NAN,
        ..BOUNDS
    };
    let err = ActionTerms::new(&robot("dragon"), &bad)
        .unwrap_err()
        .to_string();
    assert!(err.contains("leg_roll_rad"), "{err}");
}

#[test]
fn a_policy_for_another_robot_or_skill_is_refused_by_key() {
    let (tricycle, dragon) = (robot("tricycle"), robot("dragon"));
    let terms = ActionTerms::new(&tricycle, &BOUNDS).unwrap();
    let trained = contract::contract(&tricycle, &terms, NONE, b"skill-a", 30.0);
    assert_eq!(contract::check(&trained, &trained), Ok(()));
    assert_eq!(trained[kumi_policies::metadata::OBSERVATION_DIM_KEY], "37");

    let other_robot = contract::contract(
        &dragon,
        &ActionTerms::new(&dragon, &BOUNDS).unwrap(),
        NONE,
        b"skill-a",
        30.0,
    );
    match contract::check(&other_robot, &trained) {
        Err(ContractMismatch::Differs {
            key,
            found,
            expected,
        }) => {
            assert_eq!(key, contract::MORPHOLOGY);
            assert_eq!((found.as_str(), expected.as_str()), ("tricycle", "dragon"));
        }
        other => panic!("{other:?}"),
    }
    // Another robot or skill is no matter of the training config.
    assert!(!contract::check(&other_robot, &trained)
        .unwrap_err()
        .from_config());
    let other_skill = contract::contract(&tricycle, &terms, NONE, b"skill-b", 30.0);
    let mismatch = contract::check(&other_skill, &trained).unwrap_err();
    assert!(!mismatch.from_config());
    let err = mismatch.to_string();
    assert!(err.contains(contract::SKILL_FINGERPRINT), "{err}");
    // The same robot with other bounds: the action key differs.
    let wider = ActionTerms::new(
        &tricycle,
        &GoalBounds {
            leg_position_m: 0.2,
            ..BOUNDS
        },
    )
    .unwrap();
    let mismatch = contract::check(
        &contract::contract(&tricycle, &wider, NONE, b"skill-a", 30.0),
        &trained,
    )
    .unwrap_err();
    assert_eq!(
        (mismatch.key(), mismatch.from_config()),
        (contract::ACTION, true)
    );
    // The same robot and terms observing the base's angular velocity: the observation's size
    // differs first, and the description names the slot.
    let spinning = ObservationOptions {
        base_angular_velocity: true,
        arm_joint_angles: false,
    };
    let with = contract::contract(&tricycle, &terms, spinning, b"skill-a", 30.0);
    assert_eq!(with[kumi_policies::metadata::OBSERVATION_DIM_KEY], "40");
    let mismatch = contract::check(&with, &trained).unwrap_err();
    assert!(mismatch.from_config());
    let err = mismatch.to_string();
    assert!(
        err.contains(kumi_policies::metadata::OBSERVATION_DIM_KEY),
        "{err}"
    );
    let description = &with[kumi_policies::metadata::OBSERVATION];
    assert_eq!(ObservationOptions::from_description(description), spinning);
    // Observing the arm modules' joint angles too: four modules of 7 joints more.
    let angles = ObservationOptions {
        base_angular_velocity: true,
        arm_joint_angles: true,
    };
    let with = contract::contract(&tricycle, &terms, angles, b"skill-a", 30.0);
    assert_eq!(with[kumi_policies::metadata::OBSERVATION_DIM_KEY], "68");
    let description = &with[kumi_policies::metadata::OBSERVATION];
    assert!(
        description.ends_with(";arm_joint_angles:28:rad:joint"),
        "{description}"
    );
    assert_eq!(ObservationOptions::from_description(description), angles);
    let mut missing = trained.clone();
    missing.remove(contract::SKILL_FINGERPRINT);
    assert_eq!(
        contract::check(&trained, &missing),
        Err(ContractMismatch::Missing {
            key: contract::SKILL_FINGERPRINT
        })
    );
}

#[test]
fn bounds_read_back_from_the_action_description() {
    let bounds = GoalBounds {
        manipulator_position_m: 0.25,
        manipulator_rotation_rad: 0.5,
        leg_position_m: 0.1,
        leg_roll_rad: 0.3,
        wheel_velocity_rad_s: None,
        wheel_acceleration_rad_s2: None,
        lateral_acceleration_m_s2: None,
    };
    for name in ["minimal", "dragon", "tricycle"] {
        let model = robot(name);
        let terms = ActionTerms::new(&model, &bounds).unwrap();
        let back = GoalBounds::from_description(&terms.describe()).unwrap();
        let again = ActionTerms::new(&model, &back).unwrap();
        assert_eq!(again.describe(), terms.describe(), "{name}");
    }
    // Minimal has no leg: its leg bounds read back as 0.
    let minimal = ActionTerms::new(&robot("minimal"), &bounds).unwrap();
    let back = GoalBounds::from_description(&minimal.describe()).unwrap();
    assert_eq!(back.leg_position_m, 0.0);
    assert_eq!(back.manipulator_rotation_rad, 0.5);
    for bad in [
        "arm0",
        "arm0:manipulator:6:position_m=x:rotation_rad=0.5",
        "arm0:manipulator:6:position_m=0.2",
        "arm0:gripper:6:position_m=0.2:rotation_rad=0.5",
        "leg0:leg:4:position_m=0.1:roll_rad=0.5;leg1:leg:4:position_m=0.2:roll_rad=0.5",
        "arm0:manipulator:6:position_m=-1:rotation_rad=0.5",
        "wheel0:wheel:1",
        "wheel0:wheel:1:velocity_rad_s=x",
        "wheel0:wheel:1:velocity_rad_s=0",
    ] {
        assert!(GoalBounds::from_description(bad).is_err(), "{bad}");
    }
    // The wheel bound read back: the largest described, none without wheels, and for a policy
    // trained without one the wheels' own limit.
    let wheels = "w0:wheel:1:velocity_rad_s=2;w1:wheel:1:velocity_rad_s=5";
    let back = GoalBounds::from_description(wheels).unwrap();
    assert_eq!(back.wheel_velocity_rad_s, Some(5.0));
    let arm_only = "arm0:manipulator:6:position_m=0.25:rotation_rad=0.5";
    let back = GoalBounds::from_description(arm_only).unwrap();
    assert_eq!(back.wheel_velocity_rad_s, None);
    let tricycle = ActionTerms::new(&robot("tricycle"), &bounds).unwrap();
    let limit = tricycle.wheels().next().unwrap().scale_rad_s;
    let back = GoalBounds::from_description(&tricycle.describe()).unwrap();
    assert_eq!(back.wheel_velocity_rad_s, Some(limit));
}

#[test]
fn flat_terms_command_every_arm_joint_around_home_by_hand() {
    // The flat baseline (the paper's section V-C): 7 joint targets per arm module, one velocity per
    // wheel module. Tricycle: 4 arms, 3 wheel modules.
    let model = robot("tricycle");
    let terms = ActionTerms::flat(
        &model,
        &JointBounds {
            joint_scale_rad: 0.5,
            wheel_velocity_rad_s: None,
            wheel_acceleration_rad_s2: None,
            lateral_acceleration_m_s2: None,
        },
    )
    .unwrap();
    assert_eq!(terms.size(), 4 * 7 + 3);
    assert!(!terms.uses_skill());
    assert_eq!(terms.arms().count(), 0);
    assert_eq!(terms.names()[..2], ["arm0/joint1", "arm0/joint2"]);
    // Zero holds home; 1 moves by the scale; past 1 clips; NaN holds home.
    let mut action = vec![0.0_f32; terms.size()];
    let leg1 = model.module("leg1").unwrap();
    let first_leg = terms
        .terms
        .iter()
        .take_while(|t| t.module() != "leg1")
        .map(Term::width)
        .sum::<usize>();
    assert_eq!(first_leg, 14, "arm0 and leg0 come first");
    action[first_leg] = 1.0;
    action[first_leg + 3] = -3.0;
    action[first_leg + 6] = f32::NAN;
    let commands = terms.commands(&action).unwrap();
    assert_eq!(commands.joint_targets.len(), 4);
    assert!(commands.goals.is_empty());
    let leg1_targets = commands.joint_targets[2];
    assert_eq!(leg1_targets[0], leg1.home[0] + 0.5);
    assert_eq!(leg1_targets[3], leg1.home[3] - 0.5);
    assert_eq!(leg1_targets[6], leg1.home[6]);
    assert_eq!(leg1_targets[1], leg1.home[1]);
    assert_eq!(
        commands.joint_targets[0].to_vec(),
        model.module("arm0").unwrap().home
    );
    // The description says what the policy is; a node over the skill refuses it by name.
    let described = terms.describe();
    assert!(described.starts_with("arm0:manipulator:7:joint_targets:scale_rad=0.5;"));
    let err = GoalBounds::from_description(&described).unwrap_err();
    assert!(err.to_string().contains("flat baseline"), "{err}");
    // A flat policy's contract carries no skill and the arm state slots.
    let c = contract::contract(&model, &terms, NONE, b"any skill", 30.0);
    assert_eq!(c[contract::SKILL_FINGERPRINT], contract::NO_SKILL);
    assert!(c[kumi_policies::metadata::OBSERVATION]
        .ends_with("arm_joint_positions:28:rad:joint;arm_joint_velocities:28:rad/s:joint"));
    // A scale that is not positive is refused.
    for bad in [0.0, -1.0, f64::NAN] {
        assert!(ActionTerms::flat(
            &model,
            &JointBounds {
                joint_scale_rad: bad,
                wheel_velocity_rad_s: None,
                wheel_acceleration_rad_s2: None,
                lateral_acceleration_m_s2: None,
            }
        )
        .is_err());
    }
}

#[test]
fn a_wheel_bound_scales_wheel_velocities_below_the_wheels_limit_and_reads_back() {
    // Tricycle's wheels turn at up to their limit; a policy's bound lowers the scale for an
    // action of 1, never raises it, and the description carries it to a deployed node.
    let model = robot("tricycle");
    let limit = ActionTerms::new(&model, &BOUNDS)
        .unwrap()
        .wheels()
        .next()
        .unwrap()
        .scale_rad_s;
    let capped = GoalBounds {
        wheel_velocity_rad_s: Some(2.5),
        ..BOUNDS
    };
    assert!(limit > 2.5, "{limit}");
    let terms = ActionTerms::new(&model, &capped).unwrap();
    let mut action = vec![0.0_f32; terms.size()];
    let at = terms.size() - 3;
    action[at] = 0.5;
    action[at + 1] = -4.0;
    let wheels = terms.commands(&action).unwrap().wheel_velocities;
    assert_eq!(wheels, [1.25, -2.5, 0.0]);
    assert!(
        terms
            .describe()
            .ends_with("wheel2:wheel:1:velocity_rad_s=2.5"),
        "{}",
        terms.describe()
    );
    let back = GoalBounds::from_description(&terms.describe()).unwrap();
    assert_eq!(back.wheel_velocity_rad_s, Some(2.5));
    assert_eq!(
        ActionTerms::new(&model, &back).unwrap().describe(),
        terms.describe()
    );
    // Above the wheels' own limit the limit holds.
    let loose = GoalBounds {
        wheel_velocity_rad_s: Some(limit * 10.0),
        ..BOUNDS
    };
    let terms = ActionTerms::new(&model, &loose).unwrap();
    assert!(terms.wheels().all(|w| w.scale_rad_s == limit));
    // The flat baseline takes the same bound.
    let flat = ActionTerms::flat(
        &model,
        &JointBounds {
            joint_scale_rad: 0.5,
            wheel_velocity_rad_s: Some(2.5),
            wheel_acceleration_rad_s2: None,
            lateral_acceleration_m_s2: None,
        },
    )
    .unwrap();
    assert!(flat.wheels().all(|w| w.scale_rad_s == 2.5));
    // A bound that is not a positive speed is refused by name.
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let err = ActionTerms::new(
            &model,
            &GoalBounds {
                wheel_velocity_rad_s: Some(bad),
                ..BOUNDS
            },
        )
        .unwrap_err();
        assert!(err.to_string().contains("wheel_velocity_rad_s"), "{err}");
        assert!(ActionTerms::flat(
            &model,
            &JointBounds {
                joint_scale_rad: 0.5,
                wheel_velocity_rad_s: Some(bad),
                wheel_acceleration_rad_s2: None,
                lateral_acceleration_m_s2: None,
            }
        )
        .is_err());
    }
}

#[test]
fn a_ramp_moves_toward_the_wanted_velocity_by_at_most_its_step() {
    use kumi_terms::action::ramp;
    // By hand: 0.1 rad/s per step from 0 toward 0.35 takes 0.1, 0.2, 0.3, then 0.35 exactly.
    let mut now = 0.0;
    let mut seen = Vec::new();
    for _ in 0..4 {
        now = ramp(now, 0.35, Some(0.1));
        seen.push(now);
    }
    assert_eq!(seen, [0.1, 0.2, 0.30000000000000004, 0.35]);
    assert_eq!(ramp(1.0, -1.0, Some(0.5)), 0.5);
    assert_eq!(ramp(0.2, 0.25, Some(0.5)), 0.25);
    // A gap of exactly one step lands on the wanted value, either way.
    assert_eq!(ramp(0.0, 0.5, Some(0.5)), 0.5);
    assert_eq!(ramp(0.0, -0.5, Some(0.5)), -0.5);
    // No limit: the wanted value itself, bit for bit (an unramped policy's commands do not
    // change).
    assert_eq!(ramp(0.1, 0.3, None), 0.3);
}

#[test]
fn a_wheel_acceleration_ramps_the_wheel_commands_and_reads_back() {
    // 3 rad/s^2 at 30 Hz: 0.1 rad/s per control step. The ramp starts from stopped wheels,
    // each wheel module on its own, and a stop starts it again from 0.
    let model = robot("tricycle");
    let ramped = GoalBounds {
        wheel_acceleration_rad_s2: Some(3.0),
        ..BOUNDS
    };
    let terms = ActionTerms::new(&model, &ramped).unwrap();
    assert!(terms.wheels().all(|w| w.acceleration_rad_s2 == Some(3.0)));
    let limit = terms.wheels().next().unwrap().scale_rad_s;
    let mut action = vec![0.0_f32; terms.size()];
    let at = terms.size() - 3;
    action[at] = 1.0;
    action[at + 1] = -0.015625; // 2^-6: exact in f32
    let wanted = terms.commands(&action).unwrap().wheel_velocities;
    assert_eq!(wanted, [limit, -0.015625 * limit, 0.0]);
    let mut ramp = WheelRamp::new(&terms, 30.0);
    let first = ramp.follow(&wanted);
    assert!((first[0] - 0.1).abs() < 1e-12, "{first:?}");
    assert_eq!(first[1], -0.015625 * limit); // within one step: at once
    assert_eq!(first[2], 0.0);
    let second = ramp.follow(&wanted);
    assert!((second[0] - 0.2).abs() < 1e-12, "{second:?}");
    ramp.stop();
    assert!((ramp.follow(&wanted)[0] - 0.1).abs() < 1e-12);
    // Without an acceleration the ramp passes the policy's velocities through unchanged.
    let unramped = ActionTerms::new(&model, &BOUNDS).unwrap();
    assert_eq!(WheelRamp::new(&unramped, 30.0).follow(&wanted), wanted);
    // The description carries it to a deployed node; an old file (none) reads back as none.
    let described = terms.describe();
    assert!(
        described.ends_with(&format!(
            "wheel2:wheel:1:velocity_rad_s={limit}:acceleration_rad_s2=3"
        )),
        "{described}"
    );
    let back = GoalBounds::from_description(&described).unwrap();
    assert_eq!(back.wheel_acceleration_rad_s2, Some(3.0));
    assert_eq!(
        ActionTerms::new(&model, &back).unwrap().describe(),
        described
    );
    let old = GoalBounds::from_description(&unramped.describe()).unwrap();
    assert_eq!(old.wheel_acceleration_rad_s2, None);
    let malformed = described.replace("acceleration_rad_s2=3", "acceleration=3");
    assert!(GoalBounds::from_description(&malformed).is_err());
    // Wheel entries that disagree (one bound makes them all) are refused by name.
    let differ = described.replacen("acceleration_rad_s2=3", "acceleration_rad_s2=4", 1);
    let some = described.replacen(":acceleration_rad_s2=3", "", 1);
    for bad in [differ, some] {
        let err = GoalBounds::from_description(&bad).unwrap_err();
        assert!(err.to_string().contains("different wheel bounds"), "{err}");
    }
    // The flat baseline takes the same bound; one that is not positive is refused by name.
    let flat = JointBounds {
        joint_scale_rad: 0.5,
        wheel_velocity_rad_s: None,
        wheel_acceleration_rad_s2: Some(3.0),
        lateral_acceleration_m_s2: None,
    };
    let flat_terms = ActionTerms::flat(&model, &flat).unwrap();
    assert!(flat_terms
        .wheels()
        .all(|w| w.acceleration_rad_s2 == Some(3.0)));
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let err = ActionTerms::new(
            &model,
            &GoalBounds {
                wheel_acceleration_rad_s2: Some(bad),
                ..BOUNDS
            },
        )
        .unwrap_err();
        assert!(
            err.to_string().contains("wheel_acceleration_rad_s2"),
            "{err}"
        );
        let flat = JointBounds {
            wheel_acceleration_rad_s2: Some(bad),
            ..flat
        };
        assert!(ActionTerms::flat(&model, &flat).is_err());
    }
}

#[test]
fn the_turn_governor_by_hand() {
    // 0.5 m/s at 0.4 rad/s: 0.2 m/s^2 of lateral acceleration.
    assert_eq!(turn_governor(None, 0.5, 0.4), 1.0);
    assert_eq!(turn_governor(Some(0.2), 0.5, 0.3), 1.0);
    assert!((turn_governor(Some(0.1), 0.5, 0.4) - 0.5).abs() < 1e-12);
    // Either turning direction, either sign of speed.
    assert!((turn_governor(Some(0.1), 0.5, -0.4) - 0.5).abs() < 1e-12);
    assert!((turn_governor(Some(0.05), -1.0, 0.2) - 0.25).abs() < 1e-12);
    // Turning in place and driving straight are never governed.
    assert_eq!(turn_governor(Some(0.01), 0.0, 3.0), 1.0);
    assert_eq!(turn_governor(Some(0.01), 2.0, 0.0), 1.0);
    // A measurement that is not finite stops the wheels.
    assert_eq!(turn_governor(Some(0.1), f64::NAN, 0.1), 0.0);
    assert_eq!(turn_governor(Some(0.1), 1.0, f64::INFINITY), 0.0);
}

#[test]
fn a_lateral_acceleration_governs_the_wheel_commands_and_reads_back() {
    let model = robot("tricycle");
    let governed = GoalBounds {
        lateral_acceleration_m_s2: Some(0.1),
        wheel_acceleration_rad_s2: Some(3.0),
        ..BOUNDS
    };
    let terms = ActionTerms::new(&model, &governed).unwrap();
    assert_eq!(terms.lateral_acceleration_m_s2(), Some(0.1));
    let mut wheels = vec![2.0, -1.0, 0.5];
    // 0.5 m/s horizontally (a vertical speed is not part of the turn) at 0.4 rad/s about z.
    let turning = Vector3::new(0.0, 0.0, 0.4);
    assert_eq!(
        terms.governor_scale(&Vector3::new(0.5, 0.0, 9.0), &turning),
        0.5
    );
    terms.govern(&mut wheels, &Vector3::new(0.5, 0.0, 9.0), &turning);
    assert_eq!(wheels, [1.0, -0.5, 0.25]);
    terms.govern(&mut wheels, &Vector3::new(0.1, 0.0, 0.0), &turning);
    assert_eq!(wheels, [1.0, -0.5, 0.25]);
    // Without a governor the commands pass through bit for bit.
    let plain = ActionTerms::new(&model, &BOUNDS).unwrap();
    assert_eq!(plain.lateral_acceleration_m_s2(), None);
    let mut same = vec![2.0, -1.0, 0.5];
    plain.govern(
        &mut same,
        &Vector3::new(5.0, 0.0, 0.0),
        &Vector3::new(0.0, 0.0, 5.0),
    );
    assert_eq!(same, [2.0, -1.0, 0.5]);
    // The description carries it, after the ramp; it reads back, in either order (the parser's;
    // a node's contract check still wants the file's own text).
    let described = terms.describe();
    assert!(
        described.ends_with(":acceleration_rad_s2=3:lateral_acceleration_m_s2=0.1"),
        "{described}"
    );
    let back = GoalBounds::from_description(&described).unwrap();
    assert_eq!(back.lateral_acceleration_m_s2, Some(0.1));
    assert_eq!(back.wheel_acceleration_rad_s2, Some(3.0));
    assert_eq!(
        ActionTerms::new(&model, &back).unwrap().describe(),
        described
    );
    let swapped = described.replace(
        ":acceleration_rad_s2=3:lateral_acceleration_m_s2=0.1",
        ":lateral_acceleration_m_s2=0.1:acceleration_rad_s2=3",
    );
    assert_eq!(GoalBounds::from_description(&swapped).unwrap(), back);
    let alone = GoalBounds {
        lateral_acceleration_m_s2: Some(0.1),
        ..BOUNDS
    };
    let alone_described = ActionTerms::new(&model, &alone).unwrap().describe();
    let alone_back = GoalBounds::from_description(&alone_described).unwrap();
    assert_eq!(alone_back.lateral_acceleration_m_s2, Some(0.1));
    assert_eq!(alone_back.wheel_acceleration_rad_s2, None);
    // Wheel entries that disagree, and unknown wheel bounds, are refused by name.
    let differ = described.replacen(
        "lateral_acceleration_m_s2=0.1",
        "lateral_acceleration_m_s2=0.2",
        1,
    );
    assert!(GoalBounds::from_description(&differ)
        .unwrap_err()
        .to_string()
        .contains("different wheel bounds"));
    let unknown = described.replace("lateral_acceleration_m_s2=0.1", "lateral=0.1");
    assert!(GoalBounds::from_description(&unknown)
        .unwrap_err()
        .to_string()
        .contains("unknown wheel bound `lateral=0.1`"));
    // The flat baseline takes it too; one that is not positive is refused by name.
    let flat = JointBounds {
        joint_scale_rad: 0.5,
        wheel_velocity_rad_s: None,
        wheel_acceleration_rad_s2: None,
        lateral_acceleration_m_s2: Some(0.1),
    };
    assert_eq!(
        ActionTerms::flat(&model, &flat)
            .unwrap()
            .lateral_acceleration_m_s2(),
        Some(0.1)
    );
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let bounds = GoalBounds {
            lateral_acceleration_m_s2: Some(bad),
            ..BOUNDS
        };
        let err = ActionTerms::new(&model, &bounds).unwrap_err();
        assert!(
            err.to_string().contains("lateral_acceleration_m_s2"),
            "{err}"
        );
    }
}
