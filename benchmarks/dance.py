"""`dance` with video, timed as a user runs it: wall seconds per second of song.

Each run is a fresh ``quaddance dance SONG --out DIR`` process (interpreter start-up,
imports, render workers, music analysis, simulation, video, plot, metrics), timed from
outside. The songs are the built-in demo song cut to 12 s and whole (30 s); the goal is
wall / song <= 1 for both on an idle 2-core machine.

Wall times depend on what else runs on the machine, so each run also records the CPU time of
the whole process tree (user + sys of the command and of every child it waited for: render
workers, ffmpeg) and the 1-minute load average before and after it; ``cpu_s / cpu_count``
is a lower bound of the wall time on idle cores. The phase timings are the command's own,
from its metrics.json (``timings_s``).
"""

from __future__ import annotations

import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from quaddance.errors import QuaddanceError
from quaddance.fileio import write_json

SONG_LENGTHS_S: tuple[float, ...] = (12.0, 30.0)
"""Song lengths timed, s: a short clip (fixed start-up dominates) and the whole demo song."""


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def dance_command(
    song: Path, out_dir: Path, policy: Path | None = None, video: bool = True
) -> list[str]:
    """The command a user types: the installed ``quaddance`` script when it is beside this
    interpreter (as in the venv), else ``python -m quaddance.cli``."""
    script = Path(sys.executable).with_name("quaddance")
    cmd = [str(script)] if script.is_file() else [sys.executable, "-m", "quaddance.cli"]
    cmd += ["dance", str(song), "--out", str(out_dir)]
    if policy is not None:
        cmd += ["--policy", str(policy)]
    if not video:
        cmd.append("--no-video")
    return cmd


def time_dance_command(
    song: Path, song_s: float, out_dir: Path, policy: Path | None, video: bool = True
) -> dict:
    """One run of the whole command: wall, CPU of the process tree, load, phase timings and
    the simulation's real-time factor (metrics.json's ``realtime_factor_sim``)."""
    import json

    shutil.rmtree(out_dir, ignore_errors=True)
    load_before = os.getloadavg()[0]
    cpu_before = _children_cpu_s()
    start = time.perf_counter()
    proc = subprocess.run(
        dance_command(song, out_dir, policy, video), capture_output=True, text=True, check=False
    )
    wall_s = time.perf_counter() - start
    cpu_s = _children_cpu_s() - cpu_before
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
        raise QuaddanceError(f"dance exited with {proc.returncode}: {tail[0]}")
    metrics = json.loads((out_dir / "metrics.json").read_text())
    return {
        "wall_s": wall_s,
        "ratio": wall_s / song_s,
        "cpu_s": cpu_s,
        "load_1min_before": load_before,
        "load_1min_after": os.getloadavg()[0],
        "timings_s": metrics.get("timings_s", {}),
        "realtime_factor_sim": metrics.get("realtime_factor_sim"),
    }


def _summary(song_s: float, runs: list[dict]) -> dict[str, Any]:
    walls = [r["wall_s"] for r in runs]
    cpus = [r["cpu_s"] for r in runs]
    phases = sorted({k for r in runs for k in r["timings_s"]})
    n_cpu = os.cpu_count() or 1
    return {
        "song_s": song_s,
        "wall_median_s": statistics.median(walls),
        "wall_min_s": min(walls),
        "ratio_median": statistics.median(walls) / song_s,
        "ratio_min": min(walls) / song_s,
        "realtime_factor_sim_median": statistics.median(r["realtime_factor_sim"] for r in runs),
        "cpu_median_s": statistics.median(cpus),
        "cpu_bound_ratio": statistics.median(cpus) / n_cpu / song_s,
        "load_1min_median": statistics.median(r["load_1min_before"] for r in runs),
        "phases_median_s": {
            k: statistics.median(r["timings_s"][k] for r in runs if k in r["timings_s"])
            for k in phases
        },
        "runs": runs,
    }


def run_dance_bench(
    out_path: str | Path,
    song_lengths_s: Sequence[float] = SONG_LENGTHS_S,
    repeats: int = 3,
    warmup: bool = True,
    policy: Path | None = None,
    progress: Callable[[str], None] = lambda line: None,
    video: bool = True,
) -> dict[str, Any]:
    """Time the whole ``dance`` command on each song length, ``repeats`` times; write JSON.

    Args:
        out_path: the JSON results.
        song_lengths_s: lengths of the demo song to dance, s (cut from its start; at most 30).
        repeats: timed runs per song; the summary gives median and min.
        warmup: one untimed run first, so that the timed runs find the file cache (and
            numba's cache) as a user's second run does.
        policy: the policy .onnx; None: the shipped one.
        progress: called with a line after each run.
        video: False times ``dance --no-video`` (the simulation's speed, as
            ``realtime_factor_sim``: song seconds per second of physics and policy).
    """
    import soundfile as sf

    from quaddance.music.synth import demo_song

    if repeats < 1:
        raise QuaddanceError(f"repeats must be >= 1, got {repeats}")
    sr = 22050
    y, _ = demo_song(sr)
    if max(song_lengths_s) > len(y) / sr + 1e-6 or min(song_lengths_s) <= 0:
        raise QuaddanceError(f"song lengths must be in (0, {len(y) / sr:.0f}] s")
    result: dict[str, Any] = {
        "name": "dance",
        "command": "quaddance dance SONG --out DIR"
        + ("" if video else " --no-video")
        + f" (a fresh process per run, video {'on' if video else 'off'})",
        "cpu_count": os.cpu_count(),
        "machine": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "repeats": repeats,
        "goal": (
            "ratio (wall / song length) <= 1.0 for every song, on an idle machine"
            if video
            else "realtime_factor_sim >= 20 for every song, on an idle machine"
        ),
        "songs": [],
    }
    with tempfile.TemporaryDirectory(prefix="quaddance-bench-dance-") as tmp_name:
        tmp = Path(tmp_name)
        songs = []
        for song_s in song_lengths_s:
            path = tmp / f"demo_{song_s:g}s.wav"
            sf.write(path, y[: round(song_s * sr)], sr)
            songs.append((song_s, path))
        if warmup:
            progress("warm-up run (not timed) ...")
            time_dance_command(songs[0][1], songs[0][0], tmp / "out", policy, video)
        for song_s, path in songs:
            runs = []
            for i in range(repeats):
                run = time_dance_command(path, song_s, tmp / "out", policy, video)
                runs.append(run)
                progress(
                    f"{song_s:g} s song, run {i + 1}/{repeats}: {run['wall_s']:.1f} s wall "
                    f"({run['ratio']:.2f}x), {run['cpu_s']:.1f} s CPU, "
                    f"load {run['load_1min_before']:.1f}, "
                    f"sim {run['realtime_factor_sim']:.1f}x real time"
                )
            result["songs"].append(_summary(song_s, runs))
    write_json(out_path, result)
    return result
