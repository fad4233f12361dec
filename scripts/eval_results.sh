#!/usr/bin/env bash
# Regenerate the evaluation reports in docs/results/ (run from the repository root after
# scripts/setup.sh). ROBOT=go2 evaluates the Go2 and writes under docs/results/go2/ (default
# go1: docs/results/); POLICY=path/to/policy.onnx evaluates another policy (default: the
# robot's shipped one). The held-out sets are written under runs/heldout/ on first use. On
# the 2-core machine this takes 15-40 minutes per robot, depending on what else runs.
set -euo pipefail
cd "$(dirname "$0")/.."
Q=.venv/bin/quaddance
ROBOT=${ROBOT:-go1}
R=docs/results
B=benchmarks/results
T=""
if [ "$ROBOT" != go1 ]; then
  R=docs/results/$ROBOT
  B=benchmarks/results/$ROBOT
  T="${ROBOT^}: "  # the reports' headings name the robot
fi
mkdir -p "$R" "$B"
P=(--robot "$ROBOT")
[ -n "${POLICY:-}" ] && P+=(--policy "$POLICY")
gen=(--held-out runs/heldout/generator --set generator "${P[@]}")
oth=(--held-out runs/heldout/other --set other "${P[@]}")
$Q eval "${gen[@]}" -o $R/eval_heldout.md --title "${T}Held-out set 'generator' (training generator), nominal dynamics"
$Q eval "${oth[@]}" -o $R/eval_heldout_other.md --title "${T}Held-out set 'other' (motions not made by the choreographer), nominal dynamics"
$Q eval "${gen[@]}" --policy-output zero -o $R/eval_heldout_ff_only.md --title "${T}Held-out set 'generator', feed-forward alone (policy output zero)"
$Q eval "${oth[@]}" --policy-output zero -o $R/eval_heldout_other_ff_only.md --title "${T}Held-out set 'other', feed-forward alone (policy output zero)"
$Q eval "${gen[@]}" --randomize -o $R/eval_heldout_randomized.md --title "${T}Held-out set 'generator', randomised dynamics"
$Q eval "${oth[@]}" --randomize -o $R/eval_heldout_other_randomized.md --title "${T}Held-out set 'other', randomised dynamics"
# Songs quaddance did not make: the held-out band recordings of the real-music beat set
# (benchmarks/real_music, people's recordings with their own licences).
real=()
for n in feelings war_of_freedom metal_madness armygeddon mutilated_mime; do
  real+=("benchmarks/real_music/audio/$n.ogg")
done
$Q eval "${real[@]}" "${P[@]}" -o $R/eval_songs_real.md --title "${T}Songs not made by quaddance: the real-music set's held-out band recordings, nominal dynamics"
$Q eval "${real[@]}" "${P[@]}" --randomize -o $R/eval_songs_real_randomized.md --title "${T}Songs not made by quaddance: the real-music set's held-out band recordings, randomised dynamics"
$Q bench envelope "${P[@]}" --out $B/envelope.json --report $R/envelope.md --work runs/envelope_$ROBOT
# Fluidsynth renders of MIDI songs of the beat benchmark's random and untuned sets
# (rendered into benchmarks/cache/ by `quaddance bench beats`).
midi=()
for n in random05_latin rock_150_backbeat fast_ska_178 slow_halftime_60 change_rock_90_to_150 bossa_136; do
  f=$(ls benchmarks/cache/${n}-*.wav 2>/dev/null | head -1 || true)
  [ -n "$f" ] && midi+=("$f")
done
if ((${#midi[@]})); then
  $Q eval "${midi[@]}" "${P[@]}" -o $R/eval_songs_midi.md --title "${T}Songs not made by quaddance: fluidsynth renders of MIDI songs (bench beats' random and untuned sets), nominal dynamics"
else
  echo "eval_results: no MIDI renders in benchmarks/cache/ (run quaddance bench beats first); skipped"
fi
