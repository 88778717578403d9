//! The `kumi` command end to end: what a user types, and what scripts parse.

use std::process::{Command, Output};

fn kumi(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_kumi"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("kumi runs")
}

/// Runs `kumi`, which must succeed (its stderr is the failure message).
fn kumi_ok(args: &[&str]) -> Output {
    let out = kumi(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `kumi train whole-body minimal` for 4096 steps into `out_dir`, with `extra` arguments; it
/// must succeed. Returns its progress output (stderr).
fn train_minimal_briefly(out_dir: &std::path::Path, extra: &[&str]) -> String {
    let out_dir = out_dir.to_str().unwrap();
    let mut args = vec![
        "train",
        "whole-body",
        "minimal",
        "--steps",
        "4096",
        "--out",
        out_dir,
    ];
    args.extend_from_slice(extra);
    String::from_utf8_lossy(&kumi_ok(&args).stderr).into_owned()
}

/// A fresh folder `kumi-train-{tag}-PID` under the temp dir, holding `{tag}.toml`: Minimal's
/// shipped whole-body config with `extra` appended. Returns the folder and the config's path.
fn minimal_config_with(tag: &str, extra: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let text = std::fs::read_to_string(root.join("train/configs/whole_body/minimal.toml")).unwrap();
    let out_dir = std::env::temp_dir().join(format!("kumi-train-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&out_dir).unwrap();
    let config = out_dir.join(format!("{tag}.toml"));
    std::fs::write(&config, format!("{text}\n{extra}")).unwrap();
    (out_dir, config)
}

/// Runs `kumi`, which must succeed, and parses its stdout as JSON.
fn kumi_json<T: serde::de::DeserializeOwned>(args: &[&str]) -> T {
    serde_json::from_slice(&kumi_ok(args).stdout).unwrap()
}

#[test]
fn urdf_prints_a_complete_robot() {
    let out = kumi(&["urdf", "tricycle"]);
    assert!(out.status.success());
    let xml = String::from_utf8(out.stdout).unwrap();
    assert!(xml.starts_with("<?xml"));
    assert!(xml.contains(r#"<joint name="leg2/joint7" type="revolute">"#));
    assert!(xml.contains(r#"<link name="wheel1/wheel_left">"#));
}

#[test]
fn a_bad_morphology_file_is_one_clear_line_and_a_failure_code() {
    let path = std::env::temp_dir().join(format!("kumi-cli-bad-{}.toml", std::process::id()));
    std::fs::write(
        &path,
        "name = \"x\"\n[[module]]\nname = \"w\"\nkind = \"wheel\"\nrole = \"whel\"\n",
    )
    .unwrap();
    let out = kumi(&["urdf", path.to_str().unwrap()]);
    std::fs::remove_file(&path).unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(
        err.trim(),
        format!(
            "error: {}: module[0].role: unknown role `whel` (allowed here: wheel)",
            path.display()
        )
    );
}

#[test]
fn sim_reports_json() {
    let report: serde_json::Value = kumi_json(&["sim", "dragon", "--seconds", "2", "--json"]);
    assert_eq!(report["morphology"], "dragon");
    assert_eq!(report["control_steps"], 60);
    assert_eq!(report["finite"], true);
    assert!(report["max_tilt_rad"].as_f64().unwrap() < 0.1);
}

#[test]
fn sim_runs_arm_modules_on_the_skill_and_names_them() {
    // Dragon's two arm modules on the shipped skill, toward their home tool poses: it stays up.
    let report: serde_json::Value = kumi_json(&[
        "sim",
        "dragon",
        "--seconds",
        "2",
        "--skill-on",
        "all",
        "--json",
    ]);
    assert_eq!(report["skill_on"], serde_json::json!(["arm0", "leg0"]));
    assert_eq!(report["finite"], true);
    assert!(report["max_tilt_rad"].as_f64().unwrap() < 0.3, "{report}");
    // A module that is not an arm is refused by name.
    let out = kumi(&[
        "sim",
        "dragon",
        "--seconds",
        "1",
        "--skill-on",
        "rear_wheel",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr)
        .contains("--skill-on: `rear_wheel` is not an arm module of dragon"));
}

#[test]
fn tricycle_rolls_its_legs_through_the_whole_policy_range_standing() {
    // The whole-body policy rolls each leg's tool up to +-1.5 rad about its x axis to steer the
    // wheel modules (train/configs/whole_body/tricycle.toml). The legs' home tip rolls must leave
    // joint7 room for that: from the first home (leg1 and leg2 at +-120 deg) the skill swung
    // joint7 the long way round and the robot tipped over (urdf/morphologies/tricycle.toml).
    for roll in ["--leg-roll=1.5", "--leg-roll=-1.5"] {
        let report: serde_json::Value = kumi_json(&[
            "sim",
            "tricycle",
            "--seconds",
            "8",
            "--skill-on",
            "all",
            roll,
            "--json",
        ]);
        assert!(
            report["max_tilt_rad"].as_f64().unwrap() < 0.3,
            "{roll}: {report}"
        );
        let legs = report["skill_tracking"].as_array().unwrap();
        assert_eq!(legs.len(), 4, "{report}");
        for t in legs {
            // Measured 0.04-0.15 rad; the skill's own orientation error is about 0.1 rad.
            let error = t["orientation_error_rad"].as_f64().unwrap();
            assert!(error < 0.25, "{roll}: {t}");
        }
    }
    let out = kumi(&["sim", "tricycle", "--skill-on", "all", "--leg-roll=4"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr)
        .contains("--leg-roll must be an angle in [-pi, pi] rad, got 4"));
}

#[test]
fn sim_refuses_a_nonsense_duration() {
    let out = kumi(&["sim", "arm", "--seconds=-3"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--seconds must be a positive number"));
}

#[test]
fn bench_sim_json_has_the_documented_records() {
    let records: Vec<serde_json::Value> = kumi_json(&[
        "bench",
        "sim",
        "--json",
        "--models",
        "arm",
        "--seconds",
        "0.5",
        "--worlds",
        "2",
    ]);
    assert_eq!(
        records.len(),
        2,
        "one single-thread and one parallel record"
    );
    for r in &records {
        for key in [
            "model",
            "config",
            "threads",
            "worlds",
            "control_steps_per_s",
            "build_ms",
            "reset_us",
        ] {
            assert!(r.get(key).is_some(), "record lacks {key}: {r}");
        }
        assert!(r["control_steps_per_s"].as_f64().unwrap() > 0.0);
    }
    assert_eq!(records[1]["worlds"], 2);
}

#[test]
fn train_arm_runs_the_shipped_config_and_writes_metrics() {
    let out_dir = std::env::temp_dir().join(format!("kumi-train-{}", std::process::id()));
    let out = kumi_ok(&[
        "train",
        "arm",
        "--steps",
        "4096",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    let csv = std::fs::read_to_string(out_dir.join("metrics.csv")).unwrap();
    assert!(out_dir.join("checkpoint/params.safetensors").exists());
    let onnx = std::fs::read(out_dir.join("arm_reach.onnx")).unwrap();
    assert!(
        onnx.len() > 100_000,
        "a 21-256-128-7 actor is about 160 kB of weights"
    );
    // Resuming continues the step count.
    kumi_ok(&[
        "train",
        "arm",
        "--steps",
        "8192",
        "--resume",
        out_dir.join("checkpoint").to_str().unwrap(),
        "--out",
        out_dir.join("more").to_str().unwrap(),
    ]);
    let more = std::fs::read_to_string(out_dir.join("more/metrics.csv")).unwrap();
    assert!(
        more.lines().nth(1).unwrap().starts_with("2,8192,"),
        "{more}"
    );
    std::fs::remove_dir_all(&out_dir).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 2, "a header and one iteration: {csv}");
    assert!(lines[0].starts_with(
        "iteration,env_steps,collect_steps_per_s,update_samples_per_s,mean_step_reward"
    ));
    assert!(lines[1].starts_with("1,4096,"), "{}", lines[1]);
    let progress = String::from_utf8_lossy(&out.stderr);
    assert!(
        progress.contains("steps/s collect") && progress.contains("final_position_error_m"),
        "{progress}"
    );
    // Training says which engine it uses: MuJoCo where the build has it.
    let engine = if cfg!(feature = "mujoco") {
        "training on the mujoco engine"
    } else {
        "training on the rapier engine"
    };
    assert!(progress.contains(engine), "{progress}");
}

#[test]
fn a_misspelt_noise_slot_is_refused_by_name_before_training() {
    let (out_dir, config) =
        minimal_config_with("noise", "[observation_noise]\nprojected_gravty = 0.01\n");
    let out = kumi(&[
        "train",
        "whole-body",
        "minimal",
        "--config",
        config.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("`projected_gravty`") && stderr.contains("projected_gravity,"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!out_dir.join("checkpoint").exists(), "nothing was trained");
    std::fs::remove_dir_all(&out_dir).unwrap();
}

#[test]
fn a_critic_that_sees_more_trains_and_exports_a_policy_of_the_policys_observation() {
    // [critic]: the value function reads the robot's state beyond Table III in training, and
    // [observation_noise] noises the policy's observation, not those extras. The exported
    // policy takes the 19 values of Minimal's observation, as the node and eval build them,
    // and evaluates against the same config.
    let (out_dir, config) = minimal_config_with(
        "critic",
        "[critic]\nbase_height = true\nwheel_modules_off_ground = true\n\n\
         [observation_noise]\nprojected_gravity = 0.01\n",
    );
    let progress = train_minimal_briefly(&out_dir, &["--config", config.to_str().unwrap()]);
    assert!(
        progress.contains("training noises the observation")
            && progress.contains("{\"projected_gravity\":0.01}"),
        "{progress}"
    );
    // The base's height and the wheel modules off the ground: two values more for the critic,
    // normalised with the rest in training; the policy file takes the 19 alone (eval checks
    // its input's width against Minimal's observation).
    assert!(
        progress.contains("19 observations, 7 actions")
            && progress.contains("the critic also sees 2 values"),
        "{progress}"
    );
    let progress_json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out_dir.join("checkpoint/progress.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(
        progress_json["normalizer"]["mean"].as_array().map(Vec::len),
        Some(21)
    );
    let policy = out_dir.join("minimal_whole_body.onnx");
    let v: serde_json::Value = kumi_json(&[
        "eval",
        "whole-body",
        "minimal",
        "--policy",
        policy.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
        "--rollouts",
        "2",
        "--backend",
        "tract",
        "--json",
    ]);
    assert_eq!(v["rollouts"], 2);
    std::fs::remove_dir_all(&out_dir).unwrap();
}

#[test]
fn whole_body_trains_evaluates_and_refuses_a_policy_for_another_robot() {
    let out_dir = std::env::temp_dir().join(format!("kumi-train-wb-{}", std::process::id()));
    let progress = train_minimal_briefly(&out_dir, &[]);
    assert!(
        progress.contains("minimal (hierarchical): 19 observations, 7 actions"),
        "{progress}"
    );
    let csv = std::fs::read_to_string(out_dir.join("metrics.csv")).unwrap();
    assert!(
        csv.lines().next().unwrap().ends_with(
            "episodes,final_position_error_m,final_yaw_error_rad,termination_rate,wall_s"
        ),
        "{csv}"
    );
    let policy = out_dir.join("minimal_whole_body.onnx");
    // The policy carries what deployment needs of its training episodes.
    let file = kumi_runtime::ModelFile::decode(std::fs::read(&policy).unwrap()).unwrap();
    let task = kumi_terms::contract::TrainedTask::from_metadata(&file.metadata)
        .unwrap()
        .expect("the trained task is in the metadata");
    assert_eq!(
        (task.tilt_limit_rad, task.target_xy_m, task.episode_s),
        (0.6, 3.0, 12.0)
    );
    let (episodes, trace) = (out_dir.join("episodes.csv"), out_dir.join("trace.csv"));
    let v: serde_json::Value = kumi_json(&[
        "eval",
        "whole-body",
        "minimal",
        "--policy",
        policy.to_str().unwrap(),
        "--rollouts",
        "2",
        "--backend",
        "tract",
        "--json",
        "--episodes",
        episodes.to_str().unwrap(),
        "--trace",
        trace.to_str().unwrap(),
        "--traced",
        "1",
        "--trace-plot",
        out_dir.join("plots").to_str().unwrap(),
    ]);
    assert_eq!(v["rollouts"], 2);
    // The traced episode drawn: its base path and target from above, its tilt over time
    // beside the fall limit (Minimal's 0.6 rad).
    let svg = |name: &str| std::fs::read_to_string(out_dir.join("plots").join(name)).unwrap();
    let engine = v["engine"].as_str().unwrap();
    let (paths, tilt) = (
        svg(&format!("{engine}_paths.svg")),
        svg(&format!("{engine}_tilt.svg")),
    );
    let title = format!("minimal on {engine}");
    assert!(
        paths.contains(&title) && paths.contains(">episode 0"),
        "{paths}"
    );
    assert!(!paths.contains(">episode 1"), "{paths}");
    assert_eq!(paths.matches("<polyline").count(), 1, "{paths}");
    assert_eq!(tilt.matches("<polyline").count(), 2, "{tilt}");
    assert!(tilt.contains("fall: tilt past 0.600 rad"), "{tilt}");
    // One row per episode; for the one traced episode a row at the start and one after each
    // step, its first and last errors those the episode started and ended with.
    let episodes = std::fs::read_to_string(episodes).unwrap();
    let rows: Vec<Vec<&str>> = episodes.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 3, "{episodes}");
    assert_eq!(
        rows[0][..3],
        ["engine", "episode", "start_position_error_m"]
    );
    assert_eq!(rows[0][9..], ["fell", "diverged"]);
    assert!(rows.iter().all(|r| r.len() == rows[0].len()), "{episodes}");
    assert!(rows[1..].iter().all(|r| r[10] == "0"), "{episodes}");
    let steps: usize = rows[1][8].parse().unwrap();
    let trace = std::fs::read_to_string(trace).unwrap();
    let lines: Vec<&str> = trace.lines().collect();
    assert_eq!(lines.len(), 1 + (steps + 1), "{episodes}");
    assert!(lines[1..].iter().all(|l| l.split(',').nth(1) == Some("0")));
    let error_at = |line: &str| -> f64 { line.split(',').nth(14).unwrap().parse().unwrap() };
    let (start, end) = (error_at(lines[1]), error_at(lines[lines.len() - 1]));
    assert!(
        (start - rows[1][2].parse::<f64>().unwrap()).abs() < 1e-3,
        "{trace}"
    );
    assert!(
        (end - rows[1][4].parse::<f64>().unwrap()).abs() < 1e-3,
        "{trace}"
    );
    // The base's tilt, speed and yaw rate, the turn governor's scale, the links on the ground
    // and the action that led to each step: Minimal's 7 values, by name, empty at the start.
    let header: Vec<&str> = lines[0].split(',').collect();
    assert_eq!(
        header[16..21],
        [
            "tilt_rad",
            "base_speed_m_s",
            "base_yaw_rate_rad_s",
            "turn_governor_scale",
            "ground_links"
        ]
    );
    assert_eq!(header.len(), 21 + 7, "{}", lines[0]);
    assert!(header[21..].iter().all(|h| h.starts_with("action:")));
    assert!(header.contains(&"action:wheel0/velocity"), "{}", lines[0]);
    let cells = |line: &str| -> Vec<String> { line.split(',').map(String::from).collect() };
    assert!(lines[1..].iter().all(|l| cells(l).len() == header.len()));
    assert!(cells(lines[1])[21..].iter().all(String::is_empty));
    let numeric = |c: &String| c.parse::<f64>().is_ok_and(f64::is_finite);
    assert!(numeric(&cells(lines[2])[16]) && cells(lines[2])[21..].iter().all(numeric));
    // Minimal drives off (its speed is not zero all along) and has no turn governor.
    let column = |i: usize| -> Vec<f64> {
        lines[1..]
            .iter()
            .map(|l| cells(l)[i].parse().unwrap())
            .collect()
    };
    assert!(column(17).iter().all(|v| *v >= 0.0) && column(17).iter().any(|v| *v > 0.01));
    assert!(column(18).iter().all(|w| w.is_finite()));
    assert!(column(19).iter().all(|s| *s == 1.0), "{:?}", column(19));
    // Minimal stands on its wheel module's wheels (and skids): the links on the ground are
    // named, sorted, each once, and its wheels are among them.
    let grounds: Vec<String> = lines[1..].iter().map(|l| cells(l)[20].clone()).collect();
    for links in &grounds {
        let names: Vec<&str> = links.split('|').filter(|n| !n.is_empty()).collect();
        assert!(names.windows(2).all(|w| w[0] < w[1]), "{links}");
    }
    assert!(
        grounds.iter().any(|g| g.contains("wheel0/wheel_")),
        "{grounds:?}"
    );
    assert_eq!(v["robot"], "minimal");
    for key in ["position_error_m", "yaw_error_rad", "contacts_per_episode"] {
        assert!(
            v[key]["mean"].is_number() || v["terminations"] == 2,
            "{key}: {v}"
        );
    }
    assert!(v["terminations"].as_u64().unwrap() <= 2);
    assert_eq!(v["diverged"], 0);
    // The rate's 95 % interval per 1000 holds the measured rate and is not empty, even at 0.
    let rate = 1000.0 * v["terminations"].as_f64().unwrap() / v["rollouts"].as_f64().unwrap();
    let interval = &v["terminations_per_1000_95"];
    let (lo, hi) = (interval[0].as_f64().unwrap(), interval[1].as_f64().unwrap());
    assert!(
        lo <= rate && rate <= hi && lo < hi,
        "{interval} around {rate}"
    );
    // A policy for Minimal does not run Dragon: the error names the key and both values.
    let wrong = kumi(&[
        "eval",
        "whole-body",
        "dragon",
        "--policy",
        policy.to_str().unwrap(),
        "--rollouts",
        "1",
    ]);
    let err = String::from_utf8_lossy(&wrong.stderr);
    assert!(!wrong.status.success());
    assert!(
        err.contains("kumi.morphology") && err.contains("`minimal`") && err.contains("`dragon`"),
        "{err}"
    );
    // Another robot's policy is no matter of the config: no hint at --config.
    assert!(!err.contains("another config"), "{err}");
    std::fs::remove_dir_all(&out_dir).unwrap();
}

#[test]
fn action_noise_in_evaluation_changes_episodes_reproducibly_and_must_be_a_std() {
    let eval = |noise: &str| -> serde_json::Value {
        kumi_json(&[
            "eval",
            "whole-body",
            "minimal",
            "--rollouts",
            "3",
            "--backend",
            "tract",
            "--engine",
            "rapier",
            "--action-noise",
            noise,
            "--json",
        ])
    };
    let (clean, noisy) = (eval("0"), eval("0.5"));
    assert_eq!(
        (
            clean["action_noise"].as_f64(),
            noisy["action_noise"].as_f64()
        ),
        (Some(0.0), Some(0.5))
    );
    let outcome = |v: &serde_json::Value| {
        (
            v["position_error_m"]["mean"].to_string(),
            v["terminations"].to_string(),
        )
    };
    assert_ne!(
        outcome(&clean),
        outcome(&noisy),
        "noise changes the episodes"
    );
    assert_eq!(
        noisy,
        eval("0.5"),
        "the same noise again: seeded by the episode"
    );
    // The pushes are in the JSON too, as the markdown reports them.
    assert!(clean["push"].is_null(), "{clean}");
    let pushed: serde_json::Value = kumi_json(&[
        "eval",
        "whole-body",
        "minimal",
        "--rollouts",
        "1",
        "--backend",
        "tract",
        "--engine",
        "rapier",
        "--push-m-s",
        "0.5",
        "--json",
    ]);
    assert_eq!(
        pushed["push"]["velocity_m_s"].as_f64(),
        Some(0.5),
        "{pushed}"
    );
    assert!(pushed["push"]["interval_s"].is_array(), "{pushed}");
    let bad = kumi(&["eval", "whole-body", "minimal", "--action-noise=-1"]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && err.contains("at least 0"), "{err}");
}

#[test]
fn the_flat_baseline_trains_evaluates_and_is_not_taken_for_a_policy_over_the_skill() {
    let out_dir = std::env::temp_dir().join(format!("kumi-train-flat-{}", std::process::id()));
    let progress = train_minimal_briefly(&out_dir, &["--variant", "flat"]);
    // 10 + 2 wheel velocities + 8 previous actions + 7 joint angles + 7 joint velocities.
    assert!(
        progress.contains("minimal (flat): 34 observations, 8 actions")
            && progress.contains("no skill"),
        "{progress}"
    );
    let policy = out_dir.join("minimal_flat.onnx");
    let eval = |variant: &str| {
        kumi(&[
            "eval",
            "whole-body",
            "minimal",
            "--variant",
            variant,
            "--policy",
            policy.to_str().unwrap(),
            "--rollouts",
            "2",
            "--backend",
            "tract",
            "--json",
        ])
    };
    let flat = eval("flat");
    assert!(
        flat.status.success(),
        "{}",
        String::from_utf8_lossy(&flat.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&flat.stdout).unwrap();
    assert_eq!(v["rollouts"], 2);
    // Evaluated as a policy over the skill, it is refused by the key that differs first.
    let wrong = eval("hierarchical");
    let err = String::from_utf8_lossy(&wrong.stderr);
    assert!(!wrong.status.success());
    assert!(
        err.contains("kumi.skill_fingerprint") && err.contains("`none`"),
        "{err}"
    );
    std::fs::remove_dir_all(&out_dir).unwrap();
}

#[test]
fn train_refuses_a_config_with_unknown_fields() {
    let path = std::env::temp_dir().join(format!("kumi-bad-train-{}.toml", std::process::id()));
    let shipped = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../train/configs/arm_reach.toml"
    ))
    .unwrap();
    std::fs::write(
        &path,
        shipped.replace("clip = 0.2", "clip = 0.2\nclipp = 0.3"),
    )
    .unwrap();
    let out = kumi(&[
        "train",
        "arm",
        "--config",
        path.to_str().unwrap(),
        "--steps",
        "1",
    ]);
    std::fs::remove_file(&path).unwrap();
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("unknown field `clipp`"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn eval_arm_prints_the_documented_json() {
    let out = kumi(&[
        "eval",
        "arm",
        "--rollouts",
        "6",
        "--backend",
        "tract",
        "--json",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("tract backend"), "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["rollouts"], 6);
    for error in ["position_error_m", "orientation_error_rad"] {
        for stat in ["mean", "std", "median", "p90"] {
            let x = v[error][stat].as_f64().unwrap();
            assert!(x.is_finite() && x >= 0.0, "{error}.{stat} = {x}");
        }
    }
    // Training's goal noise unless asked otherwise.
    assert_eq!(v["goal_noise"]["position_m"], 0.005);
    assert_eq!(v["goal_noise"]["orientation_rad"], 0.01);
}

#[test]
fn eval_arm_takes_a_still_goal_and_refuses_a_negative_noise() {
    let still = kumi_ok(&[
        "eval",
        "arm",
        "--rollouts",
        "3",
        "--goal-noise-m",
        "0",
        "--goal-noise-rad",
        "0",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_slice(&still.stdout).unwrap();
    assert_eq!(v["goal_noise"]["position_m"], 0.0);
    assert_eq!(v["goal_noise"]["orientation_rad"], 0.0);
    let out = kumi(&["eval", "arm", "--goal-noise-rad=-0.1"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--goal-noise-rad must be a standard deviation >= 0; got -0.1"),
        "{stderr}"
    );
}

#[test]
fn eval_arm_refuses_a_file_that_is_not_a_policy() {
    let path = std::env::temp_dir().join(format!("kumi-not-policy-{}.onnx", std::process::id()));
    std::fs::write(&path, b"hello").unwrap();
    let out = kumi(&["eval", "arm", "--policy", path.to_str().unwrap()]);
    std::fs::remove_file(&path).unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("not an ONNX model"), "{stderr}");
}

#[test]
fn eval_whole_body_names_a_missing_onnx_runtime_as_such_not_as_a_config_mismatch() {
    let out = Command::new(env!("CARGO_BIN_EXE_kumi"))
        .args(["eval", "whole-body", "minimal", "--rollouts", "1"])
        .args(["--backend", "onnxruntime"])
        .env("ORT_DYLIB_PATH", "/nonexistent/libonnxruntime.so")
        .output()
        .expect("kumi runs");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("ORT_DYLIB_PATH=/nonexistent/libonnxruntime.so: no such file"),
        "{stderr}"
    );
    assert!(
        stderr.contains("loading the policy: ")
            && stderr.contains("minimal_whole_body.onnx: onnxruntime cannot load the model"),
        "{stderr}"
    );
    assert!(!stderr.contains("--config"), "{stderr}");
}

#[test]
fn a_bad_output_path_is_refused_before_any_episode_runs() {
    let missing = std::env::temp_dir().join(format!("kumi-no-such-folder-{}", std::process::id()));
    let episodes = missing.join("episodes.csv");
    let out = kumi(&[
        "eval",
        "whole-body",
        "minimal",
        "--rollouts",
        "1000",
        "--episodes",
        episodes.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--episodes") && stderr.contains("not an existing folder"),
        "{stderr}"
    );
    assert!(
        !stderr.contains("evaluating"),
        "it must fail before the episodes: {stderr}"
    );
    // A folder where a file is asked for.
    let dir = std::env::temp_dir();
    let out = kumi(&["report", "goal-bounds", "--out", dir.to_str().unwrap()]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--out") && stderr.contains("is a folder"),
        "{stderr}"
    );
}

#[test]
fn arm_node_names_the_modules_it_could_drive() {
    let out = kumi(&["arm", "leg9", "--robot", "tricycle"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("robot `tricycle` has no module `leg9`") && stderr.contains("leg1"),
        "{stderr}"
    );
    // A wheel module is not an arm.
    let out = kumi(&["arm", "wheel1", "--robot", "tricycle"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("not an arm module"), "{stderr}");
}

#[test]
fn an_unknown_engine_is_refused_with_the_known_ones() {
    let out = kumi(&["sim", "arm", "--engine", "bullet"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("expected `rapier` or `mujoco`"), "{stderr}");
}

#[test]
fn urdf_mjcf_prints_the_mujoco_model() {
    let out = kumi_ok(&["urdf", "minimal", "--mjcf"]);
    let xml = String::from_utf8_lossy(&out.stdout);
    assert!(xml.starts_with("<mujoco model=\"minimal\">"), "{xml}");
    assert!(
        xml.contains("<freejoint") && xml.contains("arm0/joint7"),
        "{xml}"
    );
}

#[cfg(feature = "mujoco")]
mod mujoco {
    use super::kumi_json;

    #[test]
    fn sim_runs_on_mujoco_and_says_so() {
        let report: serde_json::Value = kumi_json(&[
            "sim",
            "dragon",
            "--engine",
            "mujoco",
            "--seconds",
            "2",
            "--json",
        ]);
        assert_eq!(report["engine"], "mujoco");
        assert_eq!(report["config"], "mujoco/4sub");
        assert_eq!(report["finite"], true);
    }

    #[test]
    fn bench_interleaves_engines() {
        let records: Vec<serde_json::Value> = kumi_json(&[
            "bench",
            "sim",
            "--json",
            "--models",
            "arm",
            "--seconds",
            "0.5",
            "--worlds",
            "2",
            "--engines",
            "rapier,mujoco",
        ]);
        let engines: Vec<&str> = records
            .iter()
            .map(|r| r["engine"].as_str().unwrap())
            .collect();
        assert_eq!(engines, ["rapier", "rapier", "mujoco", "mujoco"]);
    }

    #[test]
    fn eval_reports_each_engine() {
        let v: Vec<serde_json::Value> = kumi_json(&[
            "eval",
            "arm",
            "--rollouts",
            "6",
            "--backend",
            "tract",
            "--engine",
            "rapier,mujoco",
            "--json",
        ]);
        assert_eq!(v.len(), 2);
        assert_eq!(
            (v[0]["engine"].as_str(), v[1]["engine"].as_str()),
            (Some("rapier"), Some("mujoco"))
        );
    }

    #[test]
    fn eval_checks_the_shipped_tricycle_against_its_last_stage_by_default() {
        // Its fourth stage tightened the turn governor (its fifth and sixth kept it): the
        // first stage's config (what `kumi train` starts from) describes other action terms
        // than the shipped file, and is refused with the key named; without --config eval
        // takes the last stage's.
        let v: serde_json::Value = kumi_json(&[
            "eval",
            "whole-body",
            "tricycle",
            "--rollouts",
            "1",
            "--backend",
            "tract",
            "--engine",
            "mujoco",
            "--json",
        ]);
        assert_eq!(v["rollouts"], 1);
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let first = root.join("train/configs/whole_body/tricycle.toml");
        let out = super::kumi(&[
            "eval",
            "whole-body",
            "tricycle",
            "--config",
            first.to_str().unwrap(),
            "--rollouts",
            "1",
            "--backend",
            "tract",
            "--engine",
            "mujoco",
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{stderr}");
        assert!(
            stderr.contains("kumi.action") && stderr.contains("lateral_acceleration_m_s2=0.07"),
            "{stderr}"
        );
        assert!(stderr.contains("tricycle.toml: "), "{stderr}");
    }

    #[test]
    fn the_shipped_tricycle_checkpoint_exports_the_shipped_policy() {
        // policies/tricycle_whole_body/checkpoint is the training state of the shipped policy
        // after its last stage. Resumed with that stage's config it has no step left to train
        // and exports the shipped file byte for byte: a later stage goes on from the shipped
        // policy itself, not from a retrained copy.
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let out_dir = std::env::temp_dir().join(format!("kumi-ckpt-{}", std::process::id()));
        let path = |p: &str| root.join(p).to_str().unwrap().to_string();
        super::kumi_ok(&[
            "train",
            "whole-body",
            "tricycle",
            "--config",
            &path("train/configs/whole_body/tricycle_sixth.toml"),
            "--resume",
            &path("policies/tricycle_whole_body/checkpoint"),
            "--out",
            out_dir.to_str().unwrap(),
        ]);
        let exported = std::fs::read(out_dir.join("tricycle_whole_body.onnx")).unwrap();
        let shipped =
            std::fs::read(root.join("policies/tricycle_whole_body/tricycle_whole_body.onnx"))
                .unwrap();
        std::fs::remove_dir_all(&out_dir).unwrap();
        assert!(
            shipped == exported,
            "the checkpoint exports another policy than policies/tricycle_whole_body/tricycle_whole_body.onnx"
        );
    }
}

#[test]
fn logs_carry_no_colour_codes_when_not_on_a_terminal() {
    // Issue 10, finding 10: log files had ANSI colour codes.
    let mut child = Command::new(env!("CARGO_BIN_EXE_kumi"))
        .args(["sim-bridge", "arm"])
        .env("ROS_DOMAIN_ID", (190 + std::process::id() % 40).to_string())
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("kumi runs");
    std::thread::sleep(std::time::Duration::from_secs(3));
    child.kill().unwrap();
    let out = child.wait_with_output().unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(log.contains("sim bridge up"), "{log}");
    assert!(
        !log.contains('\u{1b}'),
        "colour codes in a log file: {log:?}"
    );
}

#[test]
fn the_example_morphology_stands_and_its_whole_body_task_builds() {
    // examples/caterpillar.toml: a robot kumi does not ship, from the shipped modules, no code.
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    let morphology = format!("{root}/examples/caterpillar.toml");
    let report: serde_json::Value = kumi_json(&["sim", &morphology, "--seconds", "2", "--json"]);
    assert_eq!(report["morphology"], "caterpillar");
    assert!(report["max_tilt_rad"].as_f64().unwrap() < 0.1, "{report}");
    let config = format!("{root}/examples/caterpillar_whole_body.toml");
    let out = kumi(&[
        "eval",
        "whole-body",
        &morphology,
        "--config",
        &config,
        "--policy",
        "no-such-policy.onnx",
    ]);
    // It gets as far as the policy file: the robot and its terms were built from the files.
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("no-such-policy.onnx"), "{err}");

    // Without --policy, evaluation looks where training writes (relative to where it runs),
    // and says so, with the training command that writes it.
    let dir = std::env::temp_dir().join(format!("kumi-new-robot-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let eval = || {
        Command::new(env!("CARGO_BIN_EXE_kumi"))
            .args(["eval", "whole-body", &morphology, "--config", &config])
            .current_dir(&dir)
            .output()
            .unwrap()
    };
    let trained = "runs/caterpillar_whole_body/caterpillar_whole_body.onnx";
    let out = eval();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains(trained)
            && err.contains(&format!(
                "Train one with `kumi train whole-body {morphology}`"
            )),
        "{err}"
    );
    // With a file there, it is the one evaluated (this one is no policy: refused by name).
    std::fs::create_dir_all(dir.join("runs/caterpillar_whole_body")).unwrap();
    std::fs::write(dir.join(trained), b"not a policy").unwrap();
    let out = eval();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains(trained) && !err.contains("training has not written"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();

    // The goal bounds of a robot kumi does not ship come from its config.
    let bounds: serde_json::Value = kumi_json(&[
        "report",
        "goal-bounds",
        "--morphologies",
        &morphology,
        "--config",
        &config,
        "--samples",
        "20",
        "--json",
    ]);
    assert!(bounds.to_string().contains("caterpillar"), "{bounds}");
    let both = kumi(&[
        "report",
        "goal-bounds",
        "--morphologies",
        &format!("minimal,{morphology}"),
        "--config",
        &config,
    ]);
    assert!(!both.status.success());
}

#[test]
fn robot_says_what_a_new_robot_is_and_what_its_config_should_set() {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    let morphology = format!("{root}/examples/caterpillar.toml");
    let s: serde_json::Value = kumi_json(&["robot", &morphology, "--json"]);
    assert_eq!(s["robot"], "caterpillar");
    // Dragon's modules and a second trailing leg with its wheel module.
    assert_eq!(s["modules"].as_array().unwrap().len(), 6, "{s}");
    assert_eq!(s["arms"].as_array().unwrap().len(), 3, "{s}");
    assert!(s["mass_kg"].as_f64().unwrap() > 10.0, "{s}");
    // Sized by Dragon's config, the one to start from (as examples/caterpillar_whole_body.toml).
    assert_eq!(
        (s["observations"].as_u64(), s["actions"].as_u64()),
        (Some(33), Some(17))
    );
    assert!(s["config"].as_str().unwrap().contains("dragon.toml"), "{s}");
    let standing = &s["standing"];
    assert_eq!(standing["tilt_limit_rad"].as_f64(), Some(1.0), "{s}");
    assert!(
        standing["stands"].is_boolean() && standing["still"].is_boolean(),
        "{s}"
    );
    let advice = s["advice"].to_string();
    assert!(
        advice.contains("target_z_m") && advice.contains("tilt_limit_rad"),
        "{s}"
    );
    // A shipped robot has its own config: nothing to advise.
    let minimal: serde_json::Value = kumi_json(&["robot", "minimal", "--no-standing", "--json"]);
    assert_eq!(
        (
            minimal["observations"].as_u64(),
            minimal["actions"].as_u64()
        ),
        (Some(19), Some(7))
    );
    assert!(minimal["standing"].is_null() && minimal["advice"].as_array().unwrap().is_empty());
}

#[test]
fn restamp_moves_a_policy_to_its_robot_as_it_is_and_keeps_what_it_was_trained_on() {
    use kumi_terms::contract::{MORPHOLOGY_FINGERPRINT, TRAINED_MORPHOLOGY_FINGERPRINT};
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let dir = std::env::temp_dir().join(format!("kumi-restamp-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let shipped =
        std::fs::read(root.join("policies/minimal_whole_body/minimal_whole_body.onnx")).unwrap();
    let file = |b: &[u8]| kumi_runtime::ModelFile::decode(b.to_vec()).unwrap();
    let current = file(&shipped).metadata[MORPHOLOGY_FINGERPRINT].clone();
    // A policy trained on an older Minimal: loading refuses it by its fingerprint.
    let (stale, _) = file(&shipped)
        .restamp(MORPHOLOGY_FINGERPRINT, "0000", "unused.key")
        .unwrap();
    let stale_path = dir.join("stale.onnx");
    std::fs::write(&stale_path, &stale).unwrap();
    let stale_str = stale_path.to_str().unwrap();
    let eval = |policy: &str| {
        kumi(&[
            "eval",
            "whole-body",
            "minimal",
            "--policy",
            policy,
            "--rollouts",
            "1",
            "--json",
        ])
    };
    let refused = eval(stale_str);
    assert!(!refused.status.success());
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains(MORPHOLOGY_FINGERPRINT),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );

    let out_path = dir.join("restamped.onnx");
    let out = kumi_ok(&[
        "policy",
        "restamp",
        stale_str,
        "--out",
        out_path.to_str().unwrap(),
    ]);
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains(&format!("0000 -> {current}")), "{said}");
    let meta = file(&std::fs::read(&out_path).unwrap()).metadata;
    assert_eq!(meta[MORPHOLOGY_FINGERPRINT], current);
    assert_eq!(meta[TRAINED_MORPHOLOGY_FINGERPRINT], "0000");
    assert!(eval(out_path.to_str().unwrap()).status.success());
    // The original is untouched, and a current file is left as it is.
    assert_eq!(std::fs::read(&stale_path).unwrap(), stale);
    let again = kumi_ok(&["policy", "restamp", out_path.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&again.stdout).contains("nothing written"));
    // Another robot's morphology is refused by name.
    let other = kumi(&["policy", "restamp", stale_str, "--morphology", "dragon"]);
    assert!(!other.status.success());
    assert!(String::from_utf8_lossy(&other.stderr).contains("the morphology `dragon`'s"));

    // Not a whole-body policy, and not a policy at all, are refused by name.
    let skill = kumi(&[
        "policy",
        "restamp",
        root.join("policies/arm_reach/arm_reach.onnx")
            .to_str()
            .unwrap(),
    ]);
    assert!(!skill.status.success());
    assert!(String::from_utf8_lossy(&skill.stderr).contains("not a whole-body policy"));
    let junk = dir.join("junk.onnx");
    std::fs::write(&junk, b"not onnx at all").unwrap();
    let junk = kumi(&["policy", "restamp", junk.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&junk.stderr).contains("is not a policy file"));
    std::fs::remove_dir_all(&dir).unwrap();
}
