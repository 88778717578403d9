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

/// What a reader asks for to match every writer of a topic and get what they keep: reliable
/// and transient local only when every writer offers it ([`crate::DiscoveredTopic`]); keep
/// last 1000, so that a reader drained a few times a second loses nothing.
pub fn matching(topic: &crate::DiscoveredTopic) -> QosProfile {
    let profile = if topic.reliable {
        QosProfile::publisher_default().reliability_reliable(WhenFull::DEFAULT)
    } else {
        QosProfile::publisher_default().reliability_best_effort()
    };
    profile
        .durability(if topic.transient_local {
            Durability::TransientLocal
        } else {
            Durability::Volatile
        })
        .history(History::KeepLast { depth: 1000 })
}
