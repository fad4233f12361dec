"""Plots: the paper's Fig. 4 (target and measured front-foot heights) and the eval report.

Matplotlib with the Agg backend (no display needed); files are written atomically.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.fileio import atomic_path
from quaddance.layout import FRONT_PAWS

DPI = 120
FOOT_COLOURS = {"FL": "tab:orange", "FR": "tab:blue", "RL": "tab:green", "RR": "tab:purple"}
BEAT_COLOUR = "0.85"


def subplots(nrows: int, ncols: int = 1, **kwargs: Any) -> tuple[Any, Any]:
    """A figure and its axes, as ``pyplot.subplots`` (``figsize``, ``constrained_layout``
    and the rest go to `Figure`, ``sharex`` to `Figure.subplots`), without pyplot: no global
    figure state, no GUI backend, and 0.4 s less CPU to import (measured)."""
    from matplotlib.figure import Figure

    share = {k: kwargs.pop(k) for k in ("sharex", "sharey") if k in kwargs}
    fig = Figure(**kwargs)
    return fig, fig.subplots(nrows, ncols, **share)


def preload() -> None:
    """Import what drawing and saving a figure needs (0.8 s CPU, measured), for a caller that
    has an idle moment before it plots."""
    import matplotlib.backends.backend_agg  # what savefig of a .png uses
    import matplotlib.figure  # noqa: F401


def save_figure(fig: Any, path: str | Path) -> None:
    """Write ``fig`` to ``path`` (format from its suffix, png without one) atomically, at
    `DPI`."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=DPI, format=Path(path).suffix.lstrip(".") or "png")


def plot_feet(
    path: str | Path,
    time_s: np.ndarray,
    targets_m: np.ndarray,
    feet_m: np.ndarray,
    beats_s: np.ndarray,
    title: str = "",
    body_targets: np.ndarray | None = None,
    body_measured: np.ndarray | None = None,
) -> Path:
    """Fig. 4 of the paper: target (dashed) and measured (solid) foot heights over time.

    Three stacked panels: front-left, front-right, and both rear feet (whose target is 0);
    with ``body_targets`` and ``body_measured`` ((T, 4): height offset m, roll, pitch, yaw
    rad) a fourth panel shows the trunk: height offset in cm and the angles in degrees.
    Beats are light vertical lines.

    Args:
        path: output image (.png, .pdf, .svg).
        time_s: (T,) sample times, s.
        targets_m: (T, 4) targets (FL, FR, RL, RR), m.
        feet_m: (T, 4) measured foot heights, m.
        beats_s: (B,) beat times, s.
        title: figure title.

    Returns:
        ``path`` as a Path.
    """
    time = np.asarray(time_s, dtype=float).reshape(-1)
    targets = np.asarray(targets_m, dtype=float)
    feet = np.asarray(feet_m, dtype=float)
    if targets.shape != (len(time), 4) or feet.shape != (len(time), 4):
        raise QuaddanceError(
            f"plot_feet needs targets_m and feet_m of shape ({len(time)}, 4), "
            f"got {targets.shape} and {feet.shape}"
        )
    beats = np.asarray(beats_s, dtype=float).reshape(-1)
    beats = beats[(beats >= time[0]) & (beats <= time[-1])] if len(time) else beats

    body = body_targets is not None and body_measured is not None
    fig, axes = subplots(
        4 if body else 3,
        1,
        figsize=(10, 8.5 if body else 6.5),
        sharex=True,
    )
    # Fixed margins: constrained layout was about half of this plot's time (profiled), and
    # the panels' labels never change length.
    fig.subplots_adjust(left=0.075, right=0.985, top=0.95, bottom=0.06, hspace=0.12)
    front_top_m = max(
        float(np.nanmax(targets[:, FRONT_PAWS], initial=0.0)),
        float(np.nanmax(feet[:, FRONT_PAWS], initial=0.0)),
        0.05,
    )
    for ax, i, name in [(axes[0], 0, "FL"), (axes[1], 1, "FR")]:
        colour = FOOT_COLOURS[name]
        ax.plot(time, targets[:, i], "--", color=colour, lw=1.3, label="target")
        ax.plot(time, feet[:, i], "-", color=colour, lw=1.3, alpha=0.9, label="measured")
        ax.set_ylabel(f"{name} height (m)")
        ax.set_ylim(-0.02, 1.3 * front_top_m)  # headroom for the legend
        ax.legend(loc="upper right", fontsize=8, frameon=False, ncol=2)
    rear_ax = axes[2]
    for i, name in [(2, "RL"), (3, "RR")]:
        rear_ax.plot(time, feet[:, i], "-", color=FOOT_COLOURS[name], lw=1.2, label=name)
    rear_ax.axhline(0.0, color="0.3", ls="--", lw=1.0, label="target")
    # At least 5 cm of scale, so that millimetre jitter does not look like a lift.
    rear_lo = min(-0.01, float(np.nanmin(feet[:, 2:], initial=0.0)))
    rear_hi = max(0.05, 1.3 * float(np.nanmax(feet[:, 2:], initial=0.0)))
    rear_ax.set_ylim(rear_lo, rear_hi)
    rear_ax.set_ylabel("rear height (m)")
    rear_ax.set_xlabel("time (s)")
    rear_ax.legend(loc="upper right", fontsize=8, frameon=False, ncol=3)
    if body:
        _body_panel(
            axes[3], time, np.asarray(body_targets, float), np.asarray(body_measured, float)
        )
        rear_ax.set_xlabel("")
    for ax in axes:
        # One collection per panel: an axvline per beat took 35 s for a 20-minute song.
        ax.vlines(
            beats, 0, 1, transform=ax.get_xaxis_transform(), colors=BEAT_COLOUR, lw=0.8, zorder=0
        )
        ax.grid(axis="y", alpha=0.3)
        if len(time):
            ax.set_xlim(time[0], time[-1])
    if title:
        fig.suptitle(textwrap.fill(title, 100))  # a motion's source can be long
    save_figure(fig, path)
    return Path(path)


#: Trunk curves of the body panel: (column, label, scale to the plotted unit, colour).
BODY_CURVES = (
    (0, "height (cm)", 100.0, "#444444"),
    (1, "roll (deg)", float(np.rad2deg(1.0)), "#1f77b4"),
    (2, "pitch (deg)", float(np.rad2deg(1.0)), "#d62728"),
    (3, "yaw (deg)", float(np.rad2deg(1.0)), "#2ca02c"),
)


def _body_panel(ax, time: np.ndarray, targets: np.ndarray, measured: np.ndarray) -> None:
    """The trunk's pose: target dashed, measured solid, one colour per column."""
    for col, label, scale, colour in BODY_CURVES:
        ax.plot(time, targets[:, col] * scale, "--", color=colour, lw=1.0)
        ax.plot(time, measured[:, col] * scale, "-", color=colour, lw=1.1, alpha=0.9, label=label)
    ax.set_ylabel("trunk (cm, deg)")
    ax.set_xlabel("time (s)")
    # Framed: the trunk curves fill the panel, and the legend must stay legible over them.
    ax.legend(loc="upper right", fontsize=8, ncol=4, title="dashed: target", title_fontsize=8,
              framealpha=0.85, edgecolor="none")  # fmt: skip


def _get(row: Mapping[str, Any], *keys: str) -> float:
    value: Any = row
    for key in keys:
        if not isinstance(value, Mapping) or value.get(key) is None:
            return float("nan")
        value = value[key]
    return float(value)


def plot_eval(path: str | Path, rows: Sequence[Mapping[str, Any]]) -> Path:
    """Eval report: per item, front-foot MAE, correlation, rear-foot lift and beat align
    score as bars.

    Args:
        path: output image.
        rows: one mapping per evaluated item: ``"name"`` plus the keys of
            `quaddance.play.metrics.dance_metrics` (``front``, ``bas``, ``falls_s``, ...).
            Missing or None values leave a gap.

    Returns:
        ``path`` as a Path.
    """
    if not rows:
        raise QuaddanceError("plot_eval needs at least one row")
    names = [str(row.get("name", f"item {i}")) for i, row in enumerate(rows)]
    x = np.arange(len(rows))
    width = 0.2
    series = [
        ("fl", "", "FL all", FOOT_COLOURS["FL"], None),
        ("fl", "_feasible", "FL feasible", FOOT_COLOURS["FL"], "//"),
        ("fr", "", "FR all", FOOT_COLOURS["FR"], None),
        ("fr", "_feasible", "FR feasible", FOOT_COLOURS["FR"], "//"),
    ]

    fig, axes = subplots(
        4, 1, figsize=(max(6.0, 1.2 * len(rows) + 3.0), 10), sharex=True, constrained_layout=True
    )
    for ax, key, label in [(axes[0], "mae", "MAE (cm)"), (axes[1], "corr", "correlation")]:
        scale = 100.0 if key == "mae" else 1.0
        for j, (foot, suffix, legend, colour, hatch) in enumerate(series):
            field = f"mae{suffix}_m" if key == "mae" else f"corr{suffix}"
            values = [scale * _get(row, "front", foot, field) for row in rows]
            ax.bar(
                x + (j - 1.5) * width,
                values,
                width,
                color=colour,
                hatch=hatch,
                alpha=0.55 if hatch else 0.9,
                edgecolor="white",
                label=legend,
            )
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=8, frameon=False, ncol=4)
    axes[1].axhline(0.0, color="0.3", lw=0.8)
    axes[1].set_ylim(-1.0, 1.0)

    # Rear feet should stay down (eq. 3): mean and worst lift.
    for j, (key, legend, alpha) in enumerate(
        [("rear_lift_mean_m", "mean", 0.9), ("rear_lift_max_m", "max", 0.45)]
    ):
        values = [100.0 * _get(row, key) for row in rows]
        axes[2].bar(x + (j - 0.5) * width, values, width, color="tab:green", alpha=alpha)
        axes[2].bar(0, 0, 0, color="tab:green", alpha=alpha, label=legend)  # legend entry
    axes[2].set_ylabel("rear-foot lift (cm)")
    axes[2].legend(fontsize=8, frameon=False, ncol=2)
    axes[2].grid(axis="y", alpha=0.3)

    bas = [_get(row, "bas") for row in rows]
    axes[3].bar(x, bas, 0.5, color="tab:gray")
    for xi, row in zip(x, rows, strict=True):
        falls = row.get("falls_s") or []
        if falls:
            axes[3].annotate(
                f"{len(falls)} fall(s)", (xi, 0.02), ha="center", fontsize=8, color="tab:red"
            )
    axes[3].set_ylabel("beat align score")
    axes[3].set_ylim(0.0, 1.0)
    axes[3].set_xticks(x, names, rotation=20, ha="right")
    axes[3].grid(axis="y", alpha=0.3)
    save_figure(fig, path)
    return Path(path)


def plot_learning_curve(path: str | Path, curve_csv: str | Path) -> Path:
    """Training curve from a run's `curve.csv`: front-foot tracking error, falls per ended
    episode and rear-foot lift against env steps (bottom axis) and wall-clock minutes (top)."""
    import csv

    with Path(curve_csv).open() as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise QuaddanceError(f"{curve_csv}: no rows to plot")
    col = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    steps_m = col["env_steps"] / 1e6
    fig, axes = subplots(3, 1, figsize=(9, 7), sharex=True)
    series = [
        ("front_abs_err_m", 100.0, "front-foot |h - h*| (cm)"),
        ("fall_rate", 1.0, "falls per ended episode"),
        ("rear_lift_m", 100.0, "rear-foot lift (cm)"),
    ]
    marker = "o" if len(rows) == 1 else ""  # one iteration: a point, not a line
    for ax, (key, scale, label) in zip(axes, series, strict=True):
        ax.plot(steps_m, col[key] * scale, color="0.75", lw=0.8)
        k = max(1, len(rows) // 50)  # running mean over about 2 % of the run
        smooth = np.convolve(col[key] * scale, np.ones(k) / k, mode="valid")
        ax.plot(steps_m[k - 1 :], smooth, color="tab:blue", lw=1.6, marker=marker)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("env steps (millions)")
    if len(rows) > 1:  # minutes against steps needs two points
        top = axes[0].secondary_xaxis(
            "top",
            functions=(
                lambda s: np.interp(s, steps_m, col["wall_s"] / 60.0),
                lambda m: np.interp(m, col["wall_s"] / 60.0, steps_m),
            ),
        )
        top.set_xlabel("wall-clock minutes of training")
    fig.tight_layout()
    save_figure(fig, path)
    return Path(path)
