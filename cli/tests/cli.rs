//! The `kumi` command end to end: what a user types, and what scripts parse.

use std::process::{Command, Output};

fn kumi(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_kumi"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("kumi runs")
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
    let out = kumi(&["sim", "dragon", "--seconds", "2", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["morphology"], "dragon");
    assert_eq!(report["control_steps"], 60);
    assert_eq!(report["finite"], true);
    assert!(report["max_tilt_rad"].as_f64().unwrap() < 0.1);
}

#[test]
fn sim_refuses_a_nonsense_duration() {
    let out = kumi(&["sim", "arm", "--seconds=-3"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--seconds must be a positive number"));
}

#[test]
fn bench_sim_json_has_the_documented_records() {
    let out = kumi(&[
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
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let records: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
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
