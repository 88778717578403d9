"""Keeps the columns of a training run's metrics.csv that `kumi report compare` plots, with six
significant digits, for committing beside a shipped policy:

    python3 scripts/trim-metrics.py runs/minimal_flat/metrics.csv policies/minimal_flat/metrics.csv
"""
import csv
import sys

KEEP = ["iteration", "env_steps", "mean_step_reward", "mean_episode_return",
        "final_position_error_m", "final_yaw_error_rad", "termination_rate", "wall_s"]
EXACT = ("iteration", "env_steps")


def cell(name, text):
    if name in EXACT or text in ("", "NaN"):
        return text
    return "%.6g" % float(text)


def main(src, dst):
    with open(src, newline="") as f, open(dst, "w") as out:
        out.write(",".join(KEEP) + "\n")
        for row in csv.DictReader(f):
            out.write(",".join(cell(k, row[k]) for k in KEEP) + "\n")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
