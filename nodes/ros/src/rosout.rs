//! Log records on `/rosout`, as every ROS 2 node publishes them, so that `ros2 topic echo
//! /rosout` and rqt_console show kumi's warnings beside everyone else's.
//!
//! [`RosoutLayer`] is a `tracing` layer (installed once, by the binary); a node [`attach`]es
//! its publisher to the thread it runs on, and the layer publishes that thread's INFO, WARN and
//! ERROR records as that node. Threads without a node (and nested records, such as the DDS
//! library's own while it publishes) are not forwarded.

use std::cell::{Cell, RefCell};
use std::fmt::Write as _;
use std::time::{SystemTime, UNIX_EPOCH};

use kumi_msgs::builtin_interfaces::Time;
use kumi_msgs::rcl_interfaces::Log;
use ros2_client::Publisher;
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::layer::Context;
use tracing_subscriber::Layer;

use crate::{qos, topics, RosError, RosNode};

struct Sink {
    publisher: Publisher<Log>,
    logger: String,
}

thread_local! {
    static SINK: RefCell<Option<Sink>> = const { RefCell::new(None) };
    static PUBLISHING: Cell<bool> = const { Cell::new(false) };
}

/// Forwards this thread's records to `/rosout` while it lives.
#[must_use = "records are forwarded only while the guard lives"]
pub struct RosoutGuard(());

impl Drop for RosoutGuard {
    fn drop(&mut self) {
        SINK.with(|s| s.borrow_mut().take());
    }
}

/// The logger name ROS gives a node: its fully qualified name with dots, without the leading
/// one (`/arm/arm` + `arm_node` -> `arm.arm.arm_node`).
pub fn logger_name(namespace: &str, name: &str) -> String {
    namespace
        .split('/')
        .filter(|s| !s.is_empty())
        .chain(std::iter::once(name))
        .collect::<Vec<_>>()
        .join(".")
}

/// Publishes the records of the calling thread on `/rosout` as `logger` until the guard drops.
pub fn attach(node: &mut RosNode, logger: &str) -> Result<RosoutGuard, RosError> {
    let publisher = node.publisher::<Log>(topics::ROSOUT, qos::rosout())?;
    SINK.with(|s| {
        *s.borrow_mut() = Some(Sink {
            publisher,
            logger: logger.to_string(),
        })
    });
    Ok(RosoutGuard(()))
}

/// The `tracing` layer that feeds [`attach`]ed nodes' `/rosout`.
pub struct RosoutLayer;

/// A record's message, then its other fields as ` key=value`.
#[derive(Default)]
struct Message {
    text: String,
    fields: String,
}

impl Visit for Message {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let _ = write!(self.text, "{value:?}");
        } else {
            let _ = write!(self.fields, " {}={value:?}", field.name());
        }
    }

    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.text.push_str(value);
        } else {
            let _ = write!(self.fields, " {}={value}", field.name());
        }
    }
}

/// The `rcl_interfaces/Log` level of a `tracing` level; `None` below INFO.
pub fn level(level: &Level) -> Option<u8> {
    match *level {
        Level::ERROR => Some(Log::ERROR),
        Level::WARN => Some(Log::WARN),
        Level::INFO => Some(Log::INFO),
        _ => None,
    }
}

impl<S: Subscriber> Layer<S> for RosoutLayer {
    fn on_event(&self, event: &Event<'_>, _ctx: Context<'_, S>) {
        let Some(level) = level(event.metadata().level()) else {
            return;
        };
        if PUBLISHING.get() {
            return;
        }
        SINK.with(|s| {
            let sink = s.borrow();
            let Some(sink) = sink.as_ref() else {
                return;
            };
            let mut message = Message::default();
            event.record(&mut message);
            let since_epoch = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .unwrap_or_default();
            let meta = event.metadata();
            PUBLISHING.set(true);
            let _ = sink.publisher.publish(Log {
                stamp: Time::from_seconds(since_epoch.as_secs_f64()),
                level,
                name: sink.logger.clone(),
                msg: message.text + &message.fields,
                file: meta.file().unwrap_or_default().to_string(),
                function: meta.target().to_string(),
                line: meta.line().unwrap_or_default(),
            });
            PUBLISHING.set(false);
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn logger_names_and_levels_follow_ros() {
        assert_eq!(logger_name("/arm/arm", "arm_node"), "arm.arm.arm_node");
        assert_eq!(
            logger_name("/tricycle", "sim_bridge"),
            "tricycle.sim_bridge"
        );
        assert_eq!(logger_name("/", "x"), "x");
        assert_eq!(level(&Level::WARN), Some(30));
        assert_eq!(level(&Level::DEBUG), None);
    }
}
