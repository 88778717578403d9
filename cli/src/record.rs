//! `kumi record`: a robot's topics to an MCAP file ([`kumi_recorder`]), until Ctrl-C or for a
//! set time. `kumi launch --record DIR` starts it beside the nodes; `kumi demo --record`
//! records its own run.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Args;
use kumi_recorder::{RecordedTopic, Recorder};

#[derive(Args, Debug, Clone)]
pub struct RecordArgs {
    /// The robot's name: every topic under /<robot>/ is recorded, and /tf, /tf_static,
    /// /diagnostics, /rosout and /clock.
    pub robot: String,
    /// The MCAP file to write (default: <robot>.mcap in the current folder). An existing file
    /// is not overwritten.
    #[arg(long, short, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Stop after this many seconds (default: at Ctrl-C or SIGTERM).
    #[arg(long)]
    pub seconds: Option<f64>,
}

/// The file a recording of `robot` goes to in folder `dir`.
pub fn file_in(dir: &Path, robot: &str) -> PathBuf {
    dir.join(format!("{robot}.mcap"))
}

/// One line per recorded topic: count, topic, type.
pub fn summary(path: &Path, topics: &[RecordedTopic]) -> String {
    let total: u64 = topics.iter().map(|t| t.messages).sum();
    let mut text = format!(
        "recorded {total} messages on {} topics to {}",
        topics.len(),
        path.display()
    );
    for t in topics {
        text.push_str(&format!(
            "\n  {:>8}  {}  ({})",
            t.messages, t.topic, t.ros_type
        ));
    }
    text
}

pub fn run(args: RecordArgs) -> Result<()> {
    let path = args
        .output
        .clone()
        .unwrap_or_else(|| file_in(Path::new("."), &args.robot));
    if let Some(seconds) = args.seconds {
        anyhow::ensure!(
            seconds.is_finite() && seconds > 0.0,
            "--seconds must be a positive number of seconds, got {seconds}"
        );
    }
    let domain = kumi_ros::domain_id_from_env()?;
    let recorder = Recorder::create(&args.robot, domain, &path)?;
    let shutdown = Arc::new(AtomicBool::new(false));
    let flag = shutdown.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    eprintln!(
        "recording `{}` on ROS domain {domain} to {} (stop with Ctrl-C)",
        args.robot,
        path.display()
    );
    let recording = recorder.spawn();
    let started = Instant::now();
    let mut reported = 0;
    while !shutdown.load(Ordering::Relaxed)
        && !recording.failed()
        && args
            .seconds
            .is_none_or(|s| started.elapsed().as_secs_f64() < s)
    {
        let topics = recording.topics();
        if topics.len() > reported {
            reported = topics.len();
            eprintln!("recording {} topics", topics.len());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let topics = recording.stop()?;
    eprintln!("{}", summary(&path, &topics));
    Ok(())
}
