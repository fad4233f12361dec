"""Choreography speed: seconds to dance and to make robot targets for 3 minutes of music.

The music is a synthetic grid (audio analysis is excluded: it is the beat benchmark's
business). Each timing is the median of a few runs after one warm-up run.
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.choreo.choreographer import choreograph
from quaddance.choreo.grid import synthetic_grid
from quaddance.fileio import write_json
from quaddance.layout import CHOREO_FPS
from quaddance.pipeline import target_bank
from quaddance.targets import TargetConfig, robot_targets


def _median_s(fn: Callable[[], Any], repeats: int) -> float:
    """Median wall time of ``fn()`` over ``repeats`` runs after one warm-up, s."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def run_choreograph_bench(
    out_path: str | Path,
    duration_s: float = 180.0,
    tempi_bpm: tuple[float, ...] = (90.0, 120.0, 150.0),
    repeats: int = 5,
    bank_size: int = 64,
    bank_duration_s: float = 20.0,
) -> dict[str, Any]:
    """Time the choreographer and every target mode on ``duration_s`` of music per tempo,
    and the training target bank per sequence; write the results to ``out_path`` as JSON."""
    rows = []
    for tempo_bpm in tempi_bpm:
        grid = synthetic_grid(tempo_bpm, duration_s, np.random.default_rng(0))
        feet_m = choreograph(grid, seed=0, fps=CHOREO_FPS)
        row: dict[str, Any] = {
            "tempo_bpm": tempo_bpm,
            "n_beats": int(grid.beats_s.size),
            "choreograph_s": _median_s(
                lambda g=grid: choreograph(g, seed=0, fps=CHOREO_FPS), repeats
            ),
        }
        for mode in ("feasible", "paper", "minmax"):
            cfg = TargetConfig(mode=mode)
            row[f"targets_{mode}_s"] = _median_s(
                lambda f=feet_m, b=grid.beats_s, c=cfg: robot_targets(f, CHOREO_FPS, b, c), repeats
            )
        rows.append({k: round(v, 5) if isinstance(v, float) else v for k, v in row.items()})

    t0 = time.perf_counter()
    target_bank(bank_size, bank_duration_s, seed=0)
    bank_s = time.perf_counter() - t0

    results = {
        "benchmark": "choreograph",
        "what": f"seconds for {duration_s:.0f} s of music from a beat grid, analysis excluded; "
        f"median of {repeats} runs",
        "duration_s": duration_s,
        "choreo_fps": CHOREO_FPS,
        "choreograph_s_median": round(statistics.median(r["choreograph_s"] for r in rows), 5),
        "targets_feasible_s_median": round(
            statistics.median(r["targets_feasible_s"] for r in rows), 5
        ),
        "bank_s_per_sequence": round(bank_s / bank_size, 5),
        "bank_sequence_s": bank_duration_s,
        "per_tempo": rows,
        "machine": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "cpu": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(),
        },
    }
    write_json(out_path, results)
    return results
