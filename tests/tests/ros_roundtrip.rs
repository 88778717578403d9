//! Every message type round-trips between Rust (kumi-msgs over ros2-client) and rclpy with
//! identical values, both ways. Both sides build their values from `tests/ros/samples.json`.
//! Rust reads with the strict decoder the nodes use ([`kumi_ros::strict`]): what Fast DDS
//! writes must decode exactly, alignment padding and all.
//!
//! Python -> Rust: rclpy publishes each sample, Rust compares what it decodes.
//! Rust -> Python -> Rust: Rust publishes each sample, rclpy decodes it (and compares it with
//! the JSON), then republishes what it decoded, and Rust compares that again.
//! `tf2_msgs/TFMessage` has no rclpy package on PyPI; its element, TransformStamped, is covered.

use std::fmt::Debug;
use std::time::{Duration, Instant};

use kumi_msgs::{
    builtin_interfaces, diagnostic_msgs, geometry_msgs, nav_msgs, rosgraph_msgs, sensor_msgs,
    std_msgs, RosMessage,
};
use kumi_ros::{qos, RosNode, StrictSubscription};
use kumi_tests::{fresh_domain, peer, workspace};
use ros2_client::Publisher;
use serde_json::Value;

trait Endpoint {
    fn key(&self) -> &str;
    fn poll(&mut self, publish: bool);
    /// (received from Python as expected, echo received back as expected)
    fn status(&self) -> (Option<bool>, Option<bool>);
    fn describe(&self) -> String;
}

struct Typed<M: RosMessage> {
    key: String,
    expected: M,
    from_py: StrictSubscription<M>,
    to_py: Publisher<M>,
    echo: StrictSubscription<M>,
    /// Payloads the strict decoder refused, with the reason.
    refused: Vec<String>,
    got_from_py: Option<M>,
    got_echo: Option<M>,
}

impl<M: RosMessage + PartialEq + Debug> Typed<M> {
    fn new(node: &mut RosNode, key: &str, sample: &Value) -> Self {
        let topic = key.replace('/', "_");
        Self {
            key: key.to_string(),
            expected: serde_json::from_value(sample.clone())
                .unwrap_or_else(|e| panic!("{key}: sample does not fit the Rust type: {e}")),
            from_py: node
                .strict_subscription(&format!("/kumi_rt/py2rs/{topic}"), qos::default())
                .unwrap(),
            to_py: node
                .publisher(&format!("/kumi_rt/rs2py/{topic}"), qos::default())
                .unwrap(),
            echo: node
                .strict_subscription(&format!("/kumi_rt/py_echo/{topic}"), qos::default())
                .unwrap(),
            got_from_py: None,
            got_echo: None,
            refused: Vec::new(),
        }
    }
}

impl<M: RosMessage + PartialEq + Debug> Endpoint for Typed<M> {
    fn key(&self) -> &str {
        &self.key
    }

    fn poll(&mut self, publish: bool) {
        while let Some(taken) = self.from_py.take() {
            match taken {
                Ok((m, _)) => self.got_from_py = Some(m),
                Err(why) => self.refused.push(why),
            }
        }
        while let Some(taken) = self.echo.take() {
            match taken {
                Ok((m, _)) => self.got_echo = Some(m),
                Err(why) => self.refused.push(why),
            }
        }
        if publish {
            let _ = self.to_py.publish(self.expected.clone());
        }
    }

    fn status(&self) -> (Option<bool>, Option<bool>) {
        assert!(
            self.refused.is_empty(),
            "{}: the strict decoder refused what rclpy sent: {:?}",
            self.key,
            self.refused
        );
        (
            self.got_from_py.as_ref().map(|m| *m == self.expected),
            self.got_echo.as_ref().map(|m| *m == self.expected),
        )
    }

    fn describe(&self) -> String {
        format!(
            "{}:\n expected {:?}\n from rclpy {:?}\n echoed {:?}",
            self.key, self.expected, self.got_from_py, self.got_echo
        )
    }
}

#[test]
fn every_message_type_round_trips_with_rclpy() {
    let samples_path = workspace().join("tests/ros/samples.json");
    let samples: Value =
        serde_json::from_str(&std::fs::read_to_string(&samples_path).unwrap()).unwrap();
    let domain = fresh_domain();
    let mut node = RosNode::new("/", "roundtrip", domain).unwrap();

    macro_rules! endpoints {
        ($($key:literal => $ty:ty),* $(,)?) => {
            vec![$(Box::new(Typed::<$ty>::new(&mut node, $key, &samples[$key])) as Box<dyn Endpoint>),*]
        };
    }
    let mut endpoints = endpoints![
        "builtin_interfaces/Time" => builtin_interfaces::Time,
        "std_msgs/Header" => std_msgs::Header,
        "std_msgs/Float64" => std_msgs::Float64,
        "std_msgs/Float64MultiArray" => std_msgs::Float64MultiArray,
        "std_msgs/String" => std_msgs::StringMsg,
        "std_msgs/Bool" => std_msgs::Bool,
        "geometry_msgs/Vector3" => geometry_msgs::Vector3,
        "geometry_msgs/Quaternion" => geometry_msgs::Quaternion,
        "geometry_msgs/Pose" => geometry_msgs::Pose,
        "geometry_msgs/PoseStamped" => geometry_msgs::PoseStamped,
        "geometry_msgs/Twist" => geometry_msgs::Twist,
        "geometry_msgs/Transform" => geometry_msgs::Transform,
        "geometry_msgs/TransformStamped" => geometry_msgs::TransformStamped,
        "sensor_msgs/JointState" => sensor_msgs::JointState,
        "sensor_msgs/Imu" => sensor_msgs::Imu,
        "nav_msgs/Odometry" => nav_msgs::Odometry,
        "rosgraph_msgs/Clock" => rosgraph_msgs::Clock,
        "diagnostic_msgs/KeyValue" => diagnostic_msgs::KeyValue,
        "diagnostic_msgs/DiagnosticStatus" => diagnostic_msgs::DiagnosticStatus,
        "diagnostic_msgs/DiagnosticArray" => diagnostic_msgs::DiagnosticArray,
    ];
    assert_eq!(
        endpoints.len(),
        samples.as_object().unwrap().len(),
        "every sample has a Rust endpoint"
    );

    let python = std::thread::spawn(move || {
        peer(
            domain,
            &[
                "roundtrip",
                "--samples",
                samples_path.to_str().unwrap(),
                "--timeout",
                "40",
                "--linger",
                "3",
            ],
            Duration::from_secs(90),
        )
    });
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut last_publish = Instant::now() - Duration::from_secs(1);
    loop {
        let publish = last_publish.elapsed() > Duration::from_millis(100);
        if publish {
            last_publish = Instant::now();
        }
        for e in &mut endpoints {
            e.poll(publish);
        }
        if endpoints
            .iter()
            .all(|e| matches!(e.status(), (Some(_), Some(_))))
            || Instant::now() > deadline
        {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let report = python.join().unwrap();
    for e in &endpoints {
        let (from_py, echo) = e.status();
        assert_eq!(
            from_py,
            Some(true),
            "rclpy -> Rust differs or never arrived: {}",
            e.describe()
        );
        assert_eq!(
            echo,
            Some(true),
            "Rust -> rclpy -> Rust differs or never arrived: {}",
            e.describe()
        );
        assert_eq!(
            report["equal"][e.key()],
            true,
            "rclpy decoded {} differently: {}",
            e.key(),
            report["received_from_rust"][e.key()]
        );
    }
}
