#!/usr/bin/env python3
"""The penalty baseline's weight search (the paper's section V-C: eight combinations of the pose
weights, w_ori and w_c, best one shipped).

Each combination is the shipped config `train/configs/penalty/tricycle.toml` with three values
changed: the pose weights w_p1 and w_p2 (both multiplied by one factor), w_ori (Eq. 5) and w_c
(Eq. 6). Each trains for --steps environment steps (seed and every other setting unchanged) and is
evaluated with `kumi eval whole-body --json` over --rollouts episodes in MuJoCo. The table goes to
--out (README.md and search.json); the run directories to --runs.

Ranking: falls first are what the paper's collapsed settings show, so the score is the mean final
position error [m] plus 1 m per fallen episode fraction, plus 0.002 m per undesired-contact step
(171 contact steps per episode, the flat baseline's, cost 0.34 m): lower is better. The weights
are stated here and in the report, so the choice can be checked.

    python3 scripts/penalty_search.py [--steps 1000000] [--rollouts 200] [--kumi target/release/kumi]
"""
import argparse
import itertools
import json
import pathlib
import re
import subprocess
import sys
import time

BASE = pathlib.Path("train/configs/penalty/tricycle.toml")
POSE_SCALE = [1.0, 2.0]
W_ORI = [0.25, 1.0]
W_C = [0.1, 0.5]
FALL_M = 1.0
CONTACT_M = 0.002


def set_value(text, key, value):
    """Replaces `key = <number>` (one line, comments kept) in a TOML text."""
    pattern = re.compile(rf"^({re.escape(key)}\s*=\s*)([-0-9.e]+)", re.M)
    new, n = pattern.subn(lambda m: f"{m.group(1)}{value}", text)
    if n != 1:
        sys.exit(f"penalty_search: `{key} = ...` found {n} times in {BASE}, expected once")
    return new


def number(text, key):
    m = re.search(rf"^{re.escape(key)}\s*=\s*([-0-9.e]+)", text, re.M)
    if not m:
        sys.exit(f"penalty_search: no `{key}` in {BASE}")
    return float(m.group(1))


def fmt(value, digits):
    """A number with `digits` decimals; `-` for JSON null (every episode fell)."""
    return "-" if value is None else f"{value:.{digits}f}"


def score(ev):
    falls = ev["terminations"] / ev["rollouts"]
    mean = ev["position_error_m"]["mean"]
    if mean is None:  # every episode fell: no final error to average (JSON null)
        mean = 3.0
    return mean + FALL_M * falls + CONTACT_M * ev["contacts_per_episode"]["mean"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--rollouts", type=int, default=200)
    ap.add_argument("--kumi", default="target/release/kumi")
    ap.add_argument("--runs", default="runs/penalty_search")
    ap.add_argument("--out", default="reports/penalty_search")
    args = ap.parse_args()
    base = BASE.read_text()
    p1, p2 = number(base, "w_p1"), number(base, "w_p2")
    runs, out = pathlib.Path(args.runs), pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for k, (scale, w_ori, w_c) in enumerate(itertools.product(POSE_SCALE, W_ORI, W_C)):
        name = f"pose{scale:g}_ori{w_ori:g}_c{w_c:g}"
        run = runs / name
        run.mkdir(parents=True, exist_ok=True)
        config = base
        for key, value in [("w_p1", p1 * scale), ("w_p2", p2 * scale), ("w_ori", w_ori), ("w_c", w_c)]:
            config = set_value(config, key, value)
        config_path = run / "config.toml"
        config_path.write_text(config)
        policy = run / "tricycle_penalty.onnx"
        print(f"[{k + 1}/8] {name}: training {args.steps} steps", flush=True)
        t0 = time.monotonic()
        if not policy.exists():
            with open(run / "train.log", "w") as log:
                subprocess.run([args.kumi, "train", "whole-body", "tricycle", "--variant", "penalty",
                                "--config", str(config_path), "--steps", str(args.steps), "--out", str(run)],
                               stdout=log, stderr=subprocess.STDOUT, check=True)
        train_s = time.monotonic() - t0
        ev = subprocess.run([args.kumi, "eval", "whole-body", "tricycle", "--variant", "penalty",
                             "--policy", str(policy), "--config", str(config_path), "--rollouts", str(args.rollouts),
                             "--engine", "mujoco", "--backend", "tract", "--json"],
                            capture_output=True, text=True, check=True)
        evaluation = json.loads(ev.stdout)
        if isinstance(evaluation, list):
            evaluation = evaluation[0]
        row = {"name": name, "pose_scale": scale, "w_p1": p1 * scale, "w_p2": p2 * scale, "w_ori": w_ori, "w_c": w_c,
               "train_s": round(train_s), "evaluation": evaluation, "score": score(evaluation)}
        rows.append(row)
        print(f"    {evaluation['position_error_m']['mean'] or float('nan'):.3f} m, {evaluation['terminations']} falls, "
              f"{evaluation['contacts_per_episode']['mean']:.0f} contact steps: score {row['score']:.3f}", flush=True)
        (out / "search.json").write_text(json.dumps({"steps": args.steps, "rollouts": args.rollouts, "rows": rows}, indent=1))
    best = min(rows, key=lambda r: r["score"])
    lines = [
        "# The penalty baseline's weight search (Tricycle)",
        "",
        f"Generated by `python3 scripts/penalty_search.py --steps {args.steps} --rollouts {args.rollouts}`: eight",
        f"combinations of the pose weights (w_p1 = {p1:g} x factor, w_p2 = {p2:g} x factor), w_ori (Eq. 5) and w_c (Eq. 6)",
        f"over `{BASE}`, each trained {args.steps:,} steps (seed 0) and evaluated over {args.rollouts} MuJoCo episodes",
        "(seed 1). Score = mean final position error [m] + "
        f"{FALL_M:g} m x fall fraction + {CONTACT_M:g} m per undesired-contact step per episode; lower is better.",
        "",
        "| pose factor | w_ori | w_c | position error [m] mean / median | yaw [rad] | leg tool orientation [rad] | contact steps per episode | falls | score | training [s] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        e = r["evaluation"]
        mark = " **best**" if r is best else ""
        lines.append(
            f"| {r['pose_scale']:g} | {r['w_ori']:g} | {r['w_c']:g} | {fmt(e['position_error_m']['mean'], 3)} / "
            f"{fmt(e['position_error_m']['median'], 3)} | {fmt(e['yaw_error_rad']['mean'], 2)} | {fmt(e['leg_orientation_rad']['mean'], 2)} | "
            f"{e['contacts_per_episode']['mean']:.1f} | {e['terminations']} of {e['rollouts']} | {r['score']:.3f}{mark} | {r['train_s']} |"
        )
    lines += ["", f"Best: `{best['name']}` (run directory `{runs / best['name']}`)."]
    (out / "README.md").write_text("\n".join(lines) + "\n")
    print(f"best: {best['name']} (score {best['score']:.3f}); table in {out / 'README.md'}")


if __name__ == "__main__":
    main()
