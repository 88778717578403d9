//! kumi's ROS 2 plumbing on `ros2-client` (RustDDS): no C libraries, no ROS install.
//!
//! - [`RosNode::new`] takes the domain id explicitly (ros2-client's default context always uses
//!   domain 0); binaries read `ROS_DOMAIN_ID` once with [`domain_id_from_env`], tests pick
//!   their own so they can run in parallel without crosstalk.
//! - [`qos`] holds the QoS presets, each with the reason it is chosen.
//! - [`RosNode::publisher`] / [`RosNode::subscription`] derive the ROS type from the Rust type
//!   ([`kumi_msgs::RosMessage`]), so a topic's type is written once.
//! - [`topics`] is the one place topic names are built.

pub mod geometry;
pub mod joint_state;
pub mod motion_stack;
pub mod parameters;
pub mod qos;
pub mod rosout;
pub mod services;
pub mod strict;
pub mod topics;
mod warn;

pub use ros2_client::Publisher;
pub use strict::{RawChange, RawSubscription, StrictSubscription};
pub use warn::RateLimited;

use kumi_msgs::RosMessage;
use ros2_client::{
    Context, ContextOptions, Gid, MessageTypeName, Name, NodeName, NodeOptions, QosProfile,
    Subscription,
};

/// Errors creating ROS entities.
#[derive(Debug, thiserror::Error)]
pub enum RosError {
    #[error("ROS_DOMAIN_ID must be an integer from 0 to 232, got `{0}`")]
    BadDomainId(String),
    #[error("invalid ROS name `{name}`: {reason}")]
    BadName { name: String, reason: String },
    #[error("cannot create the ROS 2 context: {0}")]
    Context(String),
    #[error("cannot create {what} `{name}`: {reason}")]
    Create {
        what: &'static str,
        name: String,
        reason: String,
    },
}

/// Maps a ros2-client creation error to [`RosError::Create`].
fn create_error<E: std::fmt::Debug>(what: &'static str, name: &str) -> impl FnOnce(E) -> RosError {
    let name = name.to_string();
    move |e| RosError::Create {
        what,
        name,
        reason: format!("{e:?}"),
    }
}

/// The domain id from `ROS_DOMAIN_ID` (0 when unset), as ROS 2 tools read it.
pub fn domain_id_from_env() -> Result<u16, RosError> {
    match std::env::var("ROS_DOMAIN_ID") {
        Err(_) => Ok(0),
        Ok(s) if s.trim().is_empty() => Ok(0),
        Ok(s) => match s.trim().parse::<u16>() {
            Ok(id) if id <= 232 => Ok(id),
            _ => Err(RosError::BadDomainId(s)),
        },
    }
}

/// One ROS 2 node with its context.
pub struct RosNode {
    // Fields drop in order: the node (and its writers) before the context it lives in.
    node: ros2_client::Node,
    /// The RustDDS subscriber of strict subscriptions, made with the first one.
    subscriber: Option<ros2_client::dds::rustdds::Subscriber>,
    context: Context,
}

impl RosNode {
    /// Creates a node `namespace/name` on ROS domain `domain`.
    pub fn new(namespace: &str, name: &str, domain: u16) -> Result<Self, RosError> {
        let context = Context::with_options(ContextOptions::new().domain_id(domain))
            .map_err(|e| RosError::Context(format!("{e:?}")))?;
        let node_name = NodeName::new(namespace, name).map_err(|e| RosError::BadName {
            name: format!("{namespace}/{name}"),
            reason: format!("{e:?}"),
        })?;
        let node = context
            .new_node(node_name, NodeOptions::new().enable_rosout(false))
            .map_err(create_error("node", name))?;
        Ok(Self {
            node,
            subscriber: None,
            context,
        })
    }

    pub fn domain_id(&self) -> u16 {
        self.context.domain_id()
    }

    /// Serves `settings` as this node's read-only ROS parameters ([`parameters`]); the caller
    /// answers requests with [`parameters::ParameterServices::poll`] from its loop.
    pub fn parameter_services(
        &mut self,
        settings: parameters::Settings,
    ) -> Result<parameters::ParameterServices, RosError> {
        parameters::ParameterServices::new(&mut self.node, settings)
    }

    /// How many writers of other participants publish on the absolute topic `full_name`, as
    /// DDS discovery knows them now (discovery takes a moment after start-up). Read from the
    /// participant, not from ros2-client's graph, which only updates while its spinner runs.
    pub fn remote_publishers(&self, full_name: &str) -> usize {
        self.remote_writers(full_name).len()
    }

    /// The writers of other participants on the absolute topic `full_name` that DDS discovery
    /// knows now ([`Self::remote_publishers`]), by id. A writer of a node killed without
    /// saying goodbye stays listed until its lease runs out.
    pub fn remote_writers(&self, full_name: &str) -> std::collections::BTreeSet<Gid> {
        let dds_name = format!("rt{full_name}");
        self.context
            .domain_participant()
            .discovered_writers()
            .iter()
            .filter(|w| w.publication_topic_data.topic_name == dds_name)
            .map(|w| Gid::from(w.writer_proxy.remote_writer_guid))
            .collect()
    }

    /// Whether a node other than this one sends samples of `M` on the absolute topic
    /// `full_name` within `wait` (samples from `own`, this node's writer, do not count). The
    /// listening is done by a short-lived node of its own, `<name>_startup_check`, so that no
    /// reader is left on the topic afterwards (a node checking that it is the only one
    /// publishing its output must not appear as its own subscriber). A node discovery still
    /// lists but that sends nothing, such as one killed with SIGKILL, does not count.
    pub fn others_publish<M: RosMessage>(
        &self,
        full_name: &str,
        own: Gid,
        wait: std::time::Duration,
    ) -> Result<bool, RosError> {
        let fqn = self.node.fully_qualified_name();
        let name = fqn.rsplit('/').next().unwrap_or_default();
        let mut check = RosNode::new(
            self.node.namespace(),
            &format!("{name}_startup_check"),
            self.domain_id(),
        )?;
        let listener = check.strict_subscription::<M>(full_name, qos::default())?;
        let deadline = std::time::Instant::now() + wait;
        while std::time::Instant::now() < deadline {
            while let Some(taken) = listener.take() {
                if matches!(taken, Ok((_, writer)) if writer != own) {
                    return Ok(true);
                }
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        Ok(false)
    }

    fn topic<M: RosMessage>(
        &mut self,
        full_name: &str,
        qos: &QosProfile,
    ) -> Result<ros2_client::dds::rustdds::Topic, RosError> {
        self.topic_of_type(full_name, M::PACKAGE, M::NAME, qos)
    }

    fn topic_of_type(
        &mut self,
        full_name: &str,
        package: &str,
        type_name: &str,
        qos: &QosProfile,
    ) -> Result<ros2_client::dds::rustdds::Topic, RosError> {
        let name = Name::parse(full_name).map_err(|e| RosError::BadName {
            name: full_name.to_string(),
            reason: format!("{e:?}"),
        })?;
        self.node
            .create_topic(&name, MessageTypeName::new(package, type_name), qos)
            .map_err(create_error("topic", full_name))
    }

    /// A publisher of `M` on the absolute topic `full_name`.
    pub fn publisher<M: RosMessage>(
        &mut self,
        full_name: &str,
        qos: QosProfile,
    ) -> Result<Publisher<M>, RosError> {
        let topic = self.topic::<M>(full_name, &qos)?;
        self.node
            .create_publisher(&topic, Some(qos))
            .map_err(create_error("publisher", full_name))
    }

    /// A subscription to `M` on the absolute topic `full_name`.
    pub fn subscription<M: RosMessage>(
        &mut self,
        full_name: &str,
        qos: QosProfile,
    ) -> Result<Subscription<M>, RosError> {
        let topic = self.topic::<M>(full_name, &qos)?;
        self.node
            .create_subscription(&topic, Some(qos))
            .map_err(create_error("subscription", full_name))
    }

    /// A strictly decoding subscription to `M` on the absolute topic `full_name`
    /// ([`strict`]): what does not decode exactly is refused whole, with the reason.
    pub fn strict_subscription<M: RosMessage>(
        &mut self,
        full_name: &str,
        qos: QosProfile,
    ) -> Result<StrictSubscription<M>, RosError> {
        let raw = self.raw_subscription(full_name, M::PACKAGE, M::NAME, qos)?;
        Ok(StrictSubscription::new(raw))
    }

    /// A subscription to the absolute topic `full_name` of type `package/msg/type_name` that
    /// hands over each payload undecoded ([`RawSubscription`]).
    pub fn raw_subscription(
        &mut self,
        full_name: &str,
        package: &str,
        type_name: &str,
        qos: QosProfile,
    ) -> Result<RawSubscription, RosError> {
        use ros2_client::dds::rustdds::QosPolicies;
        let topic = self.topic_of_type(full_name, package, type_name, &qos)?;
        let graph = self
            .node
            .create_subscription::<strict::Unread>(&topic, Some(qos.clone()))
            .map_err(create_error("subscription", full_name))?;
        if self.subscriber.is_none() {
            let subscriber = self
                .context
                .domain_participant()
                .create_subscriber(&QosPolicies::from(qos.clone()))
                .map_err(create_error("subscriber", full_name))?;
            self.subscriber = Some(subscriber);
        }
        let reader = self
            .subscriber
            .as_ref()
            .expect("created above")
            .create_simple_datareader_no_key::<strict::RawSample, strict::RawAdapter>(
                &topic,
                Some(QosPolicies::from(qos)),
            )
            .map_err(create_error("subscription", full_name))?;
        Ok(RawSubscription::new(reader, graph))
    }

    /// Every topic that writers of other participants publish on, as DDS discovery knows them
    /// now: ROS topics only (DDS names `rt/...`), one entry per topic and type.
    pub fn discovered_topics(&self) -> Vec<DiscoveredTopic> {
        use ros2_client::dds::rustdds::policy::{Durability as DdsDurability, Reliability};
        let mut found: Vec<DiscoveredTopic> = Vec::new();
        for w in self.context.domain_participant().discovered_writers() {
            let data = &w.publication_topic_data;
            let Some(name) = data.topic_name.strip_prefix("rt") else {
                continue;
            };
            let topic = DiscoveredTopic {
                name: name.to_string(),
                dds_type: data.type_name.clone(),
                reliable: matches!(data.reliability, Some(Reliability::Reliable { .. })),
                transient_local: matches!(data.durability, Some(DdsDurability::TransientLocal)),
            };
            match found
                .iter_mut()
                .find(|t| t.name == topic.name && t.dds_type == topic.dds_type)
            {
                // A reader matches a writer only if it asks for no more than the writer
                // offers: what every writer on the topic offers.
                Some(known) => {
                    known.reliable &= topic.reliable;
                    known.transient_local &= topic.transient_local;
                }
                None => found.push(topic),
            }
        }
        found
    }
}

/// A topic some other participant publishes on ([`RosNode::discovered_topics`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DiscoveredTopic {
    /// The absolute ROS name, `/robot/odom`.
    pub name: String,
    /// The DDS type name, `nav_msgs::msg::dds_::Odometry_`.
    pub dds_type: String,
    /// Whether every writer on it is reliable.
    pub reliable: bool,
    /// Whether every writer on it keeps its last samples for late readers (latched).
    pub transient_local: bool,
}
