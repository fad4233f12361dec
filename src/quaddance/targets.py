"""Human foot heights -> front-foot height targets for the robot (FL, FR, RL, RR; rear = 0).

Three modes (`TargetConfig.mode`):

- ``"paper"``: eq. 4 of the paper, ``h0 * h / max(h)`` with one max over both feet. With the
  headline h0 = 2 m most targets are far out of the Go1's reach, and they never return to 0.
- ``"minmax"``: the released code: each foot min-max normalised to [0, 1], times ``scale``.
- ``"feasible"`` (default): targets a quadruped standing on three legs can actually follow.
  See `feasible_targets` for the rules.

All modes resample to ``out_fps`` (the policy's 50 Hz) by linear interpolation or by exact
evaluation of smooth curves, never by picking the nearest frame as the released code did.
This module must not import librosa or `quaddance.music`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.signal import find_peaks, peak_widths

from quaddance.choreo.choreographer import MIN_JERK_PEAK_SPEED, LiftPlan, render_lifts
from quaddance.errors import QuaddanceError

TargetMode = Literal["feasible", "paper", "minmax"]
MODES: tuple[str, ...] = ("feasible", "paper", "minmax")

#: Peak |acceleration| of a minimum-jerk move of height h over duration d is this * h / d^2.
MIN_JERK_PEAK_ACCEL = 10.0 / np.sqrt(3.0)


@dataclass(frozen=True)
class TargetConfig:
    """How human foot heights become robot front-foot targets. Heights in metres."""

    mode: TargetMode = "feasible"
    #: eq. 4's h0; 2 m gave the paper's headline result (the robot reaches about 0.5 m).
    h0_m: float = 2.0
    #: The released code's scale s on min-max normalised heights (0.2 ... 2.5 were tried).
    scale: float = 1.0
    #: Highest front-foot target while standing on three legs: 80 % of the 0.38 m that the
    #: Go1 held in our simulator (`quaddance bench reach`, quasi-static, trunk at 0.32 m);
    #: the margin is for balancing dynamically on the beat. A policy declares the range it
    #: was trained on in its JSON, and `quaddance dance` uses that instead.
    max_height_m: float = 0.30
    #: Fastest vertical foot speed asked for. Chosen below a trotting Go1's swing-foot speed
    #: (1-2 m/s) because the dancer also shifts its weight onto three legs for each lift:
    #: a 0.2 m lift then lasts about 0.75 s, a 0.1 m tap about 0.4 s.
    max_speed_m_s: float = 1.0
    #: Largest vertical foot acceleration asked for (with the speed bound, shapes the lift).
    max_accel_m_s2: float = 10.0
    #: Time both front feet rest on the floor between two lifts, so the robot can shift its
    #: weight from one side to the other. About 8 policy steps at 50 Hz.
    min_ground_s: float = 0.15
    #: Robot lifts lower than this become 0 (below what reads as a dance move). Estimate.
    min_lift_m: float = 0.03
    #: A human lift of this percentile of all lift sizes (both feet) maps to max_height_m;
    #: larger ones are clipped. Robust to one odd jump in a song.
    lift_percentile: float = 90.0
    #: Human bumps less prominent than this are not lifts (capture noise, weight shifts).
    min_prominence_m: float = 0.02
    #: A lift peak this close to a beat is moved onto the beat, s (half the +-70 ms
    #: tolerance of beat-tracking F-measure). 0 keeps the human timing as it is.
    beat_snap_s: float = 0.035
    #: Output rate, Hz: the policy's 50 Hz (sim dt 0.005 s x decimation 4, released code).
    out_fps: float = 50.0

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise QuaddanceError(f"unknown target mode {self.mode!r}; choose one of {MODES}")
        positive = {
            "h0_m": self.h0_m,
            "scale": self.scale,
            "max_height_m": self.max_height_m,
            "max_speed_m_s": self.max_speed_m_s,
            "max_accel_m_s2": self.max_accel_m_s2,
            "out_fps": self.out_fps,
        }
        for name, value in positive.items():
            if not (np.isfinite(value) and value > 0):
                raise QuaddanceError(f"TargetConfig.{name} must be > 0, got {value}")
        non_negative = {
            "min_ground_s": self.min_ground_s,
            "min_lift_m": self.min_lift_m,
            "min_prominence_m": self.min_prominence_m,
            "beat_snap_s": self.beat_snap_s,
        }
        for name, value in non_negative.items():
            if not (np.isfinite(value) and value >= 0):
                raise QuaddanceError(f"TargetConfig.{name} must be >= 0, got {value}")
        if not 0 < self.lift_percentile <= 100:
            raise QuaddanceError(
                f"TargetConfig.lift_percentile must be in (0, 100], got {self.lift_percentile}"
            )


def output_times(n_human: int, human_fps: float, out_fps: float) -> np.ndarray:
    """Sample times of the targets, s: (ceil(n_human / human_fps * out_fps),) from t = 0."""
    n_out = int(np.ceil(n_human / human_fps * out_fps - 1e-9))
    return np.arange(n_out) / out_fps


def resample(values: np.ndarray, fps: float, t_s: np.ndarray) -> np.ndarray:
    """Linearly interpolate rows of ``values`` (T, C) sampled at ``fps`` Hz from t = 0 onto
    times ``t_s`` (N,), s. Returns (N, C); times past the last frame hold its value."""
    src_t = np.arange(values.shape[0]) / fps
    return np.stack([np.interp(t_s, src_t, col) for col in values.T], axis=1)


def robot_targets(
    human_feet_m: np.ndarray,
    human_fps: float,
    beats_s: np.ndarray,
    cfg: TargetConfig | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Turn human foot heights into robot foot-height targets.

    Parameters:
        human_feet_m: (T, 2) left and right foot heights above the floor, m.
        human_fps: their sample rate, Hz.
        beats_s: (B,) beat times, s; only the feasible mode uses them (to snap peaks).
        cfg: the mapping; default `TargetConfig()`.

    Returns:
        time_s: (N,) sample times at ``cfg.out_fps`` from 0, s.
        targets_m: (N, 4) foot-height targets for FL, FR, RL, RR, m; rear columns are 0.
        Human left drives front-left, right drives front-right (released code).
    """
    cfg = cfg or TargetConfig()
    feet = np.asarray(human_feet_m, dtype=np.float64)
    if feet.ndim != 2 or feet.shape[1] != 2 or feet.shape[0] < 1:
        raise QuaddanceError(f"human foot heights must have shape (T, 2), got {feet.shape}")
    if not np.all(np.isfinite(feet)):
        raise QuaddanceError("human foot heights contain NaN or infinite values")
    if not (np.isfinite(human_fps) and human_fps > 0):
        raise QuaddanceError(f"human_fps must be > 0, got {human_fps}")
    beats = np.asarray(beats_s, dtype=np.float64).reshape(-1)
    beats = beats[np.isfinite(beats)]

    t_s = output_times(feet.shape[0], human_fps, cfg.out_fps)
    targets = np.zeros((t_s.size, 4))
    if cfg.mode == "paper":
        peak = feet.max()
        if peak > 0:
            targets[:, :2] = resample(cfg.h0_m * feet / peak, human_fps, t_s)
    elif cfg.mode == "minmax":
        lo, hi = feet.min(axis=0), feet.max(axis=0)
        span = np.where(hi - lo > 0, hi - lo, np.inf)  # a flat foot maps to 0
        targets[:, :2] = resample(cfg.scale * (feet - lo) / span, human_fps, t_s)
    else:
        targets[:, :2] = render_lifts(t_s, feasible_lifts(feet, human_fps, beats, cfg, t_s[-1]))
    return t_s, targets


def min_duration_s(height_m: np.ndarray | float, cfg: TargetConfig) -> np.ndarray:
    """Shortest minimum-jerk rise (or fall) of ``height_m`` within the speed and
    acceleration bounds, s."""
    h = np.asarray(height_m, dtype=np.float64)
    by_speed = MIN_JERK_PEAK_SPEED * h / cfg.max_speed_m_s
    by_accel = np.sqrt(MIN_JERK_PEAK_ACCEL * h / cfg.max_accel_m_s2)
    return np.maximum(by_speed, by_accel)


def max_height_for(duration_s: float, cfg: TargetConfig) -> float:
    """Highest minimum-jerk lift that rises (or falls) in ``duration_s`` within the bounds, m;
    the inverse of `min_duration_s`."""
    if duration_s <= 0:
        return 0.0
    by_speed = cfg.max_speed_m_s * duration_s / MIN_JERK_PEAK_SPEED
    by_accel = cfg.max_accel_m_s2 * duration_s**2 / MIN_JERK_PEAK_ACCEL
    return float(min(by_speed, by_accel))


@dataclass
class _Lift:
    foot: int
    peak_s: float
    height_m: float
    rise_s: float  # wished-for rise and fall: the human's, but never below the bounds
    fall_s: float


def _detect_lifts(
    feet: np.ndarray, fps: float, cfg: TargetConfig
) -> tuple[list[_Lift], np.ndarray, np.ndarray]:
    """Find the human lifts of both feet. Returns the lifts (height = human prominence),
    and each one's half-height interval (start, end), s."""
    lifts: list[_Lift] = []
    starts, ends = [], []
    for foot in (0, 1):
        h = feet[:, foot]
        peaks, props = find_peaks(h, prominence=max(cfg.min_prominence_m, 1e-9))
        if peaks.size == 0:
            continue
        prom = props["prominences"]
        _, _, left, right = peak_widths(
            h,
            peaks,
            rel_height=0.5,
            prominence_data=(prom, props["left_bases"], props["right_bases"]),
        )
        # Sub-frame peak time from a parabola through the peak and its two neighbours.
        y0, y1, y2 = h[peaks - 1], h[peaks], h[np.minimum(peaks + 1, h.size - 1)]
        curv = y0 - 2 * y1 + y2
        safe = np.where(curv < 0, curv, -1.0)
        offset = np.where(curv < 0, np.clip(0.5 * (y0 - y2) / safe, -0.5, 0.5), 0.0)
        peak_s = (peaks + offset) / fps
        # A minimum-jerk rise passes half height half-way, so the human's half-height
        # crossing sits half a rise before the peak.
        for k in range(peaks.size):
            rise = 2.0 * (peak_s[k] - left[k] / fps)
            fall = 2.0 * (right[k] / fps - peak_s[k])
            lifts.append(_Lift(foot, float(peak_s[k]), float(prom[k]), rise, fall))
            starts.append(left[k] / fps)
            ends.append(right[k] / fps)
    return lifts, np.asarray(starts), np.asarray(ends)


def feasible_lifts(
    feet_m: np.ndarray, fps: float, beats_s: np.ndarray, cfg: TargetConfig, end_s: float
) -> LiftPlan:
    """The lifts of the feasible mode (see `robot_targets`), rules in this order:

    1. Lifts: the human bumps of each foot with prominence >= ``min_prominence_m``; a lift's
       size is its prominence, its timing its sub-frame peak and half-height crossings.
    2. Scale: the ``lift_percentile`` of all lift sizes (both feet) maps to
       ``max_height_m``; larger lifts are clipped to it. Lifts below ``min_lift_m`` -> 0.
    3. One front foot up at a time: where two lifts overlap (half-height intervals, either
       foot), the larger is kept (on a tie, the one that started first); the other is dropped.
    4. Beat timing: a peak within ``beat_snap_s`` of a beat moves onto it. Peaks never move
       otherwise; what gives way are heights and durations.
    5. Shape: each lift is a minimum-jerk rise to its peak and fall back to exactly 0, as
       long as the human's but never faster than ``max_speed_m_s`` / ``max_accel_m_s2``
       allow for its height. Between two lifts both feet rest for ``min_ground_s``.
       Where that does not fit, rises and falls shrink towards their bounded minimum; if
       even that does not fit, the smaller lift is lowered until it fits, or dropped if it
       would fall below ``min_lift_m``. Lifts stay within [0, end_s].
    """
    lifts, starts, ends = _detect_lifts(feet_m, fps, cfg)
    empty = np.zeros(0)
    if not lifts:
        return LiftPlan(np.zeros(0, dtype=np.int64), empty, empty, empty, empty)

    sizes = np.array([lift.height_m for lift in lifts])
    ref = np.percentile(sizes, cfg.lift_percentile)
    for lift in lifts:
        lift.height_m = min(lift.height_m / ref, 1.0) * cfg.max_height_m

    # Rule 3: greedy by priority, larger first, then earlier start.
    order = sorted(range(len(lifts)), key=lambda k: (-lifts[k].height_m, starts[k]))
    taken = np.zeros(len(lifts), dtype=bool)
    for k in order:
        if lifts[k].height_m < cfg.min_lift_m:
            continue
        clash = taken & (starts < ends[k]) & (ends > starts[k])
        if not clash.any():
            taken[k] = True
    chosen = [lifts[k] for k in np.flatnonzero(taken)]

    if beats_s.size and cfg.beat_snap_s > 0:
        for lift in chosen:
            nearest = beats_s[np.abs(beats_s - lift.peak_s).argmin()]
            if abs(nearest - lift.peak_s) <= cfg.beat_snap_s:
                lift.peak_s = float(nearest)
    chosen.sort(key=lambda lift: lift.peak_s)

    kept = _fit_in_time(chosen, cfg, end_s)
    return LiftPlan(
        foot=np.array([lift.foot for lift in kept], dtype=np.int64),
        peak_s=np.array([lift.peak_s for lift in kept]),
        height_m=np.array([lift.height_m for lift in kept]),
        rise_s=np.array([lift.rise_s for lift in kept]),
        fall_s=np.array([lift.fall_s for lift in kept]),
    )


def _fit_in_time(lifts: list[_Lift], cfg: TargetConfig, end_s: float) -> list[_Lift]:
    """Rule 5 of `feasible_lifts` on time-sorted lifts; returns the kept ones, with final
    heights, rises and falls."""
    wish = {id(lift): (lift.rise_s, lift.fall_s) for lift in lifts}

    def fits_alone(lift: _Lift, room_s: float) -> bool:
        """Lower ``lift`` until a rise or fall of ``room_s`` holds it; False if too small."""
        lift.height_m = min(lift.height_m, max_height_for(room_s, cfg))
        return lift.height_m >= cfg.min_lift_m

    kept: list[_Lift] = []
    for lift in lifts:
        alive = True
        while alive:
            if not kept:
                alive = fits_alone(lift, lift.peak_s)
                if alive:
                    need = float(min_duration_s(lift.height_m, cfg))
                    lift.rise_s = min(max(wish[id(lift)][0], need), lift.peak_s)
                    kept.append(lift)
                break
            prev = kept[-1]
            room = lift.peak_s - prev.peak_s - cfg.min_ground_s
            need_prev = float(min_duration_s(prev.height_m, cfg))
            need_next = float(min_duration_s(lift.height_m, cfg))
            if need_prev + need_next > room:
                # Lower the smaller lift (the later one on a tie) to what the room leaves.
                small, big = (lift, prev) if lift.height_m <= prev.height_m else (prev, lift)
                big_need = need_prev if big is prev else need_next
                if not fits_alone(small, room - big_need):
                    if small is lift:
                        alive = False
                    else:
                        kept.pop()
                    continue
                need_prev = float(min_duration_s(prev.height_m, cfg))
                need_next = float(min_duration_s(lift.height_m, cfg))
            fall = max(wish[id(prev)][1], need_prev)
            rise = max(wish[id(lift)][0], need_next)
            if fall + rise > room:
                # Squeeze the slack above the bounded minimum, both sides alike.
                slack = fall + rise - need_prev - need_next
                # A lowered lift can fill the room exactly: then nothing is left to squeeze.
                squeeze = max(0.0, (room - need_prev - need_next) / slack) if slack > 1e-12 else 0.0
                fall = need_prev + squeeze * (fall - need_prev)
                rise = need_next + squeeze * (rise - need_next)
            prev.fall_s, lift.rise_s = fall, rise
            kept.append(lift)
            break

    # The last lift must be back on the ground by the end.
    while kept:
        last = kept[-1]
        room = end_s - last.peak_s
        if fits_alone(last, room):
            need = float(min_duration_s(last.height_m, cfg))
            last.fall_s = min(max(wish[id(last)][1], need), room)
            # A lowered lift may now be allowed a shorter fall than fixed before; keep it.
            break
        kept.pop()
    return kept
