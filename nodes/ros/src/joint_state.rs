//! Reading a `sensor_msgs/JointState` by joint name: the one rule every node applies to joint
//! states (lengths agree, no joint named twice, every wanted joint present and finite).

use kumi_msgs::sensor_msgs::JointState;

/// Why a joint-state message was not used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JointStateRejection {
    #[error("joint state has {names} names, {positions} positions and {velocities} velocities; a position and a velocity are needed for each named joint")]
    WrongLength {
        names: usize,
        positions: usize,
        velocities: usize,
    },
    #[error("joint state lacks joint `{0}`")]
    MissingJoint(String),
    #[error("joint state names joint `{0}` twice")]
    DuplicateJoint(String),
    #[error("joint state has a non-finite value for `{0}`")]
    NonFinite(String),
}

/// Positions [rad] and velocities [rad/s] of the joints named `joints`, in that order. Names
/// in the message may carry the module prefix (`leg1/joint3`, as the sim bridge publishes
/// them) or not, and so may `joints`; extra joints are ignored.
pub fn read_named(
    msg: &JointState,
    module: &str,
    joints: &[String],
) -> Result<(Vec<f64>, Vec<f64>), JointStateRejection> {
    if msg.name.len() != msg.position.len() || msg.name.len() != msg.velocity.len() {
        return Err(JointStateRejection::WrongLength {
            names: msg.name.len(),
            positions: msg.position.len(),
            velocities: msg.velocity.len(),
        });
    }
    let prefix = format!("{module}/");
    let bare = |n: &str| n.strip_prefix(prefix.as_str()).unwrap_or(n).to_string();
    let mut seen = std::collections::HashSet::with_capacity(msg.name.len());
    for name in &msg.name {
        if !seen.insert(bare(name)) {
            return Err(JointStateRejection::DuplicateJoint(name.clone()));
        }
    }
    let mut q = Vec::with_capacity(joints.len());
    let mut qd = Vec::with_capacity(joints.len());
    for joint in joints {
        let wanted = bare(joint);
        let k = msg
            .name
            .iter()
            .position(|n| bare(n) == wanted)
            .ok_or_else(|| JointStateRejection::MissingJoint(joint.clone()))?;
        let (p, v) = (msg.position[k], msg.velocity[k]);
        if !p.is_finite() || !v.is_finite() {
            return Err(JointStateRejection::NonFinite(joint.clone()));
        }
        q.push(p);
        qd.push(v);
    }
    Ok((q, qd))
}
