//! Joint-state intake: the module's `sensor_msgs/JointState`, read by joint name into the
//! skill's joint order.

use kumi_msgs::sensor_msgs::JointState;
use kumi_policies::observation::JOINTS;

pub use kumi_ros::joint_state::JointStateRejection;

/// Joint angles [rad] and velocities [rad/s] in the skill's order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Joints {
    pub q: [f64; JOINTS],
    pub qd: [f64; JOINTS],
}

/// Reads `msg` for the joints named `joints` (unprefixed, as in the skill), by the one rule
/// ([`kumi_ros::joint_state::read_named`]).
pub fn read(
    msg: &JointState,
    module: &str,
    joints: &[String],
) -> Result<Joints, JointStateRejection> {
    let joints = &joints[..joints.len().min(JOINTS)];
    let (q, qd) = kumi_ros::joint_state::read_named(msg, module, joints)?;
    let mut out = Joints {
        q: [0.0; JOINTS],
        qd: [0.0; JOINTS],
    };
    out.q[..q.len()].copy_from_slice(&q);
    out.qd[..qd.len()].copy_from_slice(&qd);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> Vec<String> {
        (1..=7).map(|i| format!("joint{i}")).collect()
    }

    fn msg(names: Vec<String>, q: Vec<f64>, qd: Vec<f64>) -> JointState {
        JointState {
            name: names,
            position: q,
            velocity: qd,
            ..Default::default()
        }
    }

    #[test]
    fn reads_by_name_in_skill_order_with_or_without_prefix() {
        // Reversed order, prefixed, plus an extra joint.
        let mut n: Vec<String> = (1..=7).rev().map(|i| format!("leg1/joint{i}")).collect();
        n.push("leg1/other".into());
        let q: Vec<f64> = (0..8).map(|i| 7.0 - f64::from(i)).collect();
        let qd: Vec<f64> = q.iter().map(|x| -x).collect();
        let j = read(&msg(n, q, qd), "leg1", &names()).unwrap();
        assert_eq!(j.q, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
        assert_eq!(j.qd[6], -7.0);
        let plain = read(&msg(names(), vec![0.5; 7], vec![0.0; 7]), "leg1", &names()).unwrap();
        assert_eq!(plain.q, [0.5; 7]);
    }

    #[test]
    fn refuses_what_it_cannot_use() {
        let short = read(&msg(names(), vec![0.0; 7], vec![]), "arm", &names());
        assert!(matches!(
            short,
            Err(JointStateRejection::WrongLength { velocities: 0, .. })
        ));
        let missing = read(
            &msg(names()[..6].to_vec(), vec![0.0; 6], vec![0.0; 6]),
            "arm",
            &names(),
        );
        assert_eq!(
            missing,
            Err(JointStateRejection::MissingJoint("joint7".into()))
        );
        let mut q = vec![0.0; 7];
        q[2] = f64::NAN;
        assert_eq!(
            read(&msg(names(), q, vec![0.0; 7]), "arm", &names()),
            Err(JointStateRejection::NonFinite("joint3".into()))
        );
        let mut twice = names();
        twice.push("arm/joint4".into());
        assert_eq!(
            read(&msg(twice, vec![0.0; 8], vec![0.0; 8]), "arm", &names()),
            Err(JointStateRejection::DuplicateJoint("arm/joint4".into()))
        );
    }
}
