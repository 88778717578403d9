//! The worst bug this project can have is a policy fed differently in deployment than in
//! training. Here the arm node's observation, built from the ROS messages the sim bridge and a
//! goal publisher send, must equal the training environment's, bit for bit, for the same
//! simulator state, the targets it holds must equal training's, and the node's tool pose must
//! match the simulator's.

use kumi_arm_node::run::Prepared;
use kumi_arm_node::{joints, ArmNodeConfig, ClockSource, Output};
use kumi_msgs::builtin_interfaces::Time;
use kumi_msgs::geometry_msgs::PoseStamped;
use kumi_msgs::std_msgs::Header;
use kumi_policies::observation::OBSERVATION_DIM;
use kumi_runtime::BackendChoice;
use kumi_train::arm_reach::{ArmReach, ArmReachConfig};
use nalgebra::Isometry3;

#[test]
fn the_node_sees_what_training_saw() {
    let model = kumi_tests::shipped_model("arm");
    let config = ArmNodeConfig {
        model: model.clone(),
        robot: "arm".into(),
        module: "arm".into(),
        policy: kumi_runtime::shipped_arm_policy(),
        backend: BackendChoice::Tract,
        output: Output::Increments,
        domain_id: 0,
        clock: ClockSource::Sim,
        stale_after_s: 0.2,
        duplicate_check: std::time::Duration::from_millis(500),
        goal_sync_s: 0.0,
        wait_for_first_goal: false,
        hardware: None,
    };
    let mut node = Prepared::new(&config).unwrap();
    let skill = node.controller.skill().clone();
    let mut policy =
        kumi_runtime::SkillPolicy::load(&config.policy, &skill, BackendChoice::Tract).unwrap();
    let mut env = ArmReach::new(model, ArmReachConfig::default(), 17).unwrap();
    let mut from_env = env.reset();
    let mut compared = 0;
    // The node and the environment run in a closed loop, the policy acting on the
    // environment's observation: the node, fed what the bridge and a goal publisher send,
    // must build the same observation and hold the same targets, across goal changes.
    for step in 0..400 {
        // What the bridge publishes for this state, and the goal as a publisher would send it.
        let stamp = Time::from_seconds(step as f64 / 30.0);
        let js = kumi_sim_bridge::state::joint_state(env.world(), "arm", stamp).unwrap();
        let goal = env.observed_goal();
        let msg = PoseStamped {
            header: Header {
                stamp,
                frame_id: "arm/arm/base".into(),
            },
            pose: kumi_ros::geometry::pose(&Isometry3::from_parts(
                goal.position_b.into(),
                goal.orientation_b,
            )),
        };
        node.controller.set_goal(node.rules.accept(&msg).unwrap());
        let j = joints::read(&js, "arm", &node.controller.skill().joints).unwrap();
        node.controller.set_joints(j, stamp.seconds());

        let command = node.controller.step(stamp.seconds());
        let from_node = command.observation.expect("the node ran its policy");
        let bits = |o: &[f32; OBSERVATION_DIM]| o.map(f32::to_bits);
        assert_eq!(
            bits(&from_node),
            bits(&from_env),
            "step {step}: node {from_node:?} env {from_env:?}"
        );
        if step % 7 == 0 {
            // The tool pose the node reports (forward kinematics of measured joints) matches
            // the simulator's to within the joints' servo compliance.
            let fk = node.tool_pose_b(&j.q);
            let sim = env.tool_pose_b();
            let gap = (fk.translation.vector - sim.translation.vector).norm();
            assert!(
                gap < 2e-3,
                "step {step}: node's tool pose is {gap} m off the simulator's"
            );
            compared += 1;
        }
        let action = policy.act(&from_env).unwrap();
        let stepped = env.step(&action);
        assert!(!stepped.terminated);
        assert_eq!(
            command.targets.map(|t| t.map(f64::to_bits)),
            Some(env.targets().map(f64::to_bits)),
            "step {step}: the node's targets differ from training's"
        );
        from_env = stepped.observation;
    }
    assert!(compared > 50);
}
