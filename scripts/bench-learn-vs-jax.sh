#!/usr/bin/env bash
# The learner against the JAX anchor (../shared/anchors/ppo_update_jax.py, or $JAX_ANCHOR),
# interleaved in the same minutes on the same cores: JAX, kumi, JAX, kumi for both networks.
# Needs a Python with jax and optax: JAX_PYTHON=/path/to/venv/bin/python (make one with
#   python3 -m venv /tmp/jaxvenv && /tmp/jaxvenv/bin/pip install jax jaxlib optax).
# Usage: scripts/bench-learn-vs-jax.sh [ROUNDS]   (kumi built with cargo build --release)
set -euo pipefail
cd "$(dirname "$0")/.."
python=${JAX_PYTHON:-python3}
anchor=${JAX_ANCHOR:-../shared/anchors/ppo_update_jax.py}
rounds=${1:-2}
threads=$(nproc)
kumi=target/release/kumi
for round in $(seq "$rounds"); do
  for net in "21 7 256 128" "64 24 512 256"; do
    set -- $net
    jax=$("$python" "$anchor" "$1" "$2" "$3" "$4" 10 2>/dev/null | tail -1)
    jax_per_s=$(echo "$jax" | "$python" -c 'import json,sys; print(round(json.load(sys.stdin)["update_samples_per_s"]))')
    kumi_json=$("$kumi" bench learn --only update --threads "$threads" --rounds 10 --json 2>/dev/null)
    kumi_per_s=$(echo "$kumi_json" | "$python" -c "import json,sys; print(round([r['per_s'] for r in json.load(sys.stdin) if r['net']=='$1-$3-$4-$2'][0]))")
    echo "{\"round\": $round, \"net\": \"$1-$3-$4-$2\", \"threads\": $threads, \"jax_per_s\": $jax_per_s, \"kumi_per_s\": $kumi_per_s, \"ratio\": $("$python" -c "print(round($kumi_per_s / $jax_per_s, 2))")}"
  done
done
