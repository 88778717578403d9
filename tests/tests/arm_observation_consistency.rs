//! The worst bug this project can have is a policy fed differently in deployment than in
//! training. Here the arm node's observation, built from the ROS messages the sim bridge and a
//! goal publisher send, must equal the training environment's, bit for bit, for the same
//! simulator state; and the node's tool pose must match the simulator's.

use kumi_arm_node::run::Prepared;
use kumi_arm_node::{joints, ArmNodeConfig, ClockSource, Output};
use kumi_msgs::builtin_interfaces::Time;
use kumi_msgs::geometry_msgs::PoseStamped;
use kumi_msgs::std_msgs::Header;
use kumi_runtime::BackendChoice;
use kumi_train::arm_reach::{ArmReach, ArmReachConfig};
use nalgebra::Isometry3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

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
    let mut env = ArmReach::new(model, ArmReachConfig::default(), 17).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    env.reset();
    let mut compared = 0;
    for step in 0..400 {
        // Random actions move the arm through varied states (and across goal changes).
        let action: [f32; 7] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        let out = env.step(&action);
        if step % 7 != 0 {
            continue;
        }
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

        let from_node = node.controller.observation().unwrap();
        let from_env = out.observation;
        let bits = |o: &[f32; 21]| o.map(f32::to_bits);
        assert_eq!(
            bits(&from_node),
            bits(&from_env),
            "step {step}: node {from_node:?} env {from_env:?}"
        );

        // The tool pose the node reports (forward kinematics of measured joints) matches the
        // simulator's to within the joints' servo compliance.
        let fk = node.tool_pose_b(&j.q);
        let sim = env.tool_pose_b();
        let gap = (fk.translation.vector - sim.translation.vector).norm();
        assert!(
            gap < 2e-3,
            "step {step}: node's tool pose is {gap} m off the simulator's"
        );
        compared += 1;
    }
    assert!(compared > 50);
}
