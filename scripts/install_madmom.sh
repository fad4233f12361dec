#!/usr/bin/env bash
# Build madmom 0.16.1 into its own environment (default .madmom/venv) for the beat benchmarks
# (`quaddance bench beats|live` use it when it is there). madmom is not a dependency of
# quaddance: its code is BSD-2-Clause, but its trained models are CC BY-NC-SA 4.0
# (non-commercial), so it is only ever compared against, never shipped or imported.
#
# madmom 0.16.1 (the last release) needs numpy < 1.24 and ships C files from an old Cython that
# Python 3.11 cannot compile: the sdist is rebuilt from its .pyx sources with Cython 0.29, and
# one import that Python 3.10 removed (collections.MutableSequence) is pointed at
# collections.abc. Everything comes from PyPI.
#
# Usage: bash scripts/install_madmom.sh [VENV_DIR]
set -euo pipefail

cd "$(dirname "$0")/.."
VENV="${1:-.madmom/venv}"
PYTHON="${PYTHON:-python3}"
MADMOM_VERSION=0.16.1

if [ -x "$VENV/bin/python" ] && "$VENV/bin/python" -W ignore -c \
    "import madmom, sys; sys.exit(madmom.__version__ != '$MADMOM_VERSION')" 2>/dev/null; then
  echo "madmom $MADMOM_VERSION is already in $VENV"
  exit 0
fi

"$PYTHON" -m venv "$VENV"
PIP=("$VENV/bin/pip" install --quiet --disable-pip-version-check)
# Build tools and madmom's run-time needs, pinned to versions that build on Python 3.11.
"${PIP[@]}" "numpy==1.23.5" "scipy==1.10.1" "cython==0.29.37" "setuptools==69.5.1" \
  "wheel==0.43.0" "mido==1.3.2"

WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
"$VENV/bin/pip" download --quiet --disable-pip-version-check --no-deps --no-binary :all: \
  --dest "$WORK" "madmom==$MADMOM_VERSION"
tar -xzf "$WORK/madmom-$MADMOM_VERSION.tar.gz" -C "$WORK"
SRC="$WORK/madmom-$MADMOM_VERSION"
# The shipped C was generated for Pythons before 3.11: let Cython generate it again.
find "$SRC/madmom" -name "*.c" -delete
sed -i 's/^from collections import MutableSequence$/from collections.abc import MutableSequence/' \
  "$SRC/madmom/processors.py"
"${PIP[@]}" --no-build-isolation "$SRC"

"$VENV/bin/python" -W ignore -c "
from madmom.features.beats import DBNBeatTrackingProcessor, RNNBeatProcessor
from madmom.features.downbeats import DBNDownBeatTrackingProcessor, RNNDownBeatProcessor
import madmom
print('madmom', madmom.__version__, 'in $VENV')
"
