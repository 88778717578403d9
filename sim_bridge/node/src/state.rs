//! The simulator's state as ROS messages. Pure functions of the world; the node publishes them.

use kumi_model::kinematics::{JointKind, KinematicTree};
use kumi_msgs::builtin_interfaces::Time;
use kumi_msgs::geometry_msgs::{PoseWithCovariance, TransformStamped, Twist, TwistWithCovariance};
use kumi_msgs::nav_msgs::Odometry;
use kumi_msgs::sensor_msgs::{Imu, JointState};
use kumi_msgs::std_msgs::Header;
use kumi_msgs::tf2_msgs::TFMessage;
use kumi_ros::geometry;
use kumi_ros::topics::frame;
use kumi_worlds::SimWorld;
use nalgebra::Vector3;

/// Gravity in the world frame [m/s^2].
const GRAVITY_W: Vector3<f64> = Vector3::new(0.0, 0.0, -9.81);

fn header(stamp: Time, frame_id: String) -> Header {
    Header { stamp, frame_id }
}

/// One module's joint state: names (URDF joint names), positions [rad], velocities [rad/s].
pub fn joint_state(world: &dyn SimWorld, module: &str, stamp: Time) -> Option<JointState> {
    let range = world.module_range(module).ok()?;
    let names = world.actuator_names();
    let q = world.joint_positions();
    let v = world.joint_velocities();
    Some(JointState {
        header: header(stamp, String::new()),
        name: names[range.clone()].iter().map(|s| s.to_string()).collect(),
        position: q[range.clone()].to_vec(),
        velocity: v[range].to_vec(),
        effort: Vec::new(),
    })
}

/// The position targets [rad] one module's servos follow (what increments are added to), by
/// joint name; `None` for a module without position joints.
pub fn joint_targets(world: &dyn SimWorld, module: &str, stamp: Time) -> Option<JointState> {
    let range = world.module_range(module).ok()?;
    let names = world.actuator_names();
    let commands = world.commands();
    let actuators = world.servos().actuators();
    let position: Vec<usize> = range
        .filter(|&i| actuators[i].mode == kumi_model::ActuatorMode::Position)
        .collect();
    if position.is_empty() {
        return None;
    }
    Some(JointState {
        header: header(stamp, String::new()),
        name: position.iter().map(|&i| names[i].to_string()).collect(),
        position: position.iter().map(|&i| commands[i]).collect(),
        velocity: Vec::new(),
        effort: Vec::new(),
    })
}

/// Base odometry: pose in `<robot>/odom`, twist in the base frame.
pub fn odometry(world: &dyn SimWorld, robot: &str, stamp: Time) -> Odometry {
    let base = world.base_pose();
    let (v_w, w_w) = world.base_twist_w();
    let r_inv = base.rotation.inverse();
    Odometry {
        header: header(stamp, kumi_ros::topics::odom_frame(robot)),
        child_frame_id: frame(robot, &world.model().base_link),
        pose: PoseWithCovariance {
            pose: geometry::pose(&base),
            covariance: [0.0; 36],
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: geometry::vector3(&(r_inv * v_w)),
                angular: geometry::vector3(&(r_inv * w_w)),
            },
            covariance: [0.0; 36],
        },
    }
}

/// The base IMU: orientation in `<robot>/odom`; angular velocity [rad/s] and specific force
/// [m/s^2] (acceleration minus gravity: +9.81 up at rest) in the base frame. `accel_w` is the
/// base's linear acceleration in the world frame.
pub fn imu(world: &dyn SimWorld, robot: &str, accel_w: &Vector3<f64>, stamp: Time) -> Imu {
    let base = world.base_pose();
    let (_, w_w) = world.base_twist_w();
    let r_inv = base.rotation.inverse();
    Imu {
        header: header(stamp, frame(robot, &world.model().base_link)),
        orientation: geometry::quaternion(&base.rotation),
        orientation_covariance: [0.0; 9],
        angular_velocity: geometry::vector3(&(r_inv * w_w)),
        angular_velocity_covariance: [0.0; 9],
        linear_acceleration: geometry::vector3(&(r_inv * (accel_w - GRAVITY_W))),
        linear_acceleration_covariance: [0.0; 9],
    }
}

/// `/tf`: the base in `<robot>/odom`, then each moving joint's child in its parent (fixed
/// joints go once on `/tf_static`: [`static_transforms`]).
pub fn transforms(
    world: &dyn SimWorld,
    tree: &KinematicTree,
    robot: &str,
    stamp: Time,
) -> TFMessage {
    let poses: std::collections::HashMap<String, nalgebra::Isometry3<f64>> =
        world.body_poses().into_iter().collect();
    let links = tree.links();
    let mut transforms = Vec::with_capacity(tree.joints().len() + 1);
    transforms.push(TransformStamped {
        header: header(stamp, kumi_ros::topics::odom_frame(robot)),
        child_frame_id: frame(robot, &links[tree.root()]),
        transform: geometry::transform(&world.base_pose()),
    });
    for j in tree.joints().iter().filter(|j| j.kind != JointKind::Fixed) {
        let (parent, child) = (&links[j.parent_link], &links[j.child_link]);
        let relative = poses[parent].inverse() * poses[child];
        transforms.push(TransformStamped {
            header: header(stamp, frame(robot, parent)),
            child_frame_id: frame(robot, child),
            transform: geometry::transform(&relative),
        });
    }
    TFMessage { transforms }
}

/// `/tf_static`: each fixed joint's child in its parent, from the URDF (module mounts, tool
/// frames). Published once, latched.
pub fn static_transforms(tree: &KinematicTree, robot: &str) -> TFMessage {
    let links = tree.links();
    TFMessage {
        transforms: tree
            .joints()
            .iter()
            .filter(|j| j.kind == JointKind::Fixed)
            .map(|j| TransformStamped {
                header: header(Time::default(), frame(robot, &links[j.parent_link])),
                child_frame_id: frame(robot, &links[j.child_link]),
                transform: geometry::transform(&j.origin),
            })
            .collect(),
    }
}
