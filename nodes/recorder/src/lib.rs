//! Recordings of a robot's ROS 2 topics in MCAP, the format rosbag2 stores by default.
//!
//! A [`Recorder`] is a ROS 2 node (`/<robot>/recorder`) that follows DDS discovery: every topic
//! of the robot ([`records_topic`]: everything under `/<robot>/`, `/tf`, `/tf_static`,
//! `/diagnostics`, `/rosout` and `/clock`) is recorded from the moment a writer on it is
//! discovered, latched topics with the samples their writers keep. Each message is stored as
//! it came off the wire (CDR with its encapsulation header) on a channel with the message
//! encoding `cdr`, under a `ros2msg` schema named `package/msg/Name` with the full
//! definition ([`kumi_msgs::definitions`]), in a file of profile `ros2`: what rosbag2's MCAP
//! storage writes, so Foxglove, `mcap-ros2-support` and `ros2 bag` read it. A message's log
//! time is when it was received, its publish time when its writer stamped it.

use std::collections::BTreeSet;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use kumi_msgs::cdr::ByteOrder;
use kumi_msgs::definitions;
use kumi_ros::strict::RawSample;
use kumi_ros::{qos, topics, DiscoveredTopic, RawSubscription, RosError, RosNode};

/// Why a recording could not be made or finished.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{path}: already exists; remove it or record to another file")]
    Exists { path: PathBuf },
    #[error("cannot create {path}: {source}")]
    Create {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("writing {path}: {reason}")]
    Write { path: PathBuf, reason: String },
    #[error(transparent)]
    Ros(#[from] RosError),
}

/// Whether a recording of `robot` keeps the topic `name`: the robot's own topics and the
/// shared ones its nodes publish on. Pure.
pub fn records_topic(robot: &str, name: &str) -> bool {
    let shared = [
        topics::TF,
        topics::TF_STATIC,
        topics::DIAGNOSTICS,
        topics::ROSOUT,
        topics::CLOCK,
    ];
    name.strip_prefix('/')
        .and_then(|rest| rest.strip_prefix(robot))
        .is_some_and(|rest| rest.starts_with('/'))
        || shared.contains(&name)
}

/// A payload as rosbag2 stores it: the CDR encapsulation header (its byte order, options
/// zero) before the bytes. `None` for a payload that is not plain CDR. Pure.
pub fn stored_message(sample: &RawSample) -> Option<Vec<u8>> {
    let kind = match sample.order? {
        ByteOrder::Big => 0x00,
        ByteOrder::Little => 0x01,
    };
    let mut bytes = Vec::with_capacity(sample.bytes.len() + 4);
    bytes.extend_from_slice(&[0x00, kind, 0x00, 0x00]);
    bytes.extend_from_slice(&sample.bytes);
    Some(bytes)
}

/// How often a recorder looks for new topics: discovery copies every known writer, too much
/// work for each poll, and a topic is found within this of its writer's discovery.
pub const DISCOVERY_PERIOD: Duration = Duration::from_millis(100);

/// One recorded topic and how many messages it holds.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct RecordedTopic {
    pub topic: String,
    /// `package/msg/Name`.
    #[serde(rename = "type")]
    pub ros_type: String,
    pub messages: u64,
}

struct Channel {
    subscription: RawSubscription,
    id: u16,
    recorded: RecordedTopic,
}

/// A recording in progress: call [`Recorder::poll`] often (every few milliseconds), then
/// [`Recorder::finish`].
pub struct Recorder {
    // Fields drop in order: the subscriptions before the node they belong to.
    channels: Vec<Channel>,
    writer: mcap::Writer<BufWriter<File>>,
    /// Topics and DDS types seen and not recorded (no known schema), each reported once.
    skipped: BTreeSet<(String, String)>,
    /// When discovery was last looked at ([`DISCOVERY_PERIOD`]).
    discovered_at: Option<Instant>,
    robot: String,
    path: PathBuf,
    node: RosNode,
}

impl Recorder {
    /// Starts recording `robot`'s topics on ROS domain `domain` into a new file at `path`
    /// (an existing file is not overwritten).
    pub fn create(robot: &str, domain: u16, path: &Path) -> Result<Self, RecordError> {
        if path.exists() {
            return Err(RecordError::Exists {
                path: path.to_path_buf(),
            });
        }
        let file = File::create(path).map_err(|source| RecordError::Create {
            path: path.to_path_buf(),
            source,
        })?;
        let writer = mcap::WriteOptions::new()
            .compression(None)
            .profile("ros2")
            .library(concat!("kumi-recorder ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(write_error(path))?;
        let node = RosNode::new(&format!("/{robot}"), "recorder", domain)?;
        Ok(Self {
            channels: Vec::new(),
            writer,
            skipped: BTreeSet::new(),
            discovered_at: None,
            robot: robot.to_string(),
            path: path.to_path_buf(),
            node,
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The topics recorded so far, each with its type.
    pub fn topics(&self) -> Vec<RecordedTopic> {
        self.channels.iter().map(|c| c.recorded.clone()).collect()
    }

    /// Subscribes to the robot's topics discovered since it last looked (at most every
    /// [`DISCOVERY_PERIOD`]) and writes every message that has arrived. Returns how many were
    /// written.
    pub fn poll(&mut self) -> Result<usize, RecordError> {
        if self
            .discovered_at
            .is_none_or(|t| t.elapsed() >= DISCOVERY_PERIOD)
        {
            self.subscribe_new()?;
            self.discovered_at = Some(Instant::now());
        }
        let mut written = 0;
        for channel in &mut self.channels {
            while let Some(taken) = channel.subscription.take() {
                let change = match taken {
                    Ok(change) => change,
                    Err(e) => {
                        tracing::warn!("{}: a sample was lost: {e}", channel.recorded.topic);
                        continue;
                    }
                };
                let Some(data) = stored_message(&change.sample) else {
                    continue;
                };
                let log_time = now_ns();
                let header = mcap::records::MessageHeader {
                    channel_id: channel.id,
                    sequence: channel.recorded.messages as u32,
                    log_time,
                    publish_time: change.source_time_ns.unwrap_or(log_time),
                };
                self.writer
                    .write_to_known_channel(&header, &data)
                    .map_err(write_error(&self.path))?;
                channel.recorded.messages += 1;
                written += 1;
            }
        }
        Ok(written)
    }

    fn subscribe_new(&mut self) -> Result<(), RecordError> {
        for found in self.node.discovered_topics() {
            if !records_topic(&self.robot, &found.name) || self.has(&found) {
                continue;
            }
            let key = (found.name.clone(), found.dds_type.clone());
            let Some((ros_type, schema)) = definitions::ros_type_of_dds(&found.dds_type)
                .and_then(|t| definitions::schema(&t).map(|s| (t, s)))
            else {
                if self.skipped.insert(key) {
                    tracing::warn!(
                        "{}: type {} has no known schema; not recorded",
                        found.name,
                        found.dds_type
                    );
                }
                continue;
            };
            self.add_channel(&found, ros_type, &schema)?;
        }
        Ok(())
    }

    fn has(&self, found: &DiscoveredTopic) -> bool {
        let ros_type = definitions::ros_type_of_dds(&found.dds_type);
        self.channels.iter().any(|c| {
            c.recorded.topic == found.name && Some(&c.recorded.ros_type) == ros_type.as_ref()
        })
    }

    fn add_channel(
        &mut self,
        found: &DiscoveredTopic,
        ros_type: String,
        schema: &str,
    ) -> Result<(), RecordError> {
        let mut parts = ros_type.split('/');
        let (package, name) = (parts.next().unwrap_or(""), parts.next_back().unwrap_or(""));
        let subscription =
            self.node
                .raw_subscription(&found.name, package, name, qos::matching(found))?;
        let schema_id = self
            .writer
            .add_schema(&ros_type, "ros2msg", schema.as_bytes())
            .map_err(write_error(&self.path))?;
        let id = self
            .writer
            .add_channel(schema_id, &found.name, "cdr", &Default::default())
            .map_err(write_error(&self.path))?;
        tracing::info!("recording {} ({ros_type})", found.name);
        self.channels.push(Channel {
            subscription,
            id,
            recorded: RecordedTopic {
                topic: found.name.clone(),
                ros_type,
                messages: 0,
            },
        });
        Ok(())
    }

    /// Writes what has arrived and closes the file with its summary (the index readers seek
    /// with). Returns every recorded topic with its message count.
    pub fn finish(mut self) -> Result<Vec<RecordedTopic>, RecordError> {
        self.poll()?;
        self.writer.finish().map_err(write_error(&self.path))?;
        Ok(self.topics())
    }
}

/// A recording made by a thread of its own ([`Recorder::spawn`]).
pub struct RecordingThread {
    path: PathBuf,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    recorded: std::sync::Arc<std::sync::Mutex<Vec<RecordedTopic>>>,
    handle: std::thread::JoinHandle<Result<Vec<RecordedTopic>, RecordError>>,
}

impl RecordingThread {
    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The topics recorded so far, with their message counts.
    pub fn topics(&self) -> Vec<RecordedTopic> {
        self.recorded.lock().map(|t| t.clone()).unwrap_or_default()
    }

    /// Whether the thread stopped early (it failed to write: [`Self::stop`] says why).
    pub fn failed(&self) -> bool {
        self.handle.is_finished()
    }

    /// Stops recording and finishes the file ([`Recorder::finish`]).
    pub fn stop(self) -> Result<Vec<RecordedTopic>, RecordError> {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        self.handle.join().unwrap_or_else(|_| {
            Err(RecordError::Write {
                path: PathBuf::new(),
                reason: "the recording thread panicked".into(),
            })
        })
    }
}

impl Recorder {
    /// Records on a thread of its own, polling every 5 ms, until [`RecordingThread::stop`].
    pub fn spawn(mut self) -> RecordingThread {
        let path = self.path.clone();
        use std::sync::atomic::{AtomicBool, Ordering};
        use std::sync::{Arc, Mutex};
        let stop = Arc::new(AtomicBool::new(false));
        let recorded = Arc::new(Mutex::new(Vec::new()));
        let (stop_flag, shared) = (stop.clone(), recorded.clone());
        let handle = std::thread::spawn(move || {
            while !stop_flag.load(Ordering::Relaxed) {
                if let Err(e) = self.poll() {
                    // Close what was written so far: the file stays readable.
                    let _ = self.writer.finish();
                    return Err(e);
                }
                if let Ok(mut topics) = shared.lock() {
                    *topics = self.topics();
                }
                std::thread::sleep(std::time::Duration::from_millis(5));
            }
            self.finish()
        });
        RecordingThread {
            path,
            stop,
            recorded,
            handle,
        }
    }
}

fn write_error(path: &Path) -> impl FnOnce(mcap::McapError) -> RecordError + '_ {
    move |e| RecordError::Write {
        path: path.to_path_buf(),
        reason: e.to_string(),
    }
}

/// Wall-clock time [ns since the Unix epoch].
fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recording_keeps_the_robots_topics_and_the_shared_ones_only() {
        for kept in [
            "/minimal/odom",
            "/minimal/arm0/joint_states",
            "/tf",
            "/tf_static",
            "/diagnostics",
            "/rosout",
            "/clock",
        ] {
            assert!(records_topic("minimal", kept), "{kept}");
        }
        for left in [
            "/minimalist/odom",
            "/dragon/odom",
            "/minimal",
            "/tf2",
            "/chatter",
        ] {
            assert!(!records_topic("minimal", left), "{left}");
        }
    }

    #[test]
    fn a_stored_message_starts_with_its_encapsulation_header() {
        let sample = |order| RawSample {
            order,
            bytes: vec![7, 8],
        };
        assert_eq!(
            stored_message(&sample(Some(ByteOrder::Little))),
            Some(vec![0, 1, 0, 0, 7, 8])
        );
        assert_eq!(
            stored_message(&sample(Some(ByteOrder::Big))),
            Some(vec![0, 0, 0, 0, 7, 8])
        );
        assert_eq!(stored_message(&sample(None)), None);
    }

    #[test]
    fn an_existing_file_is_not_overwritten() {
        let path = std::env::temp_dir().join(format!("kumi-recorder-{}.mcap", std::process::id()));
        std::fs::write(&path, "keep").unwrap();
        let e = Recorder::create("minimal", 0, &path).err().unwrap();
        assert!(e.to_string().contains("already exists"), "{e}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "keep");
        std::fs::remove_file(&path).unwrap();
    }
}
