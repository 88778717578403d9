//! `kumi launch`: a whole robot from its morphology file. The sim bridge, one arm node per arm
//! module and the whole-body node, each its own process and its own ROS 2 node, started from
//! the equivalent `kumi` commands (printed, so that any of them can be run by hand or on
//! another host instead).
//!
//! **Supervision.** One Ctrl-C (or SIGTERM) stops every node and waits for them. A node that
//! exits on its own stops the whole launch, with its name and exit status, and the launch
//! exits non-zero: a robot missing a node is not the robot that was launched, and a restart
//! loop would hide the cause. The nodes themselves survive a peer's restart, so a node can be
//! restarted by hand (`--without` leaves one out to start it elsewhere).

use crate::train::Variant;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use kumi_model::RobotModel;
use kumi_policies::observation::JOINTS;

use crate::sim::load_model;

#[derive(Args, Debug, Clone)]
pub struct LaunchArgs {
    /// `minimal`, `dragon`, `tricycle`, or a path to a morphology file.
    pub morphology: String,
    /// Robot name, the namespace of every topic (default: the morphology's name).
    #[arg(long)]
    pub robot: Option<String>,
    /// The bridge steps only when every node has answered the tick (reproducible, as fast as
    /// the nodes allow); without it, real time.
    #[arg(long)]
    pub lockstep: bool,
    /// Physics engine of the sim bridge: rapier (default) or mujoco.
    #[arg(long)]
    pub engine: Option<String>,
    /// Leave this arm module's node out (repeatable), to start it by hand or on another host.
    #[arg(long = "without", value_name = "MODULE")]
    pub without: Vec<String>,
    /// No whole-body node: arm goals come from elsewhere (`ros2 topic pub`).
    #[arg(long)]
    pub no_whole_body: bool,
    /// The whole-body policy (default: the shipped policies/<robot>_whole_body/<robot>_whole_body.onnx,
    /// else the one training wrote, runs/<robot>_whole_body/<robot>_whole_body.onnx).
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// The base tilt [rad] past which the whole-body node stops driving (default: the one the
    /// policy was trained with, from its metadata).
    #[arg(long)]
    pub tilt_limit_rad: Option<f64>,
    /// The skill every arm node runs (default: the shipped policies/arm_reach/arm_reach.onnx).
    #[arg(long)]
    pub skill: Option<PathBuf>,
    /// Inference backend of every node: auto (ONNX Runtime when ORT_DYLIB_PATH is set, else
    /// tract), onnxruntime or tract.
    #[arg(long)]
    pub backend: Option<String>,
    /// On MoonBot hardware: no sim bridge; the nodes talk to Motion Stack's limbs as the
    /// profile maps them (`--profile`, default beside the morphology file:
    /// `<morphology>.motion_stack.toml`).
    #[arg(long, value_enum)]
    pub hardware: Option<Hardware>,
    /// The Motion Stack profile for `--hardware motion-stack`.
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
    /// Record every topic of the robot to DIR/<robot>.mcap (`kumi record`, started before the
    /// nodes; MCAP as rosbag2 writes it, for Foxglove and `ros2 bag`).
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,
}

/// Hardware a launch can drive instead of the simulator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Hardware {
    /// MoonBot's Motion Stack.
    MotionStack,
}

/// The Motion Stack profile a launch uses: `--profile`, or the one beside the morphology.
pub fn profile_path(args: &LaunchArgs) -> PathBuf {
    args.profile.clone().unwrap_or_else(|| {
        let shipped = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../urdf/morphologies");
        kumi_ros::motion_stack::default_path(&args.morphology, &shipped)
    })
}

/// One node of a launch: a name for its log lines and the `kumi` arguments that start it.
#[derive(Debug, Clone, PartialEq)]
pub struct Planned {
    pub name: String,
    pub args: Vec<String>,
}

/// How long an arm node waits for the goal of the current tick [ms] (`kumi arm
/// --goal-sync-ms`): in lockstep long enough for a tick on a heavily loaded machine, but under
/// the bridge's [`LOCKSTEP_TIMEOUT_S`]; in real time a third of a control period.
fn goal_sync_ms(lockstep: bool) -> &'static str {
    if lockstep {
        "2500"
    } else {
        "10"
    }
}

/// The bridge's lockstep timeout in a launch [s] (`kumi sim-bridge --lockstep-timeout`): a
/// step waits this long for a node that answered the last tick before stepping without it.
/// Longer than any tick takes on a heavily loaded machine, so that a run repeats exactly; a
/// node that died costs one such wait (then it is no longer waited for).
const LOCKSTEP_TIMEOUT_S: &str = "5";

/// The nodes to start for `model`, in start order. Pure.
pub fn plan(model: &RobotModel, args: &LaunchArgs) -> Result<Vec<Planned>> {
    let robot = args.robot.clone().unwrap_or_else(|| model.name.clone());
    let arms: Vec<&str> = model
        .modules
        .iter()
        .filter(|m| m.ee_link.is_some() && m.position_joints().count() == JOINTS)
        .map(|m| m.name.as_str())
        .collect();
    for w in &args.without {
        if !arms.contains(&w.as_str()) {
            bail!(
                "--without {w}: robot `{}` has no arm module `{w}` (its arm modules: {})",
                model.name,
                arms.join(", ")
            );
        }
    }
    let s = |v: &str| v.to_string();
    let mut bridge = vec![
        s("sim-bridge"),
        args.morphology.clone(),
        s("--robot"),
        robot.clone(),
    ];
    if args.lockstep {
        bridge.extend([
            s("--lockstep"),
            s("--lockstep-timeout"),
            s(LOCKSTEP_TIMEOUT_S),
        ]);
    }
    if let Some(e) = &args.engine {
        bridge.extend([s("--engine"), e.clone()]);
    }
    let started_arms: Vec<&str> = arms
        .iter()
        .copied()
        .filter(|a| !args.without.iter().any(|w| w == a))
        .collect();
    if args.lockstep && !args.no_whole_body {
        // The first step waits for every node started here: the arm nodes, and the
        // whole-body node through the wheels it drives.
        let wheels = model
            .modules
            .iter()
            .filter(|m| m.velocity_joints().count() > 0)
            .map(|m| m.name.as_str());
        let first: Vec<&str> = started_arms.iter().copied().chain(wheels).collect();
        if !first.is_empty() {
            bridge.extend([s("--wait-for"), first.join(",")]);
        }
    }
    let hardware = args
        .hardware
        .map(|_| profile_path(args).display().to_string());
    let mut nodes = Vec::new();
    if let Some(dir) = &args.record {
        nodes.push(Planned {
            name: s("recorder"),
            args: vec![
                s("record"),
                robot.clone(),
                s("--output"),
                crate::record::file_in(dir, &robot).display().to_string(),
            ],
        });
    }
    if hardware.is_none() {
        nodes.push(Planned {
            name: s("sim_bridge"),
            args: bridge,
        });
    }
    for arm in &started_arms {
        let mut a = vec![
            s("arm"),
            s(arm),
            s("--robot"),
            robot.clone(),
            s("--morphology"),
            args.morphology.clone(),
        ];
        if let Some(p) = &args.skill {
            a.extend([s("--policy"), p.display().to_string()]);
        }
        if let Some(b) = &args.backend {
            a.extend([s("--backend"), b.clone()]);
        }
        if let Some(p) = &hardware {
            a.extend([s("--hardware"), p.clone()]);
        } else if !args.no_whole_body {
            a.extend([s("--goal-sync-ms"), s(goal_sync_ms(args.lockstep))]);
            if args.lockstep {
                a.push(s("--wait-for-first-goal"));
            }
        }
        nodes.push(Planned {
            name: s(arm),
            args: a,
        });
    }
    if !args.no_whole_body {
        let mut a = vec![
            s("whole-body"),
            s("--robot"),
            robot.clone(),
            s("--morphology"),
            args.morphology.clone(),
        ];
        // A policy trained for a robot kumi does not ship is named: the node looks for the
        // shipped one only.
        let policy = whole_body_policy(&model.name, args);
        if args.policy.is_some() || policy != Variant::Hierarchical.shipped_policy(&model.name) {
            a.extend([s("--policy"), policy.display().to_string()]);
        }
        if let Some(p) = &args.skill {
            a.extend([s("--skill"), p.display().to_string()]);
        }
        if let Some(t) = args.tilt_limit_rad {
            a.extend([s("--tilt-limit-rad"), t.to_string()]);
        }
        if args.lockstep {
            a.push(s("--lockstep"));
        }
        if let Some(p) = &hardware {
            a.extend([s("--hardware"), p.clone()]);
        }
        if let Some(b) = &args.backend {
            a.extend([s("--backend"), b.clone()]);
        }
        nodes.push(Planned {
            name: s("whole_body"),
            args: a,
        });
    }
    Ok(nodes)
}

/// A command line as a shell would take it (arguments with spaces quoted).
fn shell_line(args: &[String]) -> String {
    let quote = |a: &String| {
        if a.is_empty() || a.contains(|c: char| c.is_whitespace() || c == '\'') {
            format!("'{}'", a.replace('\'', "'\\''"))
        } else {
            a.clone()
        }
    };
    std::iter::once("kumi".to_string())
        .chain(args.iter().map(quote))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Makes the child get SIGTERM (a clean stop) when this process dies, however it dies: a
/// launch killed with SIGKILL leaves no nodes behind.
fn die_with_parent(command: &mut Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: prctl(PR_SET_PDEATHSIG) only sets a flag of the calling (child) process; it is
    // async-signal-safe, allocates nothing and touches no state shared with the parent.
    unsafe {
        command.pre_exec(|| {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) == -1 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

/// Running nodes.
pub struct Launch {
    children: Vec<(String, Child)>,
}

impl Launch {
    /// Starts every planned node as a child process of this executable, its output prefixed
    /// with its name on this process's stderr, or appended to `log` when given; on ROS
    /// `domain` when given (else `ROS_DOMAIN_ID` as it is).
    pub fn start(
        nodes: &[Planned],
        domain: Option<u16>,
        log: Option<&std::path::Path>,
    ) -> Result<Self> {
        let log = match log {
            Some(path) => Some(std::sync::Arc::new(std::sync::Mutex::new(
                std::fs::File::create(path)
                    .with_context(|| format!("creating {}", path.display()))?,
            ))),
            None => None,
        };
        let exe = std::env::current_exe().context("finding the kumi executable")?;
        let mut launch = Launch {
            children: Vec::new(),
        };
        for node in nodes {
            let mut command = Command::new(&exe);
            die_with_parent(&mut command);
            if let Some(d) = domain {
                command.env("ROS_DOMAIN_ID", d.to_string());
            }
            let mut child = command
                .args(&node.args)
                .stdin(Stdio::null())
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .with_context(|| format!("starting `{}`", shell_line(&node.args)))?;
            for stream in [
                child
                    .stdout
                    .take()
                    .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
                child
                    .stderr
                    .take()
                    .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
            ]
            .into_iter()
            .flatten()
            {
                let name = node.name.clone();
                let log = log.clone();
                std::thread::spawn(move || {
                    for line in BufReader::new(stream).lines().map_while(|l| l.ok()) {
                        match &log {
                            Some(file) => {
                                use std::io::Write;
                                if let Ok(mut f) = file.lock() {
                                    let _ = writeln!(f, "[{name}] {line}");
                                }
                            }
                            None => eprintln!("[{name}] {line}"),
                        }
                    }
                });
            }
            launch.children.push((node.name.clone(), child));
        }
        Ok(launch)
    }

    /// The first node that has exited, with how.
    pub fn exited(&mut self) -> Option<(String, std::process::ExitStatus)> {
        self.children.iter_mut().find_map(|(name, child)| {
            child
                .try_wait()
                .ok()
                .flatten()
                .map(|status| (name.clone(), status))
        })
    }

    /// Stops every node: SIGINT, then SIGKILL for any still running after `grace`.
    pub fn stop(&mut self, grace: Duration) {
        for (_, child) in &mut self.children {
            if matches!(child.try_wait(), Ok(None)) {
                let _ = Command::new("kill")
                    .args(["-INT", &child.id().to_string()])
                    .status();
            }
        }
        let deadline = Instant::now() + grace;
        for (name, child) in &mut self.children {
            while matches!(child.try_wait(), Ok(None)) && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            if matches!(child.try_wait(), Ok(None)) {
                eprintln!("launch: {name} did not stop within {grace:?}; killing it");
                let _ = child.kill();
                let _ = child.wait();
            }
        }
    }
}

impl Drop for Launch {
    fn drop(&mut self) {
        self.stop(Duration::from_secs(5));
    }
}

/// A robot's Motion Stack profile, checked against its modules.
pub fn load_profile(
    model: &RobotModel,
    path: &std::path::Path,
) -> Result<kumi_ros::motion_stack::MotionStackProfile> {
    let modules: Vec<(String, Vec<String>)> = model
        .modules
        .iter()
        .filter(|m| !m.actuators.is_empty())
        .map(|m| {
            let prefix = format!("{}/", m.name);
            let joints = m
                .actuators
                .iter()
                .map(|a| {
                    a.joint
                        .strip_prefix(&prefix)
                        .unwrap_or(&a.joint)
                        .to_string()
                })
                .collect();
            (m.name.clone(), joints)
        })
        .collect();
    kumi_ros::motion_stack::MotionStackProfile::load(path, &modules).map_err(anyhow::Error::msg)
}

/// The whole-body policy a launch of `robot` runs: `--policy`, else the shipped one, else the
/// one `kumi train whole-body` wrote ([`Variant::default_policy`]).
pub fn whole_body_policy(robot: &str, args: &LaunchArgs) -> PathBuf {
    args.policy
        .clone()
        .unwrap_or_else(|| Variant::Hierarchical.default_policy(robot))
}

/// The whole-body policy to launch with ([`whole_body_policy`]), or an error saying how to get
/// one. `otherwise` is what else the command can do without one (`--no-whole-body` for a
/// launch).
pub fn check_policy(
    model: &kumi_model::RobotModel,
    args: &LaunchArgs,
    otherwise: Option<&str>,
) -> Result<PathBuf> {
    Variant::Hierarchical.require_policy(
        &model.name,
        &args.morphology,
        args.policy.as_deref(),
        otherwise,
    )
}

pub fn run(args: LaunchArgs) -> Result<()> {
    let model = load_model(&args.morphology)?;
    if args.hardware.is_some() {
        if args.lockstep || args.engine.is_some() {
            bail!("--hardware runs no simulator: --lockstep and --engine do not apply");
        }
        load_profile(&model, &profile_path(&args))?;
    }
    let nodes = plan(&model, &args)?;
    if !args.no_whole_body {
        check_policy(&model, &args, Some("launch with --no-whole-body"))?;
    }
    if let Some(dir) = &args.record {
        crate::output::ensure_dir(dir)?;
        let robot = args.robot.as_deref().unwrap_or(&model.name);
        let file = crate::record::file_in(dir, robot);
        if file.exists() {
            bail!(
                "--record {}: {} already exists; remove it or record to another folder",
                dir.display(),
                file.display()
            );
        }
    }
    let domain = std::env::var("ROS_DOMAIN_ID").unwrap_or_else(|_| "0".into());
    eprintln!(
        "launching `{}` on ROS domain {domain}: {} nodes. The same by hand, each in its own terminal:",
        model.name,
        nodes.len()
    );
    for node in &nodes {
        eprintln!("  {}", shell_line(&node.args));
    }
    let shutdown = Arc::new(AtomicBool::new(false));
    let flag = shutdown.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    let mut launch = Launch::start(&nodes, None, None)?;
    let result = loop {
        if shutdown.load(Ordering::Relaxed) {
            eprintln!("launch: stopping every node");
            break Ok(());
        }
        if let Some((name, status)) = launch.exited() {
            eprintln!("launch: node `{name}` exited ({status}); stopping the others");
            break Err(anyhow::anyhow!(
                "node `{name}` exited ({status}); the launch stopped"
            ));
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    launch.stop(Duration::from_secs(5));
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(morphology: &str) -> LaunchArgs {
        LaunchArgs {
            morphology: morphology.into(),
            robot: None,
            lockstep: true,
            engine: None,
            without: Vec::new(),
            no_whole_body: false,
            policy: None,
            tilt_limit_rad: None,
            skill: None,
            backend: None,
            hardware: None,
            profile: None,
            record: None,
        }
    }

    #[test]
    fn one_node_per_arm_module_plus_the_bridge_and_the_whole_body_node() {
        let model = load_model("tricycle").unwrap();
        let nodes = plan(&model, &args("tricycle")).unwrap();
        let names: Vec<&str> = nodes.iter().map(|n| n.name.as_str()).collect();
        let arms = model.modules.iter().filter(|m| m.ee_link.is_some()).count();
        assert_eq!(names.len(), arms + 2, "{names:?}");
        assert_eq!(names[0], "sim_bridge");
        assert_eq!(*names.last().unwrap(), "whole_body");
        assert_eq!(
            shell_line(&nodes[0].args),
            "kumi sim-bridge tricycle --robot tricycle --lockstep --lockstep-timeout 5 --wait-for arm0,leg0,leg1,leg2,wheel0,wheel1,wheel2"
        );
        assert!(nodes[1].args.ends_with(&[
            "--goal-sync-ms".into(),
            "2500".into(),
            "--wait-for-first-goal".into()
        ]));

        let mut without = args("tricycle");
        let left_out = nodes[1].name.clone();
        without.without = vec![left_out.clone()];
        without.robot = Some("second".into());
        without.no_whole_body = true;
        let fewer = plan(&model, &without).unwrap();
        assert_eq!(fewer.len(), arms);
        assert!(fewer
            .iter()
            .all(|n| n.name != left_out && n.args.contains(&"second".to_string())));
        assert!(fewer
            .iter()
            .all(|n| !n.args.contains(&"--goal-sync-ms".to_string())));
        let mut alone = without.clone();
        alone.no_whole_body = false;
        let bridge = &plan(&model, &alone).unwrap()[0];
        let waited: Vec<&str> = ["arm0", "leg0", "leg1", "leg2", "wheel0", "wheel1", "wheel2"]
            .into_iter()
            .filter(|m| *m != left_out)
            .collect();
        assert!(
            bridge
                .args
                .ends_with(&["--wait-for".into(), waited.join(",")]),
            "a module left out is not waited for: {:?}",
            bridge.args
        );

        let mut hw = args("tricycle");
        hw.lockstep = false;
        hw.hardware = Some(Hardware::MotionStack);
        let on_hardware = plan(&model, &hw).unwrap();
        assert_eq!(on_hardware.len(), arms + 1, "no bridge");
        let profile = profile_path(&hw).display().to_string();
        assert!(profile.ends_with("urdf/morphologies/tricycle.motion_stack.toml"));
        assert!(on_hardware
            .iter()
            .all(|n| n.args.ends_with(&["--hardware".into(), profile.clone()])));
        assert!(
            load_profile(&model, &profile_path(&hw)).is_ok(),
            "the shipped example fits"
        );

        let mut unknown = args("tricycle");
        unknown.without = vec!["tail".into()];
        let err = plan(&model, &unknown).unwrap_err().to_string();
        assert!(err.contains("no arm module `tail`"), "{err}");
    }

    #[test]
    fn a_recording_launch_starts_the_recorder_first_into_its_folder() {
        let model = load_model("minimal").unwrap();
        let mut a = args("minimal");
        a.robot = Some("m2".into());
        a.record = Some(PathBuf::from("runs/rec"));
        let nodes = plan(&model, &a).unwrap();
        assert_eq!(nodes[0].name, "recorder");
        assert_eq!(
            shell_line(&nodes[0].args),
            "kumi record m2 --output runs/rec/m2.mcap"
        );
        assert_eq!(
            nodes.len(),
            plan(&model, &args("minimal")).unwrap().len() + 1
        );
    }

    #[test]
    fn command_lines_quote_what_a_shell_would_split() {
        let line = shell_line(&["arm".into(), "my file.onnx".into(), "it's".into()]);
        assert_eq!(line, "kumi arm 'my file.onnx' 'it'\\''s'");
    }
}
