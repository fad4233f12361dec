#!/usr/bin/env bash
# One job for a lent GPU machine (see ../shared/device/README.md for bringing the stack
# over): benchmark, train for a fixed time with the paper preset on MuJoCo Warp, export the
# ONNX policy + JSON, and leave them with a summary under $OUT (at most 8 files). The
# benchmark starts with the engines' agreement on this device (`engine_agreement` in its JSON).
#
#   QD_MINUTES=8 QD_TRAIN_ARGS="--whole-body --max-height 0.25" bash scripts/gpu_train.sh
#
# Settings (environment): QD_ENGINE (gpu), QD_ENVS (4096), QD_PRESET (paper), QD_MINUTES (8),
# QD_BENCH (1: run the benchmark first; a failed benchmark does not stop the training),
# QD_BENCH_ENVS ("4096 16384"), QD_MJLAB (0: 1 also times mjlab's Go1 task), QD_RUN_DIR,
# QD_BANK_SIZE (256), QD_TRAIN_ARGS (more `quaddance train` options, e.g. --robot go2).
# Tested on CPU with tiny settings (Warp on the CPU compiles its kernels first, minutes):
#   OUT=/tmp/o QD_ENGINE=gpu QD_ENVS=16 QD_PRESET=cpu QD_MINUTES=0.2 QD_BENCH_ENVS=16 QD_BANK_SIZE=8 bash scripts/gpu_train.sh
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:?set OUT to the folder for results}
engine=${QD_ENGINE:-gpu}
envs=${QD_ENVS:-4096}
preset=${QD_PRESET:-paper}
minutes=${QD_MINUTES:-8}
run_dir=${QD_RUN_DIR:-/tmp/quaddance-run}
bank=${QD_BANK_SIZE:-256}
read -r -a train_args <<<"${QD_TRAIN_ARGS:-}"
mkdir -p "$OUT"
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}"
py=${PYTHON:-python3}
qd() { "$py" -m quaddance.cli "$@"; }

if [ "${QD_BENCH:-1}" = 1 ]; then
  bench_envs=()
  for n in ${QD_BENCH_ENVS:-4096 16384}; do bench_envs+=(--num-envs "$n"); done
  mjlab=--no-mjlab
  [ "${QD_MJLAB:-0}" = 1 ] && mjlab=--mjlab
  qd bench train --engine "$engine" "${bench_envs[@]}" "$mjlab" \
    --out "$OUT/bench_train_$engine.json" 2>&1 | tail -n 20 || echo "gpu_train: the benchmark failed"
fi

resume=()
[ -f "$run_dir/checkpoint.pt" ] && resume=(--resume)
qd train --engine "$engine" --num-envs "$envs" --preset "$preset" --iterations 100000 \
  --minutes "$minutes" --run-dir "$run_dir" --bank-size "$bank" --no-progress "${resume[@]}" \
  "${train_args[@]}" 2>&1 | tee "$OUT/train.log" | grep -v -E '^\s+\(|^\s+\)|Model|Linear|ELU|Normalization|Distribution|^-+$|Resolved|actor :|critic :' | tail -n 20

cp "$run_dir/policy.onnx" "$run_dir/policy.json" "$run_dir/curve.csv" "$run_dir/checkpoint.pt" "$OUT/"
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
