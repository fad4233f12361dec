"""How well a rollout danced: tracking error, correlation, rear-foot lift and beat alignment.

Pure numpy over arrays; robot feet are in the order (FL, FR, RL, RR) and every height is the
height of the foot's bottom above the floor, in metres.

The *feasible part* of a front foot's target is the set of frames where a robot standing on
its three other legs could follow it: the foot's target lies in ``[0, feasible_max_m]`` and
the other front foot's target is at most ``ground_tol_m`` (that foot is asked to stand). Both
feet down counts as feasible for both. The paper's targets (eq. 4, h0 = 2 m) are mostly
outside this set, so errors are reported on all frames and on the feasible part alone.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.layout import FRONT_PAWS, REAR_PAWS


def default_feasible_max_m() -> float:
    """Highest front-foot target counted as reachable on three legs, m: the feasible target
    mode's ceiling, `quaddance.targets.TargetConfig.max_height_m` (one definition)."""
    from quaddance.targets import TargetConfig  # pulls in scipy; only when needed

    return TargetConfig().max_height_m


GROUND_TOL_M = 0.01
"""A target at most this high asks the foot to stand, m (the foot sphere's contact slop)."""

BAS_SIGMA_S = 0.05
"""Width of the beat-alignment kernel, s: 3 frames at 60 fps (Bailando, FACTS.md section 4)."""

SPEED_SMOOTH_SIGMA_S = 5.0 / 60.0
"""Gaussian smoothing of the motion speed before finding its minima, s: 5 frames at 60 fps
(Bailando's metric code)."""

FRONT_FEET = ("fl", "fr")


def gaussian_smooth(x: np.ndarray, sigma_frames: float) -> np.ndarray:
    """Gaussian-smooth ``x`` along axis 0 with edge-value padding.

    Args:
        x: (T,) or (T, k) signal.
        sigma_frames: kernel standard deviation in frames; 0 returns a copy.

    Returns:
        Array of the same shape, float64.
    """
    x = np.asarray(x, dtype=float)
    if sigma_frames <= 0 or x.shape[0] < 2:
        return x.copy()
    radius = max(1, int(np.ceil(4.0 * sigma_frames)))
    offsets = np.arange(-radius, radius + 1)
    kernel = np.exp(-0.5 * (offsets / sigma_frames) ** 2)
    kernel /= kernel.sum()
    flat = x.reshape(x.shape[0], -1)
    padded = np.pad(flat, ((radius, radius), (0, 0)), mode="edge")
    out = np.stack([np.convolve(col, kernel, mode="valid") for col in padded.T], axis=1)
    return out.reshape(x.shape)


def motion_beats(
    motion_m: np.ndarray, fps: float, smooth_sigma_s: float = SPEED_SMOOTH_SIGMA_S
) -> np.ndarray:
    """Motion beats: times of the local minima of the smoothed mean speed (Bailando).

    Args:
        motion_m: (T, k) coordinates (each column one height or one coordinate, m) or
            (T, J, 3) joint positions, m.
        fps: frame rate of ``motion_m``, Hz.
        smooth_sigma_s: Gaussian smoothing of the speed, s.

    Returns:
        (n,) times in seconds from the first frame. A flat stretch of the speed that is lower
        than both its neighbours counts once, at its middle. The ends never count.
    """
    motion = np.asarray(motion_m, dtype=float)
    if motion.ndim not in (2, 3) or motion.shape[0] < 3:
        raise QuaddanceError(f"motion must be (T, k) or (T, J, 3) with T >= 3, got {motion.shape}")
    if fps <= 0:
        raise QuaddanceError(f"fps must be > 0, got {fps}")
    step = np.diff(motion, axis=0)
    # Per-point speed: norm over xyz for joints, absolute value for single coordinates.
    speed = np.linalg.norm(step, axis=2) if motion.ndim == 3 else np.abs(step)
    speed = gaussian_smooth(speed.mean(axis=1) * fps, smooth_sigma_s * fps)
    # Collapse runs of equal values so that a flat minimum is found once.
    starts = np.flatnonzero(np.r_[True, np.diff(speed) != 0])
    ends = np.r_[starts[1:], len(speed)] - 1
    values = speed[starts]
    runs = np.arange(1, len(values) - 1)
    is_min = (values[runs] < values[runs - 1]) & (values[runs] < values[runs + 1])
    centre = 0.5 * (starts[runs[is_min]] + ends[runs[is_min]])
    # speed[i] is the speed between frames i and i + 1: it belongs to time (i + 0.5) / fps.
    return (centre + 0.5) / fps


def beat_align_score(
    motion_m: np.ndarray,
    fps: float,
    music_beats_s: np.ndarray,
    sigma_s: float = BAS_SIGMA_S,
    smooth_sigma_s: float = SPEED_SMOOTH_SIGMA_S,
) -> float:
    """Beat Align Score (Bailando): how close each music beat is to a motion beat.

    BAS = mean over the music beats inside the motion's time span of
    ``exp(-d^2 / (2 sigma^2))``, d = distance to the nearest motion beat (see `motion_beats`).

    Args:
        motion_m: (T, k) heights or coordinates, or (T, J, 3) joint positions, m.
        fps: frame rate of ``motion_m``, Hz; frame 0 is at time 0.
        music_beats_s: (B,) beat times of the music, s.
        sigma_s: kernel width, s.
        smooth_sigma_s: smoothing of the speed before finding its minima, s.

    Returns:
        Score in [0, 1]; 0 when the motion has no beats; NaN when no music beat falls inside
        the motion's time span.
    """
    beats = np.asarray(music_beats_s, dtype=float).reshape(-1)
    span_s = (np.asarray(motion_m).shape[0] - 1) / fps if fps > 0 else 0.0
    beats = beats[np.isfinite(beats) & (beats >= 0) & (beats <= span_s)]
    found = motion_beats(motion_m, fps, smooth_sigma_s)
    if len(beats) == 0:
        return float("nan")
    if len(found) == 0:
        return 0.0
    dist = np.min(np.abs(beats[:, None] - found[None, :]), axis=1)
    return float(np.mean(np.exp(-(dist**2) / (2.0 * sigma_s**2))))


def feasible_mask(
    targets_m: np.ndarray,
    feasible_max_m: float | None = None,
    ground_tol_m: float = GROUND_TOL_M,
) -> np.ndarray:
    """Frames where each front foot's target is reachable on three legs (see the module doc).

    Args:
        targets_m: (T, 4) foot-height targets (FL, FR, RL, RR), m.
        feasible_max_m: highest reachable front-foot target, m; None: see
            `default_feasible_max_m`.
        ground_tol_m: a target at most this high asks the foot to stand, m.

    Returns:
        (T, 2) bool, columns (FL, FR).
    """
    targets = _check_feet("targets_m", targets_m)
    if feasible_max_m is None:
        feasible_max_m = default_feasible_max_m()
    front = targets[:, FRONT_PAWS]
    in_range = (front >= -ground_tol_m) & (front <= feasible_max_m)
    other_down = np.abs(front[:, ::-1]) <= ground_tol_m
    return in_range & other_down


def pearson(a: np.ndarray, b: np.ndarray) -> float | None:
    """Pearson correlation over the frames where both are finite.

    Returns None when fewer than 2 such frames remain or either signal is constant there
    (the correlation is undefined), so that JSON gets null rather than NaN.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 2:
        return None
    da = a[ok] - a[ok].mean()
    db = b[ok] - b[ok].mean()
    denom = np.sqrt(np.sum(da**2) * np.sum(db**2))
    if denom < 1e-12:
        return None
    return float(np.clip(np.sum(da * db) / denom, -1.0, 1.0))


def _mae(target: np.ndarray, measured: np.ndarray) -> float | None:
    err = np.abs(measured - target)
    err = err[np.isfinite(err)]
    return float(err.mean()) if err.size else None


def tracking_metrics(
    targets_m: np.ndarray, feet_m: np.ndarray, feasible: np.ndarray
) -> dict[str, dict[str, float | None]]:
    """Front-foot tracking error and correlation, on all frames and on the feasible part.

    Args:
        targets_m: (T, 4) targets (FL, FR, RL, RR), m.
        feet_m: (T, 4) measured foot heights, m.
        feasible: (T, 2) bool mask (FL, FR), e.g. from `feasible_mask`.

    Returns:
        ``{"fl": {...}, "fr": {...}}``, each with ``mae_m`` and ``mae_feasible_m`` (mean
        absolute error, m) and ``corr`` and ``corr_feasible`` (Pearson); None where undefined.
    """
    targets = _check_feet("targets_m", targets_m)
    feet = _check_feet("feet_m", feet_m)
    mask = np.asarray(feasible, dtype=bool)
    if targets.shape != feet.shape or mask.shape != (targets.shape[0], 2):
        raise QuaddanceError(
            f"shapes differ: targets {targets.shape}, feet {feet.shape}, feasible {mask.shape}"
        )
    out: dict[str, dict[str, float | None]] = {}
    for i, name in enumerate(FRONT_FEET):
        t, h, m = targets[:, i], feet[:, i], mask[:, i]
        out[name] = {
            "mae_m": _mae(t, h),
            "mae_feasible_m": _mae(t[m], h[m]),
            "corr": pearson(t, h),
            "corr_feasible": pearson(t[m], h[m]),
        }
    return out


#: Body-target columns (`quaddance.layout.BODY_COLUMNS`) and their report units.
BODY_METRIC_COLUMNS: tuple[tuple[str, str], ...] = (
    ("height", "m"),
    ("roll", "deg"),
    ("pitch", "deg"),
    ("yaw", "deg"),
)


def body_metrics(body_targets: np.ndarray, body_measured: np.ndarray) -> dict[str, Any]:
    """Trunk tracking: per column (height m; roll, pitch, yaw deg) the mean absolute error,
    the correlation, and the range (max - min) of the targets and of the measured pose.

    Args:
        body_targets: (T, 4) height offset m, roll, pitch, yaw rad (relative to standing).
        body_measured: (T, 4) the trunk's pose in the same units.
    """
    targets = np.asarray(body_targets, dtype=float)
    measured = np.asarray(body_measured, dtype=float)
    if targets.ndim != 2 or targets.shape[1] != 4 or targets.shape != measured.shape:
        raise QuaddanceError(
            f"body targets and measured pose must both be (T, 4), got {targets.shape} and "
            f"{measured.shape}"
        )
    out: dict[str, Any] = {}
    for i, (name, unit) in enumerate(BODY_METRIC_COLUMNS):
        scale = 1.0 if unit == "m" else 180.0 / np.pi
        t, m = targets[:, i] * scale, measured[:, i] * scale
        out[name] = {
            f"mae_{unit}": _mae(t, m),
            "corr": pearson(t, m),
            f"target_range_{unit}": float(np.ptp(t)) if t.size else None,
            f"measured_range_{unit}": float(np.ptp(m)) if m.size else None,
        }
    angles = [out[n]["mae_deg"] for n, u in BODY_METRIC_COLUMNS if u == "deg"]
    out["angle_mae_deg"] = None if None in angles else float(np.mean(angles))
    return out


def dance_metrics(
    time_s: np.ndarray,
    targets_m: np.ndarray,
    feet_m: np.ndarray,
    beats_s: np.ndarray,
    falls_s: Sequence[float],
    sim_time_s: float,
    render_time_s: float | None,
    feasible_max_m: float | None = None,
    ground_tol_m: float = GROUND_TOL_M,
) -> dict[str, Any]:
    """All metrics of one danced song, JSON-ready (None for undefined values).

    Args:
        time_s: (T,) sample times, s, evenly spaced.
        targets_m: (T, 4) foot-height targets (FL, FR, RL, RR), m.
        feet_m: (T, 4) measured foot heights, m.
        beats_s: (B,) music beat times, s (same clock as ``time_s``).
        falls_s: times at which the robot fell, s.
        sim_time_s: wall-clock seconds the simulation took.
        render_time_s: wall-clock seconds the video took, or None without video.
        feasible_max_m, ground_tol_m: define the feasible part (module doc); pass the
            ceiling the policy's targets were made with (None: `default_feasible_max_m`).

    Returns:
        Keys ``duration_s``, ``falls_s``, ``front`` (``fl``/``fr`` -> ``mae_m``,
        ``mae_feasible_m``, ``corr``, ``corr_feasible``), ``rear_lift_mean_m``,
        ``rear_lift_max_m``, ``bas`` (on the front feet's heights), ``realtime_factor_sim``
        and ``realtime_factor_render`` (song seconds per wall-clock second; above 1 is faster
        than real time; None without video).
    """
    time = np.asarray(time_s, dtype=float).reshape(-1)
    targets = _check_feet("targets_m", targets_m)
    feet = _check_feet("feet_m", feet_m)
    if not (len(time) == targets.shape[0] == feet.shape[0]) or len(time) < 2:
        raise QuaddanceError(
            f"time_s, targets_m and feet_m need the same length >= 2, got "
            f"{len(time)}, {targets.shape[0]}, {feet.shape[0]}"
        )
    dt_s = float(np.median(np.diff(time)))
    if not dt_s > 0:
        raise QuaddanceError("time_s must increase")
    duration_s = float(time[-1] - time[0] + dt_s)
    feasible = feasible_mask(targets, feasible_max_m, ground_tol_m)
    rear = feet[:, REAR_PAWS]
    # Lift is height above the floor; soft-contact penetration (< 0) is no lift.
    rear = np.clip(rear[np.isfinite(rear)], 0.0, None)
    bas = beat_align_score(
        feet[:, FRONT_PAWS], 1.0 / dt_s, np.asarray(beats_s, dtype=float) - time[0]
    )
    return {
        "duration_s": duration_s,
        "falls_s": [float(t) for t in falls_s],
        "front": tracking_metrics(targets, feet, feasible),
        "rear_lift_mean_m": float(rear.mean()) if rear.size else None,
        "rear_lift_max_m": float(rear.max()) if rear.size else None,
        "bas": None if np.isnan(bas) else bas,
        "realtime_factor_sim": _rate(duration_s, sim_time_s),
        "realtime_factor_render": None
        if render_time_s is None
        else _rate(duration_s, render_time_s),
    }


def _rate(duration_s: float, wall_s: float) -> float | None:
    return float(duration_s / wall_s) if wall_s and wall_s > 0 else None


def _check_feet(name: str, values: np.ndarray) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise QuaddanceError(f"{name} must be (T, 4) heights (FL, FR, RL, RR), got {arr.shape}")
    return arr


def _fmt(value: Any, unit: str = "", scale: float = 1.0, digits: int = 3) -> str:
    if value is None:
        return "n/a"
    return f"{value * scale:.{digits}f}{unit}"


def summary_table(metrics: Mapping[str, Any]) -> Any:
    """A one-screen `rich.table.Table` of `dance_metrics` output (print it with rich)."""
    from rich.table import Table

    table = Table(title="Dance metrics", show_header=True, header_style="bold")
    table.add_column("metric")
    table.add_column("FL", justify="right")
    table.add_column("FR", justify="right")
    front = metrics["front"]
    rows = [
        ("MAE, all frames", "mae_m", " cm", 100.0, 1),
        ("MAE, feasible part", "mae_feasible_m", " cm", 100.0, 1),
        ("correlation, all", "corr", "", 1.0, 2),
        ("correlation, feasible", "corr_feasible", "", 1.0, 2),
    ]
    for label, key, unit, scale, digits in rows:
        table.add_row(
            label,
            _fmt(front["fl"][key], unit, scale, digits),
            _fmt(front["fr"][key], unit, scale, digits),
        )
    table.add_section()
    falls = metrics["falls_s"]
    fall_text = f"{len(falls)}" + (f" (first at {falls[0]:.1f} s)" if falls else "")
    for label, text in [
        ("duration", _fmt(metrics["duration_s"], " s", 1.0, 1)),
        ("falls", fall_text),
        (
            "rear lift mean / max",
            f"{_fmt(metrics['rear_lift_mean_m'], ' cm', 100.0, 1)} / "
            f"{_fmt(metrics['rear_lift_max_m'], ' cm', 100.0, 1)}",
        ),
        ("beat align score", _fmt(metrics["bas"], "", 1.0, 3)),
        ("real-time factor, sim", _fmt(metrics["realtime_factor_sim"], "x", 1.0, 1)),
        ("real-time factor, video", _fmt(metrics["realtime_factor_render"], "x", 1.0, 2)),
    ]:
        table.add_row(label, text, "")
    return table


def whole_body_metrics(result, beats_s, standing_height_m: float) -> dict[str, Any]:
    """metrics.json's ``body`` (trunk tracking, `play.metrics.body_metrics`) and
    ``beat_coverage`` (fraction of beats with a motion accent of the robot, paws or trunk, as
    measured in the simulator, within +-100 ms). `dance`, `deploy` and `live` all use it."""
    measured = result.body_measured(standing_height_m)
    return body_and_coverage(result.time_s, result.feet_m, result.body_targets, measured, beats_s)


def body_and_coverage(
    time_s: np.ndarray,
    feet_m: np.ndarray,
    body_targets: np.ndarray,
    body_measured: np.ndarray,
    beats_s: np.ndarray,
) -> dict[str, Any]:
    """`whole_body_metrics` over plain arrays (what `dance` sends to its helper process):
    ``feet_m`` (T, 4) measured foot heights, ``body_targets`` and ``body_measured`` (T, 4)."""
    from quaddance.choreo.accents import BEAT_TOLERANCE_S, beat_coverage, motion_accents_s

    accents = motion_accents_s(time_s, feet_m, body_measured)
    if len(time_s):  # the beats the dance spans: a motion may end before the song does
        beats_s = beats_s[
            (beats_s >= time_s[0] - BEAT_TOLERANCE_S) & (beats_s <= time_s[-1] + BEAT_TOLERANCE_S)
        ]
    return {
        "body": body_metrics(body_targets, body_measured),
        # None without music beats (a motion file alone): nothing to cover.
        "beat_coverage": beat_coverage(accents, beats_s) if len(beats_s) else None,
    }
