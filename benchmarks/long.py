"""Long inputs: `dance --no-video` on a song of the maximum length, and a far longer file.

1. A code-made song of `MAX_SONG_S` (20 min, 44.1 kHz stereo 16-bit: a CD rip's format) is
   danced by the real command in a child process, `LONG_REPEATS` times; wall time, CPU time
   and peak memory (the child's maximum resident set, from ``os.wait4``) are recorded, with
   the command's own split (analysis + choreography, simulation, the rest: plot, metrics,
   files). The goal: median wall <= `TARGET_WALL_S`, peak <= `TARGET_PEAK_MB`.
2. A 2-hour, mostly silent file (8 kHz mono 8-bit, 58 MB) must be refused from its header:
   the time and peak memory of that refusal.

The machine is shared: the load average before each run is recorded beside the figures, and
CPU seconds (user + system) say what the command costs whatever else runs.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.fileio import write_json
from quaddance.music.audio import MAX_SONG_S


def _run(cmd: list[str]) -> dict[str, Any]:
    """Run ``cmd``: exit code, wall time, CPU time and peak resident memory of that child
    (``os.wait4`` gives the child's own resource usage)."""
    load = os.getloadavg()[0]
    start = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here, not by Popen
        wall_s = time.perf_counter() - start
        err.seek(0)
        stderr = err.read().decode(errors="replace")
    return {
        "command": " ".join("python" if c == sys.executable else c for c in cmd),
        "exit_code": proc.returncode,
        "stderr_tail": stderr[-300:],
        "wall_s": round(wall_s, 2),
        "cpu_s": round(usage.ru_utime + usage.ru_stime, 2),
        "peak_rss_mb": round(usage.ru_maxrss / 1024, 1),  # Linux reports kB
        "load_avg_1min_before": round(load, 2),
    }


def _write_long_song(path: str | Path, duration_s: float) -> None:
    import soundfile as sf

    from quaddance.music.synth import render_song

    y, _ = render_song(118.0, duration_s, seed=3, sections=8, sr=44100)
    sf.write(str(path), np.stack([y, y], axis=1), 44100, subtype="PCM_16")


def _write_silent_hours(path: str | Path, duration_s: float, sr: int = 8000) -> None:
    """Mostly silence, a click every second, written in blocks (never all in memory)."""
    import soundfile as sf

    block = np.zeros(sr * 60, dtype=np.float32)
    block[::sr] = 0.5
    with sf.SoundFile(str(path), "w", sr, 1, subtype="PCM_U8") as f:
        for _ in range(int(duration_s // 60)):
            f.write(block)


def _make_in_child(writer: str, path: Path, duration_s: float) -> None:
    root = str(Path(__file__).resolve().parents[1])  # the checkout that holds benchmarks/
    code = (
        f"import sys; sys.path.insert(0, {root!r}); from benchmarks.long import {writer}; "
        f"{writer}({str(path)!r}, {duration_s!r})"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


#: What `dance --no-video` must achieve on a song of `MAX_SONG_S`: the median wall time of
#: `LONG_REPEATS` runs on an idle machine, and the peak memory of any run.
TARGET_WALL_S = 90.0
TARGET_PEAK_MB = 1024.0
LONG_REPEATS = 3


def _dance_run(quaddance: list[str], song: Path, out_dir: Path) -> dict[str, Any]:
    """One `dance --no-video` of ``song``: `_run`'s figures and the command's own split."""
    run = _run([*quaddance, "dance", str(song), "--no-video", "--out", str(out_dir)])
    metrics_path = out_dir / "metrics.json"
    if metrics_path.exists():
        metrics = json.loads(metrics_path.read_text())
        split = metrics["timings_s"]
        split["rest_s"] = round(
            split["total_s"] - split["choreography_s"] - split["simulation_s"], 3
        )
        run["split_s"] = split
        run["song_s"] = metrics["duration_s"]
        run["realtime_factor_sim"] = round(metrics["realtime_factor_sim"], 2)
        run["falls"] = len(metrics.get("falls_s", []))
    return run


def summarize_runs(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The median wall and CPU time of ``runs``, their largest peak memory, and whether all
    ran and met `TARGET_WALL_S` (median) and `TARGET_PEAK_MB` (every run)."""
    ok = [r for r in runs if r["exit_code"] == 0]
    if not ok:
        return {"runs": runs, "met": False}
    wall = statistics.median(r["wall_s"] for r in ok)
    peak = max(r["peak_rss_mb"] for r in ok)
    return {
        "wall_median_s": round(wall, 2),
        "cpu_median_s": round(statistics.median(r["cpu_s"] for r in ok), 2),
        "peak_rss_max_mb": peak,
        "met": len(ok) == len(runs) and wall <= TARGET_WALL_S and peak <= TARGET_PEAK_MB,
        "runs": runs,
    }


def run_long_bench(
    out_path: str | Path,
    log: Callable[[str], None] = lambda msg: None,
    repeats: int = LONG_REPEATS,
) -> dict[str, Any]:
    """Run both cases (the long song ``repeats`` times); write and return the results."""
    quaddance = [sys.executable, "-m", "quaddance.cli"]
    results: dict[str, Any] = {
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "machine": platform.machine(),
        },
        "limits": {
            "max_song_s": MAX_SONG_S,
            "target_wall_median_s": TARGET_WALL_S,
            "target_peak_mb": TARGET_PEAK_MB,
            "repeats": repeats,
        },
    }
    with tempfile.TemporaryDirectory() as tmp:
        song = Path(tmp) / "long.wav"
        log(f"writing a {MAX_SONG_S / 60:g}-minute song")
        # In a child: a forked child's peak RSS counts the parent's pages, so the parent
        # must stay small for the figures below to be the command's own.
        _make_in_child("_write_long_song", song, MAX_SONG_S)
        runs = []
        for k in range(repeats):
            log(f"dancing it (no video), run {k + 1} of {repeats}")
            runs.append(_dance_run(quaddance, song, Path(tmp) / f"out{k}"))
        results["dance_20min_no_video"] = summarize_runs(runs)

        silent = Path(tmp) / "two_hours.wav"
        log("writing a 2-hour mostly silent file")
        _make_in_child("_write_silent_hours", silent, 2 * 3600.0)
        log("analysing it (must be refused from its header)")
        results["analyze_2h_silent"] = {
            "file_mb": round(silent.stat().st_size / 2**20, 1),
            **_run([*quaddance, "analyze", str(silent), "-o", f"{tmp}/a.json"]),
        }
    write_json(out_path, results)
    return results
