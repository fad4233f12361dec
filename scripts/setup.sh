#!/usr/bin/env bash
# Set up quaddance on a fresh Debian/Ubuntu machine (run as root or with sudo available):
# system packages for headless rendering and the beat benchmark, then a virtual environment
# in .venv with the package installed editable. A second run reuses everything that is
# already there (it reinstalls only when pyproject.toml changed).
set -euo pipefail
cd "$(dirname "$0")/.."

# Mesa's EGL (software rendering for videos) and fluidsynth + a General MIDI soundfont
# (`quaddance bench beats`).
sys_pkgs=(libegl1 libegl-mesa0 libgl1-mesa-dri libgles2 fluidsynth fluid-soundfont-gm libportaudio2)
# Chromium, with its own software WebGL (SwiftShader): the test of the live viewer's page.
sys_pkgs+=(chromium)
missing=()
for p in "${sys_pkgs[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if ((${#missing[@]})); then
  sudo_cmd=""
  [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
  echo "setup: installing system packages: ${missing[*]}"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# Python 3.11+ (3.11 first: the CPU build of torch on these machines is for 3.11).
py=""
for cand in python3.11 python3.12 python3.13 python3; do
  if command -v "$cand" >/dev/null && "$cand" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
    py=$cand; break
  fi
done
[ -n "$py" ] || { echo "setup: needs Python 3.11 or newer" >&2; exit 1; }

stamp=.venv/.setup-stamp
want=$(sha256sum pyproject.toml | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && .venv/bin/python -c 'import quaddance' 2>/dev/null; then
  exit 0
fi
[ -x .venv/bin/python ] || "$py" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
# torch first, by its exact pin: on CPU-only machines this takes the CPU build.
.venv/bin/python -m pip install -q "$(grep -o '"torch==[^"]*"' pyproject.toml | tr -d '"')"
.venv/bin/python -m pip install -q -e '.[dev]'
echo "$want" > "$stamp"
echo "setup: ready (.venv)"
