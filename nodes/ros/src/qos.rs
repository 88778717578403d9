//! QoS presets. Each topic picks one, for the reason given here.

use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::QosProfile;

/// What stock rclpy publishers and subscribers use by default: reliable, volatile, keep last 10.
/// Every topic uses this unless it has a reason not to, so `ros2 topic pub/echo` and rclpy
/// nodes match it without flags.
pub fn default() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
}

/// Latched: reliable, transient local, keep last 1. For the robot description, so a node that
/// starts later still receives it (what `robot_state_publisher` does).
pub fn latched() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 1 })
}

/// `/rosout`, as rcl publishes it: reliable, transient local, keep last 1000, so that a
/// `ros2 topic echo /rosout` started late still sees the recent records.
pub fn rosout() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 1000 })
}
