#!/usr/bin/env bash
# One job for a lent GPU machine (see ../shared/device/README.md for bringing the stack
# over): benchmark, train for a fixed time with the paper preset on MuJoCo Warp, export the
# ONNX policy + JSON, and leave them with a summary under $OUT (at most 8 files).
#
#   QD_MINUTES=8 bash scripts/gpu_train.sh
#
# Settings (environment): QD_ENGINE (gpu), QD_ENVS (4096), QD_PRESET (paper), QD_MINUTES (8),
# QD_BENCH (1: run the benchmark first), QD_BENCH_ENVS ("4096 16384"), QD_RUN_DIR,
# QD_BANK_SIZE (1024). Tested on CPU with tiny settings:
#   OUT=/tmp/o QD_ENGINE=cpu QD_ENVS=16 QD_PRESET=cpu QD_MINUTES=0.2 QD_BENCH_ENVS=16 QD_BANK_SIZE=8 bash scripts/gpu_train.sh
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:?set OUT to the folder for results}
engine=${QD_ENGINE:-gpu}
envs=${QD_ENVS:-4096}
preset=${QD_PRESET:-paper}
minutes=${QD_MINUTES:-8}
run_dir=${QD_RUN_DIR:-/tmp/quaddance-run}
bank=${QD_BANK_SIZE:-1024}
mkdir -p "$OUT"
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}"
py=${PYTHON:-python3}
qd() { "$py" -m quaddance.cli "$@"; }

if [ "${QD_BENCH:-1}" = 1 ]; then
  bench_envs=()
  for n in ${QD_BENCH_ENVS:-4096 16384}; do bench_envs+=(--num-envs "$n"); done
  qd bench train --engine "$engine" "${bench_envs[@]}" --out "$OUT/bench_train_$engine.json" \
    2>&1 | tail -n 20
fi

resume=()
[ -f "$run_dir/checkpoint.pt" ] && resume=(--resume)
qd train --engine "$engine" --num-envs "$envs" --preset "$preset" --iterations 100000 \
  --minutes "$minutes" --run-dir "$run_dir" --bank-size "$bank" --no-progress "${resume[@]}" \
  2>&1 | grep -v -E '^\s+\(|^\s+\)|Model|Linear|ELU|Normalization|Distribution|^-+$|Resolved|actor :|critic :' | tail -n 20

cp "$run_dir/policy.onnx" "$run_dir/policy.json" "$run_dir/curve.csv" "$OUT/"
"$py" - "$run_dir/curve.csv" "$OUT/summary.json" <<'PY'
import csv, json, sys
rows = list(csv.DictReader(open(sys.argv[1])))
def f(r, k): return float(r[k])
first, last = rows[0], rows[-1]
tail = rows[-max(1, len(rows) // 10):]
summary = {
    "iterations": int(last["iteration"]), "env_steps": int(last["env_steps"]),
    "wall_s": f(last, "wall_s"),
    "env_steps_per_s_mean": sum(f(r, "env_steps_per_s") for r in tail) / len(tail),
    "first": {k: f(first, k) for k in ("reward_per_step", "front_abs_err_m", "fall_rate", "rear_lift_m")},
    "last10pct": {k: sum(f(r, k) for r in tail) / len(tail)
                  for k in ("reward_per_step", "front_abs_err_m", "fall_rate", "rear_lift_m")},
}
json.dump(summary, open(sys.argv[2], "w"), indent=2)
print(json.dumps(summary, indent=2))
PY
ls -la "$OUT"
