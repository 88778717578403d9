//! `std_srvs/srv/Trigger`, the service kumi offers besides its parameters' (the sim bridge's
//! reset), served with rmw_fastrtps's request/reply mapping, as rclpy from PyPI calls it.

use std::time::{Duration, Instant};

use ros2_client::{Client, Message, Name, Server, ServiceMapping, ServiceTypeName};
use serde::{Deserialize, Serialize};

use crate::{create_error, qos, RosError, RosNode};

/// `std_srvs/srv/Trigger`'s request: no fields (ROS 2 sends an empty message as one byte).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct TriggerRequest {
    structure_needs_at_least_one_member: u8,
}
impl Message for TriggerRequest {}

/// `std_srvs/srv/Trigger`'s response.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct TriggerResponse {
    pub success: bool,
    pub message: String,
}
impl Message for TriggerResponse {}

/// A `std_srvs/srv/Trigger` server.
pub type TriggerServer = Server<TriggerRequest, TriggerResponse>;

/// A `std_srvs/srv/Trigger` client.
pub type TriggerClient = Client<TriggerRequest, TriggerResponse>;

fn service_name(full_name: &str) -> Result<Name, RosError> {
    Name::parse(full_name).map_err(|e| RosError::BadName {
        name: full_name.to_string(),
        reason: format!("{e:?}"),
    })
}

/// How kumi serves and calls every service: rmw_fastrtps's request/reply mapping (what rclpy
/// from PyPI runs), with its services' QoS (reliable, volatile, keep last 10).
const MAPPING: ServiceMapping = ServiceMapping::Enhanced;

/// A server of the service type `package/type_name` on the absolute name `full_name`.
pub(crate) fn server<Req, Resp>(
    node: &mut ros2_client::Node,
    full_name: &str,
    package: &str,
    type_name: &str,
) -> Result<Server<Req, Resp>, RosError>
where
    Req: Message + Clone + 'static,
    Resp: Message + 'static,
{
    let service_type = ServiceTypeName::new(package, type_name);
    node.create_server(
        MAPPING,
        &service_name(full_name)?,
        &service_type,
        qos::default(),
        qos::default(),
    )
    .map_err(create_error("service", full_name))
}

impl RosNode {
    /// A `std_srvs/srv/Trigger` server on the absolute service name `full_name`.
    pub fn trigger_server(&mut self, full_name: &str) -> Result<TriggerServer, RosError> {
        server(&mut self.node, full_name, "std_srvs", "Trigger")
    }

    /// A `std_srvs/srv/Trigger` client of the absolute service name `full_name`.
    pub fn trigger_client(&mut self, full_name: &str) -> Result<TriggerClient, RosError> {
        self.node
            .create_client(
                MAPPING,
                &service_name(full_name)?,
                &ServiceTypeName::new("std_srvs", "Trigger"),
                qos::default(),
                qos::default(),
            )
            .map_err(create_error("service client", full_name))
    }

    /// Whether another participant serves `full_name`: its request reader and its reply
    /// writer are discovered (a request sent before both are is lost).
    pub fn service_available(&self, full_name: &str) -> bool {
        let participant = self.context.domain_participant();
        let request = format!("rq{full_name}Request");
        let reply = format!("rr{full_name}Reply");
        participant
            .discovered_writers()
            .iter()
            .any(|w| w.publication_topic_data.topic_name == reply)
            && participant
                .discovered_readers()
                .iter()
                .any(|r| r.subscription_topic_data.topic_name() == &request)
    }

    /// Calls the `std_srvs/srv/Trigger` service `full_name` through `client` once it is
    /// available, and waits for its answer, all within `timeout`.
    pub fn trigger(
        &self,
        client: &TriggerClient,
        full_name: &str,
        timeout: Duration,
    ) -> Result<TriggerResponse, String> {
        let deadline = Instant::now() + timeout;
        while !self.service_available(full_name) {
            if Instant::now() > deadline {
                return Err(format!("no service {full_name} within {timeout:?}"));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        // The server discovered here is not yet the server having matched this client's
        // request writer: a moment for that before the one request goes out.
        std::thread::sleep(Duration::from_millis(200));
        let id = client
            .send_request(TriggerRequest::default())
            .map_err(|e| format!("calling {full_name}: {e:?}"))?;
        while Instant::now() < deadline {
            match client.receive_response() {
                Ok(Some((answered, response))) if answered == id => return Ok(response),
                Ok(_) => std::thread::sleep(Duration::from_millis(5)),
                Err(e) => return Err(format!("the answer of {full_name}: {e:?}")),
            }
        }
        Err(format!("no answer from {full_name} within {timeout:?}"))
    }
}
