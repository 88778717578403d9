//! Topic names: everything of one robot under `/<robot>`, each module under `/<robot>/<module>`,
//! so that launching one more module node is all a reconfiguration needs.

/// `/<robot>/<module>/joint_states`: `sensor_msgs/JointState`, the module's joints.
pub fn joint_states(robot: &str, module: &str) -> String {
    format!("/{robot}/{module}/joint_states")
}

/// `/<robot>/<module>/joint_increments`: `std_msgs/Float64MultiArray`, one increment [rad] per
/// joint in the module's joint order.
pub fn joint_increments(robot: &str, module: &str) -> String {
    format!("/{robot}/{module}/joint_increments")
}

/// `/<robot>/<module>/joint_set`: `sensor_msgs/JointState`, absolute targets by joint name (the
/// form MoonBot's Motion Stack uses).
pub fn joint_set(robot: &str, module: &str) -> String {
    format!("/{robot}/{module}/joint_set")
}

/// `/<robot>/<module>/wheel_velocity`: `std_msgs/Float64` [rad/s] for both wheels.
pub fn wheel_velocity(robot: &str, module: &str) -> String {
    format!("/{robot}/{module}/wheel_velocity")
}

/// `/<robot>/<module>/goal_pose`: `geometry_msgs/PoseStamped` in the module's base frame.
pub fn goal_pose(robot: &str, module: &str) -> String {
    format!("/{robot}/{module}/goal_pose")
}

/// `/<robot>/<module>/ee_pose`: `geometry_msgs/PoseStamped`, the tool pose in the module's
/// base frame, as the arm node measures it.
pub fn ee_pose(robot: &str, module: &str) -> String {
    format!("/{robot}/{module}/ee_pose")
}

/// `/<robot>/odom`: `nav_msgs/Odometry` of the base.
pub fn odom(robot: &str) -> String {
    format!("/{robot}/odom")
}

/// `/<robot>/imu`: `sensor_msgs/Imu` of the base.
pub fn imu(robot: &str) -> String {
    format!("/{robot}/imu")
}

/// `/<robot>/reset`: the sim bridge's `std_srvs/srv/Trigger` service that puts the robot back
/// at its start pose, sim time back to zero.
pub fn reset(robot: &str) -> String {
    format!("/{robot}/reset")
}

/// `/<robot>/robot_description`: `std_msgs/String`, the URDF, latched.
pub fn robot_description(robot: &str) -> String {
    format!("/{robot}/robot_description")
}

/// `/tf`: `tf2_msgs/TFMessage`.
pub const TF: &str = "/tf";
/// `/clock`: `rosgraph_msgs/Clock`, simulated time, for ROS tools (`use_sim_time`). With two
/// simulated robots on one domain it carries both simulators' times: kumi's nodes read their own
/// robot's [`robot_clock`].
pub const CLOCK: &str = "/clock";

/// `/<robot>/clock`: `rosgraph_msgs/Clock`, the simulated time of this robot's simulator only.
pub fn robot_clock(robot: &str) -> String {
    format!("/{robot}/clock")
}
/// `/rosout`: `rcl_interfaces/Log`, every node's log records.
pub const ROSOUT: &str = "/rosout";
/// `/diagnostics`: `diagnostic_msgs/DiagnosticArray`.
pub const DIAGNOSTICS: &str = "/diagnostics";

/// `/<robot>/<module>/joint_targets`: `sensor_msgs/JointState`, the position targets [rad] the
/// simulator's servos follow (what increments are added to), by joint name.
pub fn joint_targets(robot: &str, module: &str) -> String {
    format!("/{robot}/{module}/joint_targets")
}

/// `/tf_static`: `tf2_msgs/TFMessage`, fixed joints, latched.
pub const TF_STATIC: &str = "/tf_static";

/// The tf frame of a link: every frame of a robot is prefixed by its name
/// (`tricycle/arm0/base`), so that several robots share one `/tf`. Every frame id kumi
/// publishes or accepts is built here.
pub fn frame(robot: &str, link: &str) -> String {
    format!("{robot}/{link}")
}

/// The fixed frame that odometry and `/tf` roots are expressed in, per robot: `<robot>/odom`.
pub fn odom_frame(robot: &str) -> String {
    format!("{robot}/odom")
}

/// `/<robot>/goal_pose`: `geometry_msgs/PoseStamped`, the target for the manipulator's tool in
/// `<robot>/odom` (position and heading), taken by the whole-body node.
pub fn robot_goal_pose(robot: &str) -> String {
    format!("/{robot}/goal_pose")
}

/// `/<robot>/tool_pose`: `geometry_msgs/PoseStamped`, the manipulator's tool in `<robot>/odom`
/// as the whole-body node computes it from each tick's state.
pub fn tool_pose(robot: &str) -> String {
    format!("/{robot}/tool_pose")
}
