"""`quaddance bench ff-ablation`: training without the front-lift feed-forward, next to the
shipped run, against the error of standing still.

Standing still (all four feet down) scores a front-foot error equal to the mean front target
of the bank; a run whose error settles there has learned to stand, not to dance (the
paper's "reward hacking", section 4.3.3).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import InputFileError
from quaddance.fileio import atomic_path, write_json
from quaddance.train import read_curve

#: Points of comparison, env steps.
AT_ENV_STEPS: tuple[int, ...] = (250_000, 500_000, 1_000_000, 1_500_000, 2_000_000)


def _window_mean(cols: dict[str, np.ndarray], key: str, at: int, width: int) -> float | None:
    """Mean of ``key`` over the iterations within ``width`` env steps before ``at``."""
    steps = cols["env_steps"]
    if steps[-1] < at:
        return None
    inside = (steps <= at) & (steps > at - width)
    return float(cols[key][inside].mean()) if inside.any() else None


def compare(curves: dict[str, Path], bank: Path, width: int = 100_000) -> dict[str, Any]:
    """Numbers of each labelled run at `AT_ENV_STEPS` (means over the last ``width`` env
    steps), and the front-foot error of standing still on ``bank``."""
    targets = np.load(bank, allow_pickle=False)[..., :2]
    out: dict[str, Any] = {
        "standing_still_front_err_m": float(np.abs(targets).mean()),
        "bank": str(bank),
        "window_env_steps": width,
        "runs": {},
    }
    keys = ("front_abs_err_m", "rear_lift_m", "fall_rate", "reward_per_step")
    for name, path in curves.items():
        cols = read_curve(path)
        out["runs"][name] = {
            "curve": str(path),
            "env_steps": int(cols["env_steps"][-1]),
            "at": [
                {"env_steps": at, **{k: _window_mean(cols, k, at, width) for k in keys}}
                for at in AT_ENV_STEPS
            ],
        }
    return out


#: Line colours of the comparison plot, in the order of the curves.
COLOURS = ("tab:red", "tab:green", "tab:blue")


def plot_compare(path: Path, curves: dict[str, Path], standing_m: float) -> Path:
    """Front-foot error and rear lift of each labelled run over the env steps of the first
    one, with the standing-still error as a line."""
    from quaddance.play.plots import save_figure, subplots

    cols_by_name = {name: read_curve(p) for name, p in curves.items()}
    end = next(iter(cols_by_name.values()))["env_steps"][-1]
    fig, axes = subplots(2, 1, figsize=(8, 6), sharex=True)
    for (label, cols), colour in zip(cols_by_name.items(), COLOURS, strict=False):
        keep = cols["env_steps"] <= end
        steps_m = cols["env_steps"][keep] / 1e6
        for ax, key in zip(axes, ("front_abs_err_m", "rear_lift_m"), strict=True):
            y = 100.0 * cols[key][keep]
            k = max(1, int(keep.sum()) // 40)
            ax.plot(steps_m, y, color=colour, alpha=0.25, lw=0.8)
            smooth = np.convolve(y, np.ones(k) / k, "valid")
            ax.plot(steps_m[k - 1 :], smooth, color=colour, label=label)
    axes[0].axhline(
        100.0 * standing_m, color="0.3", ls="--", label="standing still (mean |target|)"
    )
    axes[0].set_ylabel("front-foot |h - h*| (cm)")
    axes[1].set_ylabel("rear-foot lift (cm)")
    axes[1].set_xlabel("env steps (millions); training rollouts, exploration noise included")
    axes[0].legend(frameon=False, fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)
    return path


def run_ablation(
    run_dir: Path,
    shipped_curve: Path,
    out_json: Path,
    docs_dir: Path,
    with_ff_run: Path | None = None,
) -> dict:
    """Copy the no-feed-forward run's curve into ``docs_dir`` (csv + its learning-curve plot),
    compare it with ``with_ff_run`` (a run with the feed-forward and otherwise the same
    settings, if given) and the shipped run, plot all, write JSON."""
    from quaddance.play.plots import plot_learning_curve

    curve = run_dir / "curve.csv"
    bank = run_dir / "bank.npy"
    for path in (curve, bank):
        if not path.is_file():
            raise InputFileError(path, "missing: train with --no-feedforward into this run dir")
    curves = {"without feed-forward": curve}
    if with_ff_run is not None:
        curves["with feed-forward, same settings"] = with_ff_run / "curve.csv"
    curves["with feed-forward (shipped run)"] = shipped_curve
    result = compare(curves, bank)
    with atomic_path(docs_dir / "learning_curve_no_feedforward.csv") as tmp:
        tmp.write_bytes(curve.read_bytes())
    plot_learning_curve(docs_dir / "learning_curve_no_feedforward.png", curve)
    if with_ff_run is not None:
        with atomic_path(docs_dir / "learning_curve_with_feedforward.csv") as tmp:
            tmp.write_bytes((with_ff_run / "curve.csv").read_bytes())
    plot_compare(
        docs_dir / "learning_curve_ff_ablation.png", curves, result["standing_still_front_err_m"]
    )
    write_json(out_json, result)
    return result
