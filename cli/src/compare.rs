//! `kumi report compare`: the paper's comparison (section V-C, Fig. 6, Table VI) reproduced
//! from the shipped policies. Every shipped whole-body policy of each morphology (hierarchical,
//! flat, penalty) is evaluated with the same function as `kumi eval whole-body`; the report
//! puts them side by side with box plots, Table VI, learning curves and the paper's figures.
//!
//! The generator ([`write_report`]) is pure apart from writing its files: it takes finished
//! evaluations and learning curves, so a test can feed it fixtures.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use kumi_train::evaluate_body::BodyEvaluation;

use crate::plot::{box_plot, line_plot, BoxGroup, BoxStats, Series};
use crate::train::Variant;

#[derive(Args, Debug)]
pub struct CompareArgs {
    /// Robots to compare (shipped names).
    #[arg(long, value_delimiter = ',', default_value = "minimal,dragon,tricycle")]
    pub morphologies: Vec<String>,
    /// Episodes per policy and engine.
    #[arg(long, default_value_t = 1000)]
    pub rollouts: usize,
    /// Seed of the episodes (the same for every policy: the same starts and targets).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Physics engines to evaluate in (default: mujoco, the training engine).
    #[arg(long, value_delimiter = ',', value_parser = crate::engine::parse, default_value = "mujoco")]
    pub engine: Vec<kumi_worlds::Engine>,
    /// Inference backend: auto, onnxruntime or tract.
    #[arg(long, default_value = "auto")]
    pub backend: kumi_runtime::BackendChoice,
    /// Where the report (README.md) and its figures go.
    #[arg(long, default_value = "reports/compare")]
    pub out: PathBuf,
    /// Where the learning curves are: `DIR/<policy name>/metrics.csv`, as the shipped policies'
    /// folders hold them and as training writes them (`--curves runs` reads
    /// `runs/minimal_flat/metrics.csv`).
    #[arg(long, default_value = "policies")]
    pub curves: PathBuf,
}

/// The variants compared, in the order of every table and legend.
pub const VARIANTS: [Variant; 3] = [Variant::Hierarchical, Variant::Flat, Variant::Penalty];
/// One colour per variant, in `VARIANTS`' order.
const COLOURS: [&str; 3] = [
    crate::plot::SERIES[0],
    crate::plot::SERIES[1],
    crate::plot::SERIES[2],
];

/// One policy's evaluation in one engine.
#[derive(Debug, Clone)]
pub struct Entry {
    pub robot: String,
    pub variant: Variant,
    /// Environment steps it was trained for.
    pub steps: String,
    pub evaluation: BodyEvaluation,
}

/// A training run's learning curve: per iteration, env steps, mean reward per step and the
/// final position error of the episodes that ended in it.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    pub robot: String,
    pub variant: Variant,
    pub env_steps: Vec<f64>,
    pub mean_step_reward: Vec<f64>,
    pub final_position_error_m: Vec<f64>,
}

/// What the report says about how it was made.
#[derive(Debug, Clone)]
pub struct Settings {
    pub rollouts: usize,
    pub seed: u64,
    pub engines: Vec<String>,
    pub backend: String,
    pub command: String,
}

pub fn run(args: CompareArgs) -> Result<()> {
    anyhow::ensure!(args.rollouts > 0, "--rollouts must be positive");
    crate::output::ensure_dir(&args.out)?;
    let mut entries = Vec::new();
    let mut curves = Vec::new();
    for robot in &args.morphologies {
        for variant in VARIANTS {
            let policy = variant.shipped_policy(robot);
            if !policy.exists() {
                eprintln!(
                    "{robot} {variant}: no shipped policy ({}), left out",
                    policy.display()
                );
                continue;
            }
            let results = crate::eval::evaluate_whole_body(&eval_args(&args, robot, variant))
                .with_context(|| format!("evaluating the {variant} policy of {robot}"))?;
            for evaluation in results.evaluations {
                entries.push(Entry {
                    robot: robot.clone(),
                    variant,
                    steps: results.steps.clone(),
                    evaluation,
                });
            }
            let csv = args
                .curves
                .join(variant.policy_name(robot))
                .join("metrics.csv");
            match std::fs::read_to_string(&csv) {
                Ok(text) => curves.push(
                    read_curve(robot, variant, &text)
                        .with_context(|| format!("reading {}", csv.display()))?,
                ),
                Err(_) => eprintln!("{robot} {variant}: no learning curve at {}", csv.display()),
            }
        }
    }
    let settings =
        Settings {
            rollouts: args.rollouts,
            seed: args.seed,
            engines: args.engine.iter().map(|e| e.to_string()).collect(),
            backend: args.backend.resolve().to_string(),
            command: format!(
            "kumi report compare --morphologies {} --rollouts {} --seed {} --engine {} --out {}",
            args.morphologies.join(","),
            args.rollouts,
            args.seed,
            args.engine.iter().map(|e| e.to_string()).collect::<Vec<_>>().join(","),
            args.out.display()
        ),
        };
    let files = write_report(&args.out, &args.morphologies, &entries, &curves, &settings)?;
    for file in files {
        println!("{}", file.display());
    }
    Ok(())
}

/// Parses a metrics CSV by its header's column names.
pub fn read_curve(robot: &str, variant: Variant, text: &str) -> Result<Curve> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().context("empty file")?.split(',').collect();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .with_context(|| format!("no column `{name}`"))
    };
    let (steps, reward, error) = (
        column("env_steps")?,
        column("mean_step_reward")?,
        column("final_position_error_m")?,
    );
    let mut curve = Curve {
        robot: robot.to_string(),
        variant,
        env_steps: Vec::new(),
        mean_step_reward: Vec::new(),
        final_position_error_m: Vec::new(),
    };
    for (i, line) in lines.enumerate().filter(|(_, l)| !l.is_empty()) {
        let fields: Vec<&str> = line.split(',').collect();
        let value = |k: usize| -> Result<f64> {
            let text = fields
                .get(k)
                .with_context(|| format!("row {}: too short", i + 2))?;
            text.parse()
                .with_context(|| format!("row {}: `{text}` is not a number", i + 2))
        };
        curve.env_steps.push(value(steps)?);
        curve.mean_step_reward.push(value(reward)?);
        curve.final_position_error_m.push(value(error)?);
    }
    Ok(curve)
}

/// The evaluation of one shipped policy, as the comparison runs it: the paper's task, no
/// pushes, no noise, no files.
fn eval_args(args: &CompareArgs, robot: &str, variant: Variant) -> crate::eval::EvalBodyArgs {
    crate::eval::EvalBodyArgs {
        morphology: robot.to_string(),
        variant,
        policy: None,
        config: None,
        skill: None,
        rollouts: args.rollouts,
        seed: args.seed,
        backend: args.backend,
        engine: args.engine.clone(),
        json: false,
        episodes: None,
        trace: None,
        trace_plot: None,
        traced: 0,
        action_noise: 0.0,
        push_m_s: 0.0,
        push_tip_rad_s: 0.0,
        push_interval_s: Vec::new(),
    }
}

/// Writes `README.md` and its figures into `out`; returns the files written.
pub fn write_report(
    out: &Path,
    robots: &[String],
    entries: &[Entry],
    curves: &[Curve],
    settings: &Settings,
) -> Result<Vec<PathBuf>> {
    crate::output::ensure_dir(out)?;
    let mut files = Vec::new();
    let mut figures = Vec::new();
    for engine in &settings.engines {
        for (what, label, pick) in ERROR_FIGURES {
            let name = format!("{what}_{engine}.svg");
            let svg = error_boxes(robots, entries, engine, label, pick);
            files.push(write(out, &name, &svg)?);
            figures.push((format!("{label}, {engine}"), name));
        }
    }
    for robot in robots {
        let of_robot: Vec<&Curve> = curves.iter().filter(|c| &c.robot == robot).collect();
        if of_robot.is_empty() {
            continue;
        }
        for (what, label, pick) in CURVE_FIGURES {
            let name = format!("learning_{robot}_{what}.svg");
            let svg = learning_plot(robot, &of_robot, label, pick);
            files.push(write(out, &name, &svg)?);
            figures.push((format!("{robot}: {label} while training"), name));
        }
    }
    let text = markdown(robots, entries, curves, settings, &figures);
    files.insert(0, write(out, "README.md", &text)?);
    Ok(files)
}

fn write(out: &Path, name: &str, text: &str) -> Result<PathBuf> {
    let path = out.join(name);
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

type Pick = fn(&kumi_train::evaluate_body::Episode) -> f64;
type CurvePick = fn(&Curve) -> &[f64];

const ERROR_FIGURES: [(&str, &str, Pick); 2] = [
    ("position_error", "final position error [m]", |e| e.position),
    ("yaw_error", "final yaw error [rad]", |e| e.yaw),
];

const CURVE_FIGURES: [(&str, &str, CurvePick); 2] = [
    ("reward", "mean reward per step", |c| &c.mean_step_reward),
    ("position_error", "final position error [m]", |c| {
        &c.final_position_error_m
    }),
];

fn series() -> Vec<Series> {
    VARIANTS
        .iter()
        .zip(COLOURS)
        .map(|(v, colour)| Series {
            label: v.to_string(),
            colour,
        })
        .collect()
}

/// Fig. 6: per robot a box per variant of one final error over the episodes that did not
/// fall.
fn error_boxes(
    robots: &[String],
    entries: &[Entry],
    engine: &str,
    label: &str,
    pick: Pick,
) -> String {
    let groups: Vec<BoxGroup> = robots
        .iter()
        .map(|robot| BoxGroup {
            label: robot.clone(),
            boxes: VARIANTS
                .iter()
                .map(|&v| {
                    find(entries, robot, v, engine).and_then(|e| {
                        let values: Vec<f64> = e
                            .evaluation
                            .episodes
                            .iter()
                            .filter(|ep| !ep.terminated)
                            .map(pick)
                            .collect();
                        BoxStats::of(&values)
                    })
                })
                .collect(),
        })
        .collect();
    box_plot(
        &format!("{label} at the episode's end ({engine}; whiskers 5-95 %, dot: mean)"),
        label,
        &series(),
        &groups,
    )
}

fn learning_plot(robot: &str, curves: &[&Curve], label: &str, pick: CurvePick) -> String {
    let lines: Vec<(Series, Vec<[f64; 2]>)> = curves
        .iter()
        .map(|c| {
            let i = VARIANTS.iter().position(|v| *v == c.variant).unwrap_or(0);
            (
                Series {
                    label: c.variant.to_string(),
                    colour: COLOURS[i],
                },
                smooth(&c.env_steps, pick(c)),
            )
        })
        .collect();
    // The first tenth of training (errors of metres, rewards near zero) would squash the rest.
    let x_max = lines
        .iter()
        .flat_map(|(_, p)| p.iter().map(|p| p[0]))
        .fold(0.0, f64::max);
    let y_max = lines
        .iter()
        .flat_map(|(_, p)| p.iter())
        .filter(|p| p[0] >= 0.1 * x_max)
        .map(|p| p[1])
        .fold(0.0, f64::max)
        * 1.1;
    line_plot(
        &format!("{robot}: {label} (10-iteration means; y axis fitted from 10 % of training on)"),
        "environment steps",
        label,
        &lines,
        (y_max > 0.0).then_some(y_max),
    )
}

/// Points averaged over windows of 10 iterations (NaN values, iterations without a finished
/// episode, skipped), so that the curves are readable.
fn smooth(x: &[f64], y: &[f64]) -> Vec<[f64; 2]> {
    x.chunks(10)
        .zip(y.chunks(10))
        .filter_map(|(xs, ys)| {
            let finite: Vec<f64> = ys.iter().copied().filter(|v| v.is_finite()).collect();
            (!finite.is_empty()).then(|| {
                [
                    *xs.last().expect("chunks are not empty"),
                    finite.iter().sum::<f64>() / finite.len() as f64,
                ]
            })
        })
        .collect()
}

fn find<'a>(
    entries: &'a [Entry],
    robot: &str,
    variant: Variant,
    engine: &str,
) -> Option<&'a Entry> {
    entries
        .iter()
        .find(|e| e.robot == robot && e.variant == variant && e.evaluation.engine == engine)
}

/// `mean ± std` with 3 decimals, or `-` when missing.
fn pm(s: &kumi_train::evaluate::ErrorStats) -> String {
    if s.mean.is_finite() {
        format!("{:.3} ± {:.3}", s.mean, s.std)
    } else {
        "-".into()
    }
}

fn markdown(
    robots: &[String],
    entries: &[Entry],
    curves: &[Curve],
    settings: &Settings,
    figures: &[(String, String)],
) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# Hierarchical against flat: the paper's comparison, reproduced\n\nGenerated by `{}` from the shipped policies in `policies/`. Each policy ran {} episodes (seed {}, the same starts and targets for every policy) in {} with the {} backend; errors are taken at the end of the 12 s episode over the episodes that did not fall, as in `kumi eval whole-body <robot> --variant <v> --rollouts {} --seed {} --json`, which prints the same numbers.\n",
        settings.command,
        settings.rollouts,
        settings.seed,
        settings.engines.join(" and "),
        settings.backend,
        settings.rollouts,
        settings.seed,
    );
    summary_table(&mut md, robots, entries, settings);
    table_vi(&mut md, entries, settings);
    directions(&mut md, robots, entries, settings);
    let _ = writeln!(md, "## Figures\n");
    for (caption, file) in figures {
        let _ = writeln!(md, "**{caption}**\n\n![{caption}]({file})\n");
    }
    if curves.is_empty() {
        let _ = writeln!(md, "No learning curves were found.\n");
    }
    md
}

fn summary_table(md: &mut String, robots: &[String], entries: &[Entry], settings: &Settings) {
    let _ = writeln!(
        md,
        "## Every policy\n\n| robot | policy | engine | trained steps | position [m] mean ± std | median | p90 | yaw [rad] mean ± std | median | terminations | contacts [steps/episode] |\n|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for robot in robots {
        for engine in &settings.engines {
            for variant in VARIANTS {
                let Some(e) = find(entries, robot, variant, engine) else {
                    if variant != Variant::Penalty || robot == "tricycle" {
                        let _ = writeln!(
                            md,
                            "| {robot} | {variant} | {engine} | not shipped | | | | | | | |"
                        );
                    }
                    continue;
                };
                let ev = &e.evaluation;
                let _ = writeln!(
                    md,
                    "| {robot} | {variant} | {engine} | {} | {} | {:.3} | {:.3} | {} | {:.3} | {} of {} | {:.1} |",
                    e.steps,
                    pm(&ev.position_error_m),
                    ev.position_error_m.median,
                    ev.position_error_m.p90,
                    pm(&ev.yaw_error_rad),
                    ev.yaw_error_rad.median,
                    ev.terminations,
                    ev.rollouts,
                    ev.contacts_per_episode.mean,
                );
            }
        }
    }
    md.push('\n');
}

/// The paper's Table VI (Tricycle): hierarchical against penalty, mean ± std.
const PAPER_TABLE_VI: [(&str, &str, &str); 5] = [
    ("position [m]", "0.17 ± 0.18", "0.08 ± 0.18"),
    ("orientation [rad]", "0.31 ± 0.03", "0.38 ± 0.29"),
    ("leg tool orientation [rad]", "0.44 ± 0.24", "0.62 ± 0.37"),
    (
        "contact count [steps/episode]",
        "117.14 ± 88.95",
        "194.18 ± 121.13",
    ),
    ("terminations (of 1000)", "2.80 ± 1.54", "6.00 ± 2.79"),
];

fn table_vi(md: &mut String, entries: &[Entry], settings: &Settings) {
    for engine in &settings.engines {
        let cells = |v: Variant| -> [String; 5] {
            match find(entries, "tricycle", v, engine) {
                Some(e) => {
                    let ev = &e.evaluation;
                    [
                        pm(&ev.position_error_m),
                        pm(&ev.yaw_error_rad),
                        pm(&ev.leg_orientation_rad),
                        pm(&ev.contacts_per_episode),
                        terminations_cell(ev),
                    ]
                }
                None => std::array::from_fn(|_| "not shipped".to_string()),
            }
        };
        let (h, p) = (cells(Variant::Hierarchical), cells(Variant::Penalty));
        let _ = writeln!(
            md,
            "## Table VI: Tricycle, hierarchical against penalty ({engine})\n\n| metric | kumi hierarchical | kumi penalty | paper hierarchical | paper penalty |\n|---|---|---|---|---|"
        );
        for (i, (metric, paper_h, paper_p)) in PAPER_TABLE_VI.iter().enumerate() {
            let _ = writeln!(
                md,
                "| {metric} | {} | {} | {paper_h} | {paper_p} |",
                h[i], p[i]
            );
        }
        let _ = writeln!(
            md,
            "\nThe paper reports terminations as mean ± std over seeds; kumi counts them in its {} episodes of one seed, with the 95 % Wilson interval of the rate per 1000.\n",
            settings.rollouts
        );
    }
}

/// Table VI's terminations: the count, and the 95 % Wilson interval of the rate per 1000, which
/// says whether a count such as 8 of 1000 stands apart from the paper's 2.8.
fn terminations_cell(ev: &BodyEvaluation) -> String {
    let count = format!("{} of {}", ev.terminations, ev.rollouts);
    match BodyEvaluation::terminations_per_1000_95(ev.terminations, ev.rollouts) {
        Some([lo, hi]) => format!("{count} (95 %: {lo:.1}-{hi:.1} per 1000)"),
        None => count,
    }
}

/// The paper's claim per robot (section V-C), and whether kumi's numbers show it.
fn directions(md: &mut String, robots: &[String], entries: &[Entry], settings: &Settings) {
    let _ = writeln!(md, "## Does kumi reproduce the paper's direction?\n");
    for engine in &settings.engines {
        for robot in robots {
            let mean = |v: Variant, f: fn(&BodyEvaluation) -> f64| {
                find(entries, robot, v, engine).map(|e| f(&e.evaluation))
            };
            let pos = |e: &BodyEvaluation| e.position_error_m.mean;
            let yaw = |e: &BodyEvaluation| e.yaw_error_rad.mean;
            let (claim, verdict) = direction(
                robot,
                [
                    mean(Variant::Hierarchical, pos),
                    mean(Variant::Flat, pos),
                    mean(Variant::Penalty, pos),
                ],
                [
                    mean(Variant::Hierarchical, yaw),
                    mean(Variant::Flat, yaw),
                    mean(Variant::Penalty, yaw),
                ],
            );
            let _ = writeln!(
                md,
                "- **{robot}** ({engine}). The paper: {claim}. kumi: {verdict}"
            );
        }
    }
    md.push('\n');
}

/// Comparable: within this factor of each other.
const COMPARABLE: f64 = 1.25;
/// Clearly worse: more than this factor.
const CLEARLY_WORSE: f64 = 1.5;
/// A yaw error [rad] this large is no better than a random heading (mean pi/2).
const YAW_NOT_LEARNT_RAD: f64 = 1.2;

/// How `a` compares with `b` (errors: smaller is better).
fn compare_errors(a: f64, b: f64) -> &'static str {
    if a * COMPARABLE < b {
        "better"
    } else if a <= b * COMPARABLE {
        "comparable"
    } else if a <= b * CLEARLY_WORSE {
        "worse"
    } else {
        "clearly worse"
    }
}

/// `position flat 0.030 against hierarchical 0.085 (better)`, noting a yaw neither policy
/// learnt.
fn versus(what: &str, flat: f64, hierarchical: f64) -> String {
    let mut text = format!(
        "{what} flat {flat:.3} against hierarchical {hierarchical:.3} ({})",
        compare_errors(flat, hierarchical)
    );
    if what == "yaw" && flat > YAW_NOT_LEARNT_RAD && hierarchical > YAW_NOT_LEARNT_RAD {
        text.push_str(", learnt by neither: a random heading gives 1.57");
    }
    text
}

/// The paper's claim for `robot` and kumi's verdict from the mean errors of the hierarchical,
/// flat and penalty policies (position [m], yaw [rad]; none where not shipped). Comparable
/// means within 25 % of each other; clearly worse more than 1.5 times.
pub fn direction(
    robot: &str,
    position: [Option<f64>; 3],
    yaw: [Option<f64>; 3],
) -> (String, String) {
    let claim = match robot {
        "minimal" => "flat comparable to hierarchical, slightly better",
        "dragon" => "comparable in position, hierarchical substantially better in orientation",
        "tricycle" => "flat degrades markedly; the penalty baseline closes much of the gap",
        other => return (format!("no claim for `{other}`"), "-".into()),
    }
    .to_string();
    let (Some(h), Some(f)) = (position[0], position[1]) else {
        let missing = if position[0].is_none() {
            "hierarchical"
        } else {
            "flat"
        };
        return (
            claim,
            format!("not measured: the {missing} policy is not shipped."),
        );
    };
    let (hy, fy) = (yaw[0].unwrap_or(f64::NAN), yaw[1].unwrap_or(f64::NAN));
    let measured = format!("{}; {}", versus("position", f, h), versus("yaw", fy, hy));
    let (reproduced, why) = match robot {
        "minimal" => (
            f <= h * COMPARABLE && fy <= hy * COMPARABLE,
            "flat is worse than comparable",
        ),
        "dragon" => (
            hy * COMPARABLE < fy && f <= h * COMPARABLE && h <= f * COMPARABLE,
            "position is not comparable, or hierarchical is not better in yaw",
        ),
        _ => (
            f > h * CLEARLY_WORSE,
            "flat is not clearly worse in position",
        ),
    };
    let mut verdict = format!(
        "{measured} → {}.",
        if reproduced {
            "reproduced".to_string()
        } else {
            format!("not reproduced: {why}")
        }
    );
    if let (Some(p), "tricycle") = (position[2], robot) {
        verdict.push_str(&format!(
            " Penalty {p:.3} m: {}.",
            if p < f {
                "closer than flat"
            } else {
                "no better than flat"
            }
        ));
    }
    (claim, verdict)
}

#[cfg(test)]
mod tests {
    use super::*;
    use kumi_train::evaluate::ErrorStats;
    use kumi_train::evaluate_body::Episode;

    #[test]
    fn the_comparisons_evaluations_pass_the_evaluation_checks() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: CompareArgs,
        }
        let cli = <Cli as clap::Parser>::try_parse_from(["kumi"]).unwrap();
        for robot in &cli.args.morphologies {
            for variant in VARIANTS {
                let eval = eval_args(&cli.args, robot, variant);
                // No pushes, and none asked for: no interval needed (an interval checked
                // without pushes would refuse every comparison).
                assert!(eval.push().unwrap().is_none(), "{robot} {variant}");
            }
        }
    }

    /// A fake evaluation whose episodes end at these position errors (yaw twice as large).
    fn fake(robot: &str, variant: Variant, positions: &[f64]) -> Entry {
        let episodes: Vec<Episode> = positions
            .iter()
            .map(|&p| Episode {
                position: p,
                yaw: 2.0 * p,
                leg: f64::NAN,
                contacts: 3,
                terminated: false,
                diverged: false,
                start_position: 2.0,
                closest_position: p,
                steps: 360,
                target: kumi_terms::observation::Target {
                    position_w: nalgebra::Vector3::zeros(),
                    yaw: 0.0,
                },
                trace: Vec::new(),
            })
            .collect();
        let stats =
            |f: fn(&Episode) -> f64| ErrorStats::of(&episodes.iter().map(f).collect::<Vec<_>>());
        Entry {
            robot: robot.into(),
            variant,
            steps: "4096".into(),
            evaluation: BodyEvaluation {
                robot: robot.into(),
                engine: "mujoco".into(),
                rollouts: positions.len(),
                position_error_m: stats(|e| e.position),
                yaw_error_rad: stats(|e| e.yaw),
                leg_orientation_rad: stats(|e| e.leg),
                contacts_per_episode: stats(|e| e.contacts as f64),
                terminations: 0,
                diverged: 0,
                terminations_per_1000_95: BodyEvaluation::terminations_per_1000_95(
                    0,
                    positions.len(),
                ),
                action_noise: 0.0,
                push: None,
                episodes,
                action_names: Vec::new(),
            },
        }
    }

    #[test]
    fn table_vi_gives_the_terminations_with_their_interval() {
        let mut ev = fake("tricycle", Variant::Hierarchical, &[0.1, 0.2]).evaluation;
        (ev.terminations, ev.rollouts) = (8, 1000);
        assert_eq!(
            terminations_cell(&ev),
            "8 of 1000 (95 %: 4.1-15.7 per 1000)"
        );
        ev.rollouts = 0;
        assert_eq!(terminations_cell(&ev), "8 of 0");
    }

    #[test]
    fn the_report_of_two_fake_evaluations_has_its_tables_and_figures() {
        let out = std::env::temp_dir().join(format!("kumi-compare-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let entries = [
            fake("minimal", Variant::Hierarchical, &[0.1, 0.2, 0.3]),
            fake("minimal", Variant::Flat, &[0.05, 0.1, 0.15]),
        ];
        let curve = read_curve(
            "minimal",
            Variant::Flat,
            "iteration,env_steps,mean_step_reward,final_position_error_m,wall_s\n1,4096,0.1,NaN,1\n2,8192,0.3,0.9,2\n",
        )
        .unwrap();
        assert_eq!(curve.env_steps, [4096.0, 8192.0]);
        assert!(curve.final_position_error_m[0].is_nan());
        let settings = Settings {
            rollouts: 3,
            seed: 1,
            engines: vec!["mujoco".into()],
            backend: "tract".into(),
            command: "kumi report compare".into(),
        };
        let robots = ["minimal".to_string(), "tricycle".to_string()];
        let files = write_report(&out, &robots, &entries, &[curve], &settings).unwrap();
        let names: Vec<String> = files
            .iter()
            .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            names,
            [
                "README.md",
                "position_error_mujoco.svg",
                "yaw_error_mujoco.svg",
                "learning_minimal_reward.svg",
                "learning_minimal_position_error.svg"
            ]
        );
        for file in &files {
            assert!(
                std::fs::metadata(file).unwrap().len() > 200,
                "{}",
                file.display()
            );
        }
        let md = std::fs::read_to_string(&files[0]).unwrap();
        // Mean ± population std of 0.1, 0.2, 0.3 and of 0.05, 0.1, 0.15.
        assert!(md.contains("| minimal | hierarchical | mujoco | 4096 | 0.200 ± 0.082 | 0.200 | 0.300 | 0.400 ± 0.163 |"), "{md}");
        assert!(
            md.contains("| minimal | flat | mujoco | 4096 | 0.100 ± 0.041 |"),
            "{md}"
        );
        assert!(
            md.contains("| tricycle | hierarchical | mujoco | not shipped |"),
            "{md}"
        );
        assert!(
            md.contains("| position [m] | not shipped | not shipped | 0.17 ± 0.18 | 0.08 ± 0.18 |"),
            "{md}"
        );
        assert!(md.contains("**minimal** (mujoco). The paper: flat comparable to hierarchical, slightly better. kumi: position flat 0.100 against hierarchical 0.200 (better); yaw flat 0.200 against hierarchical 0.400 (better) → reproduced."), "{md}");
        assert!(
            md.contains("**tricycle** (mujoco)") && md.contains("not measured"),
            "{md}"
        );
        // Two boxes in the position figure: minimal's hierarchical and flat, none for tricycle.
        let svg = std::fs::read_to_string(out.join("position_error_mujoco.svg")).unwrap();
        assert_eq!(svg.matches("fill-opacity").count(), 2);
        std::fs::remove_dir_all(&out).unwrap();
    }

    #[test]
    fn directions_follow_the_numbers() {
        let some = |a: f64, b: f64, c: Option<f64>| [Some(a), Some(b), c];
        let (_, v) = direction("minimal", some(0.1, 0.2, None), some(0.3, 0.3, None));
        assert!(
            v.ends_with("not reproduced: flat is worse than comparable."),
            "{v}"
        );
        assert!(
            v.contains("position flat 0.200 against hierarchical 0.100 (clearly worse)"),
            "{v}"
        );
        let (_, v) = direction("minimal", some(0.1, 0.03, None), some(1.4, 1.5, None));
        assert!(
            v.contains("learnt by neither") && v.ends_with("→ reproduced."),
            "{v}"
        );
        let (_, v) = direction("dragon", some(0.2, 0.2, None), some(0.3, 0.9, None));
        assert!(v.ends_with("→ reproduced."), "{v}");
        let (_, v) = direction("tricycle", some(0.2, 0.5, Some(0.3)), some(0.3, 0.9, None));
        assert!(
            v.contains("→ reproduced.") && v.contains("closer than flat"),
            "{v}"
        );
        let (_, v) = direction("tricycle", [None, Some(0.5), None], [None; 3]);
        assert!(v.contains("hierarchical policy is not shipped"), "{v}");
    }
}
