//! `kumi`: the front door to every kumi tool.

mod arm;
mod bench;
mod bench_learn;
mod bridge;
mod compare;
mod demo;
mod engine;
mod eval;
mod launch;
mod output;
mod plot;
mod policy;
mod record;
mod report;
mod robot;
mod sim;
mod trace_plot;
mod train;
mod whole_body;

use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "kumi",
    version,
    about = "Hierarchical controllers for modular robots: models, simulation, training, ROS 2 nodes"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the assembled URDF of a morphology (a shipped name or a path to a TOML file).
    Urdf {
        /// `minimal`, `dragon`, `tricycle`, `arm`, or a path to a morphology file.
        morphology: String,
        /// Print the MuJoCo model (MJCF) the MuJoCo engine builds from it instead.
        #[arg(long)]
        mjcf: bool,
    },
    /// What a robot is, before training it: modules and roles, mass, each arm module's home
    /// tool pose and standing height, the whole-body policy's sizes, whether it stands on the
    /// skill, and what a config for it should set.
    Robot(robot::RobotArgs),
    /// Simulate a morphology for a while and report what happened.
    Sim(sim::SimArgs),
    /// Run the sim bridge node: the simulated robot on ROS 2 (stop with Ctrl-C).
    SimBridge(bridge::BridgeArgs),
    /// Run the arm-module node: the shared low-level skill for one arm module (stop with Ctrl-C).
    Arm(arm::ArmArgs),
    /// Run the whole-body node: a robot's upper-level policy, sending each arm module's goal and
    /// each wheel module's velocity (stop with Ctrl-C).
    WholeBody(whole_body::WholeBodyArgs),
    /// The whole system end to end: launch a robot on a private ROS domain, send it targets,
    /// report each target's final tool error, with a top-down plot and a CSV of the run.
    Demo(demo::DemoArgs),
    /// Bring up a whole robot: the sim bridge, one arm node per arm module and the whole-body
    /// node, each its own process (stop all with Ctrl-C).
    Launch(launch::LaunchArgs),
    /// Record a robot's topics to an MCAP file (rosbag2's format; opens in Foxglove) until
    /// Ctrl-C.
    Record(record::RecordArgs),
    /// Train policies with PPO.
    Train {
        #[command(subcommand)]
        what: train::TrainCommand,
    },
    /// Evaluate trained policies.
    Eval {
        #[command(subcommand)]
        what: eval::EvalCommand,
    },
    /// Benchmarks.
    Bench {
        #[command(subcommand)]
        what: bench::BenchCommand,
    },
    /// Operations on policy files.
    Policy {
        #[command(subcommand)]
        what: policy::PolicyCommand,
    },
    /// Reports computed from the shipped configs and models.
    Report {
        #[command(subcommand)]
        what: report::ReportCommand,
    },
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // `{:#}` prints the whole chain of causes on one line, without a backtrace.
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    tracing_subscriber::registry()
        .with(
            tracing_subscriber::EnvFilter::try_from_default_env()
                // RustDDS reports every discovery event at info: keep it to warnings.
                .unwrap_or_else(|_| {
                    tracing_subscriber::EnvFilter::new(
                        "info,rustdds=warn,ros2_client=warn,ros2_client::distributions=error",
                    )
                }),
        )
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(std::io::stderr)
                // Colour codes only on a terminal: log files and pipes get plain text (and
                // NO_COLOR turns them off everywhere, as https://no-color.org asks).
                .with_ansi(
                    std::io::IsTerminal::is_terminal(&std::io::stderr())
                        && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty()),
                ),
        )
        // A node's records also go on /rosout.
        .with(kumi_ros::rosout::RosoutLayer)
        .init();
    let cli = Cli::parse();
    match cli.command {
        Command::Urdf { morphology, mjcf } => {
            let model = sim::load_model(&morphology)?;
            if mjcf {
                let config = kumi_worlds::SimConfig::for_model(&model);
                print!("{}", kumi_worlds::mjcf(&model, &config)?);
            } else {
                print!("{}", model.urdf_xml());
            }
            Ok(())
        }
        Command::Robot(args) => robot::run(args),
        Command::Sim(args) => sim::run(args),
        Command::SimBridge(args) => bridge::run(args),
        Command::Arm(args) => arm::run(args),
        Command::WholeBody(args) => whole_body::run(args),
        Command::Launch(args) => launch::run(args),
        Command::Demo(args) => demo::run(args),
        Command::Record(args) => record::run(args),
        Command::Train { what } => train::run(what),
        Command::Eval { what } => eval::run(what),
        Command::Bench { what } => bench::run(what),
        Command::Policy { what } => policy::run(what),
        Command::Report { what } => report::run(what),
    }
}
