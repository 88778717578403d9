//! Read-only ROS 2 parameters: a node's settings (robot, policy file and its fingerprint, limits,
//! clock mode, ...) served on the six `rcl_interfaces` parameter services
//! (`<node>/list_parameters`, `get_parameters`, `get_parameter_types`, `describe_parameters`,
//! `set_parameters`, `set_parameters_atomically`), so that `ros2 param list`, `ros2 param get`
//! and `ros2 param describe` work as on any ROS 2 node. A kumi node's settings are fixed when it
//! starts: every set request is answered, and refused ([`READ_ONLY`]).
//!
//! The answers are pure functions of the settings ([`list`], [`get`], [`types`], [`describe`]);
//! [`ParameterServices::poll`] is the shell that serves them, called from the node's loop.

use std::collections::BTreeMap;

use ros2_client::parameters::raw;
pub use ros2_client::parameters::ParameterValue;
use ros2_client::rcl_interfaces::{
    DescribeParametersRequest, DescribeParametersResponse, GetParameterTypesRequest,
    GetParameterTypesResponse, GetParametersRequest, GetParametersResponse, ListParametersRequest,
    ListParametersResponse, ListParametersResult, SetParametersAtomicallyResponse,
    SetParametersRequest, SetParametersResponse,
};
use ros2_client::Server;

use crate::RosError;

/// Why a set request is refused.
pub const READ_ONLY: &str =
    "read-only: a kumi node's settings are fixed when it starts (restart it with other flags)";

/// A node's settings, by name.
pub type Settings = BTreeMap<String, ParameterValue>;

/// A file's settings: its path (`<name>.file`) and its fingerprint (`<name>.fingerprint`,
/// FNV-1a of its bytes, as kumi's policies name each other; empty when it cannot be read).
pub fn file(
    settings: &mut Settings,
    name: &str,
    path: &std::path::Path,
    fingerprint: impl Fn(&[u8]) -> String,
) {
    let print = std::fs::read(path).map_or_else(|_| String::new(), |b| fingerprint(&b));
    settings.insert(
        format!("{name}.file"),
        ParameterValue::String(path.display().to_string()),
    );
    settings.insert(format!("{name}.fingerprint"), ParameterValue::String(print));
}

/// `ListParameters`: the names under `prefixes` (all when none), at most `depth` levels below
/// the prefix (`.`-separated; 0: any depth), as rclcpp answers it.
pub fn list(settings: &Settings, request: &ListParametersRequest) -> ListParametersResult {
    let depth_ok =
        |rest: &str| request.depth == 0 || rest.matches('.').count() < request.depth as usize;
    let names: Vec<String> = settings
        .keys()
        .filter(|name| {
            if request.prefixes.is_empty() {
                return depth_ok(name);
            }
            request.prefixes.iter().any(|p| {
                name.strip_prefix(p.as_str())
                    .and_then(|rest| rest.strip_prefix('.'))
                    .is_some_and(depth_ok)
            })
        })
        .cloned()
        .collect();
    let mut prefixes: Vec<String> = names
        .iter()
        .filter_map(|n| n.rsplit_once('.').map(|(p, _)| p.to_string()))
        .collect();
    prefixes.sort();
    prefixes.dedup();
    ListParametersResult { names, prefixes }
}

/// `GetParameters`: each name's value (not set, for a name the node does not have).
pub fn get(settings: &Settings, names: &[String]) -> Vec<raw::ParameterValue> {
    names
        .iter()
        .map(|n| {
            settings
                .get(n)
                .cloned()
                .unwrap_or(ParameterValue::NotSet)
                .into()
        })
        .collect()
}

/// `GetParameterTypes`: each name's `rcl_interfaces/ParameterType`.
pub fn types(settings: &Settings, names: &[String]) -> Vec<u8> {
    get(settings, names).iter().map(|v| v.ptype).collect()
}

/// `DescribeParameters`: each name's type, marked read-only.
pub fn describe(settings: &Settings, names: &[String]) -> Vec<raw::ParameterDescriptor> {
    names
        .iter()
        .zip(types(settings, names))
        .map(|(name, ptype)| raw::ParameterDescriptor {
            name: name.clone(),
            r#type: ptype,
            description: String::new(),
            additional_constraints: String::new(),
            read_only: true,
            dynamic_typing: false,
            floating_point_range: Vec::new(),
            integer_range: Vec::new(),
        })
        .collect()
}

fn refused() -> raw::SetParametersResult {
    raw::SetParametersResult {
        successful: false,
        reason: READ_ONLY.to_string(),
    }
}

/// The six servers of one node, and its settings.
pub struct ParameterServices {
    settings: Settings,
    list: Server<ListParametersRequest, ListParametersResponse>,
    get: Server<GetParametersRequest, GetParametersResponse>,
    types: Server<GetParameterTypesRequest, GetParameterTypesResponse>,
    describe: Server<DescribeParametersRequest, DescribeParametersResponse>,
    set: Server<SetParametersRequest, SetParametersResponse>,
    set_atomically: Server<SetParametersRequest, SetParametersAtomicallyResponse>,
}

impl ParameterServices {
    /// Serves `settings` on `node`'s parameter services.
    pub(crate) fn new(node: &mut ros2_client::Node, settings: Settings) -> Result<Self, RosError> {
        let fqn = node.fully_qualified_name();
        Ok(Self {
            settings,
            list: server(node, &fqn, "list_parameters", "ListParameters")?,
            get: server(node, &fqn, "get_parameters", "GetParameters")?,
            types: server(node, &fqn, "get_parameter_types", "GetParameterTypes")?,
            describe: server(node, &fqn, "describe_parameters", "DescribeParameters")?,
            set: server(node, &fqn, "set_parameters", "SetParameters")?,
            set_atomically: server(
                node,
                &fqn,
                "set_parameters_atomically",
                "SetParametersAtomically",
            )?,
        })
    }

    /// Answers every request waiting; never blocks. A request that cannot be read or answered
    /// is dropped (the caller's client times out), never the node.
    pub fn poll(&self) {
        let s = &self.settings;
        while let Ok(Some((id, r))) = self.list.receive_request() {
            let _ = self.list.send_response(
                id,
                ListParametersResponse {
                    result: list(s, &r),
                },
            );
        }
        while let Ok(Some((id, r))) = self.get.receive_request() {
            let values = get(s, &r.names);
            let _ = self.get.send_response(id, GetParametersResponse { values });
        }
        while let Ok(Some((id, r))) = self.types.receive_request() {
            let values = types(s, &r.names);
            let _ = self
                .types
                .send_response(id, GetParameterTypesResponse { values });
        }
        while let Ok(Some((id, r))) = self.describe.receive_request() {
            let values = describe(s, &r.names);
            let _ = self
                .describe
                .send_response(id, DescribeParametersResponse { values });
        }
        while let Ok(Some((id, r))) = self.set.receive_request() {
            let results = r.parameter.iter().map(|_| refused()).collect();
            let _ = self
                .set
                .send_response(id, SetParametersResponse { results });
        }
        while let Ok(Some((id, _))) = self.set_atomically.receive_request() {
            let result = refused();
            let _ = self
                .set_atomically
                .send_response(id, SetParametersAtomicallyResponse { result });
        }
    }
}

fn server<Req, Resp>(
    node: &mut ros2_client::Node,
    fqn: &str,
    service: &str,
    type_name: &str,
) -> Result<Server<Req, Resp>, RosError>
where
    Req: ros2_client::Message + Clone + 'static,
    Resp: ros2_client::Message + 'static,
{
    crate::services::server(
        node,
        &format!("{fqn}/{service}"),
        "rcl_interfaces",
        type_name,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> Settings {
        [
            ("robot", ParameterValue::String("minimal".into())),
            ("stale_after_s", ParameterValue::Double(0.5)),
            ("policy.file", ParameterValue::String("p.onnx".into())),
            ("policy.fingerprint", ParameterValue::String("abc".into())),
            ("lockstep", ParameterValue::Boolean(true)),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
    }

    fn request(prefixes: &[&str], depth: u64) -> ListParametersRequest {
        ListParametersRequest {
            prefixes: prefixes.iter().map(|p| p.to_string()).collect(),
            depth,
        }
    }

    #[test]
    fn list_answers_every_name_or_those_under_a_prefix() {
        let s = settings();
        let all = list(&s, &request(&[], 0));
        assert_eq!(all.names.len(), 5);
        assert_eq!(all.prefixes, vec!["policy".to_string()]);
        let top = list(&s, &request(&[], 1));
        assert_eq!(top.names, vec!["lockstep", "robot", "stale_after_s"]);
        let policy = list(&s, &request(&["policy"], 0));
        assert_eq!(policy.names, vec!["policy.file", "policy.fingerprint"]);
        assert!(
            list(&s, &request(&["pol"], 0)).names.is_empty(),
            "a prefix is a whole name part"
        );
    }

    #[test]
    fn values_types_and_descriptions_are_read_only_and_unknown_names_not_set() {
        let s = settings();
        let names = vec!["stale_after_s".to_string(), "nope".to_string()];
        let values = get(&s, &names);
        assert_eq!(values[0].ptype, raw::ParameterType::DOUBLE);
        assert_eq!(values[0].double_value, 0.5);
        assert_eq!(values[1].ptype, raw::ParameterType::NOT_SET);
        assert_eq!(
            types(&s, &names),
            vec![raw::ParameterType::DOUBLE, raw::ParameterType::NOT_SET]
        );
        let described = describe(&s, &names);
        assert!(described.iter().all(|d| d.read_only));
        assert_eq!(described[0].name, "stale_after_s");
        assert!(!refused().successful && refused().reason.contains("read-only"));
    }
}
