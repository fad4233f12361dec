#!/usr/bin/env bash
# Regenerate the evaluation reports in docs/results/ (run from the repository root after
# scripts/setup.sh). POLICY=path/to/policy.onnx evaluates another policy (default: shipped).
# The held-out sets are written under runs/heldout/ on first use. On the 2-core machine this
# takes 10-30 minutes, depending on what else runs.
set -euo pipefail
cd "$(dirname "$0")/.."
Q=.venv/bin/quaddance
R=docs/results
P=()
[ -n "${POLICY:-}" ] && P=(--policy "$POLICY")
gen=(--held-out runs/heldout/generator --set generator "${P[@]}")
oth=(--held-out runs/heldout/other --set other "${P[@]}")
$Q eval "${gen[@]}" -o $R/eval_heldout.md --title "Held-out set 'generator' (training generator), nominal dynamics"
$Q eval "${oth[@]}" -o $R/eval_heldout_other.md --title "Held-out set 'other' (motions not made by the choreographer), nominal dynamics"
$Q eval "${gen[@]}" --policy-output zero -o $R/eval_heldout_ff_only.md --title "Held-out set 'generator', feed-forward alone (policy output zero)"
$Q eval "${oth[@]}" --policy-output zero -o $R/eval_heldout_other_ff_only.md --title "Held-out set 'other', feed-forward alone (policy output zero)"
$Q eval "${gen[@]}" --randomize -o $R/eval_heldout_randomized.md --title "Held-out set 'generator', randomised dynamics"
$Q eval "${oth[@]}" --randomize -o $R/eval_heldout_other_randomized.md --title "Held-out set 'other', randomised dynamics"
$Q bench envelope "${P[@]}"
