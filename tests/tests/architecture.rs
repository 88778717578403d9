//! The crate graph shows the architecture: a node that runs on hardware links no physics
//! engine (issue 12). Checked on the resolved dependency graph (`cargo tree`), so a dependency
//! that sneaks in through another crate is caught too.

use std::process::Command;

/// Every package `package` depends on (normal dependencies, all features), by name.
fn dependencies(package: &str) -> Vec<String> {
    let out = Command::new(env!("CARGO"))
        .args([
            "tree",
            "--offline",
            "--locked",
            "--all-features",
            "-e",
            "normal",
            "--prefix",
            "none",
            "-p",
            package,
        ])
        .current_dir(kumi_tests::workspace())
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "cargo tree failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect()
}

const SIMULATION: [&str; 6] = [
    "rapier3d",
    "mujoco-rs",
    "kumi-engine",
    "kumi-sim",
    "kumi-mujoco",
    "kumi-worlds",
];

#[test]
fn the_nodes_that_run_on_hardware_link_no_simulator() {
    for node in [
        "kumi-arm-node",
        "kumi-whole-body-node",
        "kumi-terms",
        "kumi-runtime",
    ] {
        let deps = dependencies(node);
        assert!(deps.len() > 3, "{node}: no dependency graph: {deps:?}");
        let found: Vec<&String> = deps
            .iter()
            .filter(|d| SIMULATION.contains(&d.as_str()))
            .collect();
        assert!(found.is_empty(), "{node} links the simulator: {found:?}");
        assert!(
            !deps.iter().any(|d| d == "kumi-train" || d == "candle-core"),
            "{node} links the trainer"
        );
    }
}

#[test]
fn the_sim_bridge_does_link_it() {
    // The check above can fail: the bridge's graph has what the nodes' must not.
    assert!(dependencies("kumi-sim-bridge").contains(&"rapier3d".to_string()));
}
