"""`quaddance bench ff-ablation`: training without the front-lift feed-forward, next to the
shipped run, against the error of standing still.

Standing still (all four feet down) scores a front-foot error equal to the mean front target
of the bank; a run whose error settles there has learned to stand, not to dance (the
paper's "reward hacking", section 4.3.3).
"""

from __future__ import annotations

import csv
import gzip
import io
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import InputFileError
from quaddance.fileio import atomic_path, write_json

#: Points of comparison, env steps.
AT_ENV_STEPS: tuple[int, ...] = (250_000, 500_000, 1_000_000, 1_500_000, 2_000_000)


def read_curve(path: Path) -> dict[str, np.ndarray]:
    """A run's `curve.csv` (or `.csv.gz`) as columns of floats."""
    try:
        raw = path.read_bytes()
        text = gzip.decompress(raw).decode() if path.suffix == ".gz" else raw.decode()
        rows = list(csv.DictReader(io.StringIO(text)))
        cols = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    except (OSError, ValueError, IndexError, KeyError, gzip.BadGzipFile, EOFError) as err:
        raise InputFileError(path, f"not a readable learning curve ({err})") from err
    if "env_steps" not in cols or "front_abs_err_m" not in cols:
        raise InputFileError(path, "learning curve lacks env_steps or front_abs_err_m")
    return cols


def _window_mean(cols: dict[str, np.ndarray], key: str, at: int, width: int) -> float | None:
    """Mean of ``key`` over the iterations within ``width`` env steps before ``at``."""
    steps = cols["env_steps"]
    if steps[-1] < at:
        return None
    inside = (steps <= at) & (steps > at - width)
    return float(cols[key][inside].mean()) if inside.any() else None


def compare(
    no_ff_curve: Path, bank: Path, shipped_curve: Path, width: int = 100_000
) -> dict[str, Any]:
    """Numbers of both runs at `AT_ENV_STEPS` (means over the last ``width`` env steps)."""
    runs = {"without feed-forward": read_curve(no_ff_curve), "shipped": read_curve(shipped_curve)}
    targets = np.load(bank, allow_pickle=False)[..., :2]
    out: dict[str, Any] = {
        "standing_still_front_err_m": float(np.abs(targets).mean()),
        "bank": str(bank),
        "window_env_steps": width,
        "runs": {},
    }
    for name, cols in runs.items():
        out["runs"][name] = {
            "env_steps": int(cols["env_steps"][-1]),
            "at": [
                {
                    "env_steps": at,
                    **{
                        key: _window_mean(cols, key, at, width)
                        for key in (
                            "front_abs_err_m",
                            "rear_lift_m",
                            "fall_rate",
                            "reward_per_step",
                        )
                    },
                }
                for at in AT_ENV_STEPS
            ],
        }
    return out


def plot_compare(path: Path, no_ff_curve: Path, shipped_curve: Path, standing_m: float) -> Path:
    """Front-foot error of both runs over the first env steps of the shorter-lived one,
    with the standing-still error as a line."""
    from quaddance.play.plots import _pyplot, _save  # the project's headless, atomic savefig

    plt = _pyplot()
    no_ff, shipped = read_curve(no_ff_curve), read_curve(shipped_curve)
    end = no_ff["env_steps"][-1]
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for cols, label, colour in (
        (shipped, "with feed-forward (shipped run)", "tab:blue"),
        (no_ff, "without feed-forward", "tab:red"),
    ):
        keep = cols["env_steps"] <= end
        steps_m = cols["env_steps"][keep] / 1e6
        for ax, key in zip(axes, ("front_abs_err_m", "rear_lift_m"), strict=True):
            y = 100.0 * cols[key][keep]
            k = max(1, int(keep.sum()) // 40)
            ax.plot(steps_m, y, color=colour, alpha=0.25, lw=0.8)
            ax.plot(
                steps_m[k - 1 :], np.convolve(y, np.ones(k) / k, "valid"), color=colour, label=label
            )
    axes[0].axhline(100.0 * standing_m, color="0.3", ls="--", label="standing still")
    axes[0].set_ylabel("front-foot |h - h*| (cm)")
    axes[1].set_ylabel("rear-foot lift (cm)")
    axes[1].set_xlabel("env steps (millions)")
    axes[0].legend(frameon=False, fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    _save(fig, path)
    return path


def run_ablation(run_dir: Path, shipped_curve: Path, out_json: Path, docs_dir: Path) -> dict:
    """Copy the run's curve into ``docs_dir``, plot it beside the shipped run, write JSON."""
    from quaddance.play.plots import plot_learning_curve

    curve = run_dir / "curve.csv"
    bank = run_dir / "bank.npy"
    for path in (curve, bank):
        if not path.is_file():
            raise InputFileError(path, "missing: train with --no-feedforward into this run dir")
    result = compare(curve, bank, shipped_curve)
    with atomic_path(docs_dir / "learning_curve_no_feedforward.csv") as tmp:
        tmp.write_bytes(curve.read_bytes())
    plot_learning_curve(docs_dir / "learning_curve_no_feedforward.png", curve)
    plot_compare(
        docs_dir / "learning_curve_ff_ablation.png",
        curve,
        shipped_curve,
        result["standing_still_front_err_m"],
    )
    write_json(out_json, result)
    return result
