"""Soak benchmark (issue 10): a sim bridge and one arm node per arm module, in real time, for
an hour (by default), driven by goals all along. Reports resident memory and its slope per
process, the bridge's late steps (a step that began more than one control period after its
tick) and the latest start, and every warning the nodes logged.

Run from the repository root with the Python that has rclpy (`bash .ci/run` creates it):

    cargo build --release --bin kumi
    target/rosvenv/bin/python scripts/soak.py [--morphology tricycle] [--seconds 3600] [--json]

Each node is the release `kumi` binary in its own process; their logs, and a CSV of the memory
samples, go to --out (default runs/soak). The manipulator alternates between two goals 5 cm
apart (±2.5 cm around its starting pose) every 5 s; every leg is sent its own starting tool pose, so that its policy runs.
"""

import argparse
import copy
import json
import os
import signal
import subprocess
import sys
import time
import tomllib

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def arm_modules(morphology):
    """(name, role) of every arm module of a shipped morphology, or of a morphology file."""
    path = morphology if morphology.endswith(".toml") else os.path.join(ROOT, "urdf/morphologies", morphology + ".toml")
    with open(path, "rb") as f:
        spec = tomllib.load(f)
    return spec["name"], [(m["name"], m["role"]) for m in spec["module"] if m["kind"] == "arm"]


def rss_kib(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def slope_per_hour(samples):
    """Least-squares slope of (t [s], value) pairs, per hour."""
    n = len(samples)
    if n < 2:
        return 0.0
    mt = sum(t for t, _ in samples) / n
    mv = sum(v for _, v in samples) / n
    var = sum((t - mt) ** 2 for t, _ in samples)
    return 3600.0 * sum((t - mt) * (v - mv) for t, v in samples) / var if var > 0 else 0.0


def start(kumi, args, log_dir, name, env):
    log = open(os.path.join(log_dir, name + ".log"), "w")
    return subprocess.Popen([kumi] + args, stdout=log, stderr=subprocess.STDOUT, env=env)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--morphology", default="tricycle")
    p.add_argument("--seconds", type=float, default=3600.0)
    p.add_argument("--warmup", type=float, default=60.0, help="seconds left out of the memory slope")
    p.add_argument("--kumi", default=os.path.join(ROOT, "target/release/kumi"))
    p.add_argument("--domain", type=int, default=201, help="ROS domain (default outside the tests' 20-179)")
    p.add_argument("--out", default=os.path.join(ROOT, "runs/soak"))
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    if not os.path.exists(args.kumi):
        sys.exit(f"error: no kumi binary at {args.kumi}: run `cargo build --release --bin kumi` first")
    robot, arms = arm_modules(args.morphology)
    os.makedirs(args.out, exist_ok=True)
    env = dict(os.environ, ROS_DOMAIN_ID=str(args.domain))
    env.pop("RUST_LOG", None)  # the nodes' own default filter
    os.environ["ROS_DOMAIN_ID"] = str(args.domain)

    procs = {}
    dead = []
    try:
        procs["bridge"] = start(args.kumi, ["sim-bridge", args.morphology, "--robot", robot], args.out, "bridge", env)
        time.sleep(2.0)
        for name, _ in arms:
            procs[name] = start(args.kumi, ["arm", name, "--robot", robot, "--morphology", args.morphology],
                                args.out, name, env)

        rclpy.init()
        node = rclpy.create_node("kumi_soak")
        ee, goals, diag = {}, {}, {}
        for name, _ in arms:
            node.create_subscription(PoseStamped, f"/{robot}/{name}/ee_pose", lambda m, n=name: ee.setdefault(n, m), 10)
            goals[name] = node.create_publisher(PoseStamped, f"/{robot}/{name}/goal_pose", 10)

        def on_diag(m):
            for s in m.status:
                diag[s.name] = {kv.key: kv.value for kv in s.values}

        node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)

        samples = []  # (t, {process: rss})
        csv = open(os.path.join(args.out, "memory.csv"), "w")
        csv.write("t_s," + ",".join(f"{k}_rss_kib" for k in procs) + "\n")
        t0 = time.monotonic()
        next_goal, next_sample, flip = t0, t0, 1
        rtf_min = None
        while time.monotonic() - t0 < args.seconds:
            rclpy.spin_once(node, timeout_sec=0.1)
            now = time.monotonic()
            dead = [k for k, pr in procs.items() if pr.poll() is not None]
            if dead:
                print(f"error: {', '.join(dead)} exited", file=sys.stderr)
                break
            if now >= next_goal and len(ee) == len(arms):
                for name, role in arms:
                    goal = PoseStamped()
                    goal.header.frame_id = ee[name].header.frame_id
                    goal.pose = copy.deepcopy(ee[name].pose)
                    if role == "manipulator":
                        goal.pose.position.z += 0.025 * flip
                    goals[name].publish(goal)
                flip, next_goal = -flip, now + 5.0
            if now >= next_sample:
                row = {k: rss_kib(pr.pid) for k, pr in procs.items()}
                samples.append((now - t0, row))
                csv.write(f"{now - t0:.1f}," + ",".join(str(row[k]) for k in procs) + "\n")
                csv.flush()
                bridge = diag.get(f"kumi sim bridge: {robot}", {})
                if "realtime_factor" in bridge and now - t0 > 10:
                    rtf = float(bridge["realtime_factor"])
                    rtf_min = rtf if rtf_min is None else min(rtf_min, rtf)
                next_sample = now + 10.0
        elapsed = time.monotonic() - t0
        bridge = dict(diag.get(f"kumi sim bridge: {robot}", {}))
        nodes = {name: dict(diag.get(f"kumi arm node: {robot}/{name}", {})) for name, _ in arms}
        node.destroy_node()
        rclpy.try_shutdown()

    finally:
        for pr in procs.values():
            if pr.poll() is None:
                pr.send_signal(signal.SIGINT)
        for pr in procs.values():
            try:
                pr.wait(timeout=10)
            except subprocess.TimeoutExpired:
                pr.kill()
    warnings = []
    for k in procs:
        with open(os.path.join(args.out, k + ".log")) as f:
            warnings += [f"{k}: {line.strip()}" for line in f if " WARN " in line or " ERROR " in line]
    memory = {}
    for k in procs:
        series = [(t, row[k]) for t, row in samples if t >= args.warmup and row[k] > 0]
        memory[k] = {
            "rss_start_kib": samples[0][1][k] if samples else 0,
            "rss_end_kib": samples[-1][1][k] if samples else 0,
            "slope_kib_per_hour": round(slope_per_hour(series), 1),
        }
    report = {
        "morphology": args.morphology,
        "seconds": round(elapsed, 1),
        "memory": memory,
        "bridge": {key: bridge.get(key) for key in ("control_steps", "sim_time_s", "wall_time_s", "late_steps",
                                                     "max_step_late_ms", "stale_holds", "rejected_total")},
        "realtime_factor_min": rtf_min,
        "arm_nodes": {name: {key: d.get(key) for key in ("goals_accepted", "stale_holds", "policy_failures",
                                                           "sim_restarts")} for name, d in nodes.items()},
        "exited": dead,
        "warnings": len(warnings),
        "first_warnings": warnings[:10],
        "out": args.out,
    }
    if args.json:
        print(json.dumps(report))
    else:
        print(json.dumps(report, indent=2))
    if dead:
        print(f"error: {', '.join(dead)} exited during the soak", file=sys.stderr)
    ok = not warnings and not dead and elapsed >= 0.99 * args.seconds
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
