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

import math
from dataclasses import dataclass

import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.layout import BODY_COLUMNS, FRONT_PAWS, MODES, N_PAWS, TargetMode
from quaddance.lifts import (
    MIN_JERK_PEAK_ACCEL,
    MIN_JERK_PEAK_SPEED,
    LiftPlan,
    min_jerk,
    render_lifts,
)
from quaddance.robots import GO1, BodyLimits, RobotCfg


@dataclass(frozen=True)
class TargetConfig:
    """How human foot heights become targets for ``robot``. Heights in metres.

    ``robot`` is the one source of the limits a dance keeps to: the paw height
    (``max_height_m``, unless given) and the trunk ranges (`RobotCfg.body_four_feet`,
    `RobotCfg.body_paw_up`). To change the robot, make a new config (``replace`` would keep
    the old robot's ``max_height_m``).
    """

    mode: TargetMode = "feasible"
    #: eq. 4's h0; 2 m gave the paper's headline result (the robot reaches about 0.5 m).
    h0_m: float = 2.0
    #: The released code's scale s on min-max normalised heights (0.2 ... 2.5 were tried).
    scale: float = 1.0
    #: Highest front-foot target while standing on three legs; None: the robot's
    #: (`RobotCfg.max_paw_height_m`). A policy declares the range it was trained on in its
    #: JSON, and `quaddance dance` uses that instead.
    max_height_m: float | None = None
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
    #: The robot the targets are for.
    robot: RobotCfg = GO1

    def __post_init__(self) -> None:
        if self.max_height_m is None:
            object.__setattr__(self, "max_height_m", self.robot.max_paw_height_m)
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
    targets = np.zeros((t_s.size, N_PAWS))
    if cfg.mode == "paper":
        peak = feet.max()
        if peak > 0:
            targets[:, FRONT_PAWS] = resample(cfg.h0_m * feet / peak, human_fps, t_s)
    elif cfg.mode == "minmax":
        lo, hi = feet.min(axis=0), feet.max(axis=0)
        span = np.where(hi - lo > 0, hi - lo, np.inf)  # a flat foot maps to 0
        targets[:, FRONT_PAWS] = resample(cfg.scale * (feet - lo) / span, human_fps, t_s)
    else:
        targets[:, FRONT_PAWS] = render_lifts(
            t_s, feasible_lifts(feet, human_fps, beats, cfg, t_s[-1])
        )
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
    # scipy.signal here, not at the top: `dance` imports this module before it starts its
    # helper processes, and scipy.signal costs a second there.
    from scipy.signal import find_peaks, peak_widths

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


# --- body (trunk) targets ---------------------------------------------------------------------


#: Time over which the allowed range blends between the two sets, s (before a lift starts
#: and after it ends), so the range edges never move faster than the trunk may.
BODY_RANGE_BLEND_S = 0.3
#: Share of the range that a human body curve's 98th percentile is scaled to (`fit_body`).
BODY_FIT_SHARE = 0.9


def fit_body(body: np.ndarray, limits: BodyLimits = GO1.body_four_feet) -> np.ndarray:
    """Scale human-unit body curves (T, 4) into the robot's four-feet range ``limits``,
    column by column.

    Each column is multiplied by one gain <= 1 (never amplified), chosen so that its 98th
    percentile of |value| fills `BODY_FIT_SHARE` of the four-feet range (height: of each
    side, the tighter gain). One gain per column keeps the dance's dynamics: quiet stays
    quieter than loud. What still sticks out is clamped by `feasible_body_targets`.
    """
    body = np.asarray(body, dtype=np.float64)
    out = body.copy()
    for c in range(4):
        col = body[:, c]
        gain = 1.0
        for side, bound in ((col[col < 0], -limits.low[c]), (col[col > 0], limits.high[c])):
            if side.size:
                p = float(np.percentile(np.abs(side), 98.0))
                if p > 0 and bound > 0:
                    gain = min(gain, BODY_FIT_SHARE * bound / p)
        out[:, c] = gain * col
    return out


def _paw_up_weight(time_s: np.ndarray, paw_targets_m: np.ndarray | None, min_lift_m: float):
    """(T,) in [0, 1]: 1 where a front paw target is above ``min_lift_m``, blending to 0
    over `BODY_RANGE_BLEND_S` on both sides with a minimum-jerk ramp (C2)."""
    n = time_s.size
    if paw_targets_m is None or n == 0:
        return np.zeros(n)
    up = np.asarray(paw_targets_m, dtype=np.float64)[:, FRONT_PAWS].max(axis=1) > min_lift_m
    if not up.any():
        return np.zeros(n)
    # Distance in time to the nearest paw-up sample, both directions.
    up_t = time_s[up]
    idx = np.clip(np.searchsorted(up_t, time_s), 1, up_t.size) - 1
    nxt = np.clip(idx + 1, 0, up_t.size - 1)
    dist = np.minimum(np.abs(time_s - up_t[idx]), np.abs(time_s - up_t[nxt]))
    return 1.0 - min_jerk(np.clip(dist / BODY_RANGE_BLEND_S, 0.0, 1.0))


def _stop_speed(gap: float, dt: float, a_max: float) -> float:
    """Fastest speed towards a bound ``gap`` away that can still stop before it, braking at
    ``a_max`` in steps of ``dt`` (solves v^2 / 2a + 2 v dt = gap; the 2 v dt covers the
    step taken now and the discretisation of the stop)."""
    if gap <= 0.0:
        return 0.0
    return a_max * (-2.0 * dt + math.sqrt(4.0 * dt * dt + 2.0 * gap / a_max))


def _window_min(x: np.ndarray, width: int) -> np.ndarray:
    """Minimum of ``x[k : k + width]`` for every k (the window is cut at the end)."""
    padded = np.concatenate([x, np.full(width - 1, x[-1])]) if width > 1 else x
    return np.lib.stride_tricks.sliding_window_view(padded, width).min(axis=1)


def _rate_limit(
    x: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    dt: float,
    v_max: float,
    a_max: float,
    vel0: float = 0.0,
) -> np.ndarray:
    """One causal pass: follow ``x`` (T,) inside [low, high] with |velocity| <= v_max and
    |acceleration| <= a_max (finite differences at ``dt``), feeding the target's own
    velocity forward; it starts at ``x[0]`` moving at ``vel0``.

    A target that keeps the bounds is reproduced exactly. Elsewhere the output closes the
    gap as fast as the bounds allow and brakes in time, both for the target (velocity towards
    it at most sqrt(2 a |gap|)) and for the range edges, which it looks at as far ahead as
    a stop from full speed takes.
    """
    n = x.size
    y = np.empty(n)
    if n == 0:
        return y
    ahead = int(np.ceil(v_max / a_max / dt)) + 2
    high_l = _window_min(high, ahead).tolist()
    low_l = (-_window_min(-low, ahead)).tolist()
    xs = x.tolist()
    pos, vel = xs[0], float(vel0)
    y[0] = pos
    dv = a_max * dt
    for k in range(1, n):
        v_ff = (xs[k] - xs[k - 1]) / dt
        gap = xs[k - 1] - pos
        w = min(abs(gap) / dt, math.sqrt(2.0 * a_max * abs(gap)))
        want = v_ff + (w if gap > 0 else -w)
        up = _stop_speed(high_l[k] - pos, dt, a_max)
        down = -_stop_speed(pos - low_l[k], dt, a_max)
        want = min(max(want, down), up)
        vel = min(max(want, vel - dv, -v_max), vel + dv, v_max)
        pos += vel * dt
        y[k] = pos
    return y


def _bounded_smooth(
    x: np.ndarray, low: np.ndarray, high: np.ndarray, dt: float, v_max: float, a_max: float
) -> np.ndarray:
    """Forward-backward `_rate_limit`, averaged: no net lag, and within all bounds (the mean
    of two curves that keep a range and a bound on velocity and acceleration keeps them)."""
    # Already within the bounds (from rest to rest, as the passes start): nothing to do. The
    # passes would give the same; this only saves their time (most choreographed columns).
    vel = np.diff(x, prepend=x[:1], append=x[-1:]) / dt
    if np.all(np.abs(vel) <= v_max) and np.all(np.abs(np.diff(vel)) <= a_max * dt):
        return x.copy()
    fwd = _rate_limit(x, low, high, dt, v_max, a_max)
    bwd = _rate_limit(x[::-1], low[::-1], high[::-1], dt, v_max, a_max)[::-1]
    return 0.5 * (fwd + bwd)


def continue_body_targets(
    body: np.ndarray, sent: np.ndarray, dt: float, robot: RobotCfg = GO1
) -> np.ndarray:
    """(T, 4) body targets that carry on from ``sent`` (the last two rows already final,
    (2, 4)), at steps of ``dt``: each column follows ``body`` from the position and
    velocity that ``sent`` ends with, within the speed and acceleration bounds of
    `feasible_body_targets` and ``robot``'s four-feet range (the causal pass of its filter).
    Where ``body`` keeps the bounds from there, it comes out unchanged; where it would jump (a
    new plan meeting an old one), it is caught up with as fast as the bounds allow."""
    four_feet, paw_up = robot.body_four_feet, robot.body_paw_up
    body = np.asarray(body, dtype=np.float64)
    sent = np.asarray(sent, dtype=np.float64)
    v_max = np.minimum(four_feet.max_speed, paw_up.max_speed)
    a_max = np.minimum(four_feet.max_accel, paw_up.max_accel)
    out = np.empty_like(body)
    for c in range(4):
        x = np.concatenate([sent[-1:, c], body[:, c]])
        low = np.full(x.size, four_feet.low[c])
        high = np.full(x.size, four_feet.high[c])
        vel0 = (sent[-1, c] - sent[-2, c]) / dt
        y = _rate_limit(x, low, high, dt, float(v_max[c]), float(a_max[c]), vel0)
        out[:, c] = y[1:]
    return out


def paw_clamp_report(
    human_feet_m: np.ndarray, human_fps: float, targets_m: np.ndarray, cfg: TargetConfig
) -> dict:
    """What became of the human lifts in the robot's paw targets: counts of lifts (human
    bumps of at least ``cfg.min_prominence_m``; robot peaks above ``cfg.min_lift_m``), how
    many human lifts were above the scale reference (clipped to ``max_height_m``), and the
    highest target, m."""
    from scipy.signal import find_peaks

    feet = np.asarray(human_feet_m, dtype=np.float64)
    lifts, _, _ = _detect_lifts(feet, human_fps, cfg)
    sizes = np.array([lift.height_m for lift in lifts])
    robot = sum(
        int(find_peaks(np.asarray(targets_m)[:, k], height=cfg.min_lift_m)[0].size) for k in (0, 1)
    )
    clipped = 0
    if sizes.size and cfg.mode == "feasible":
        clipped = int(np.count_nonzero(sizes > np.percentile(sizes, cfg.lift_percentile)))
    return {
        "mode": cfg.mode,
        "human_lifts": int(sizes.size),
        "robot_lifts": robot,
        "dropped_or_merged": max(int(sizes.size) - robot, 0),
        "clipped_to_max_height": clipped,
        "max_height_m": float(cfg.max_height_m),
        "highest_target_m": float(np.max(targets_m[:, FRONT_PAWS], initial=0.0)),
    }


def feasible_body_targets(
    body: np.ndarray,
    fps_in: float,
    time_s_out: np.ndarray,
    paw_targets_m: np.ndarray | None = None,
    cfg: TargetConfig | None = None,
) -> tuple[np.ndarray, dict]:
    """Body curves the robot can follow, at the paw targets' times.

    Parameters:
        body: (T_in, 4) body curves in robot units (see `fit_body`), columns `BODY_COLUMNS`,
            sampled at ``fps_in`` Hz from t = 0.
        time_s_out: (T,) output times, s (those of the paw targets).
        paw_targets_m: (T, 4) paw targets at ``time_s_out``; where a front one is above
            ``cfg.min_lift_m`` the robot's paw-up range applies, blended over
            `BODY_RANGE_BLEND_S`; elsewhere its four-feet range.
        cfg: the targets' settings (default `TargetConfig()`): its robot's two ranges
            (`RobotCfg.body_four_feet`, `RobotCfg.body_paw_up`); speed and acceleration
            bounds come from the tighter of the two.

    Rules, in order: resample linearly; clamp each sample to the range at its time; limit
    speed and acceleration (forward-backward, zero net lag) while staying inside the
    range: the filter also brakes before the range edges, so the range holds too.

    Returns:
        body_out: (T, 4) float64.
        report: per column name, ``{"clamped": samples changed by more than 1e-6,
        "max": largest change, "mean": mean change over all samples}`` in the column's
        units, and ``"samples"``: T.
    """
    cfg = cfg or TargetConfig()
    four_feet, paw_up = cfg.robot.body_four_feet, cfg.robot.body_paw_up
    body = np.asarray(body, dtype=np.float64)
    t_out = np.asarray(time_s_out, dtype=np.float64)
    if body.ndim != 2 or body.shape[1] != 4:
        raise QuaddanceError(f"body targets must have shape (T, 4), got {body.shape}")
    if not np.all(np.isfinite(body)):
        raise QuaddanceError("body targets contain NaN or infinite values")
    if not (np.isfinite(fps_in) and fps_in > 0):
        raise QuaddanceError(f"body fps must be > 0, got {fps_in}")
    n = t_out.size
    empty = body.shape[0] == 0 or n == 0
    wanted = np.zeros((n, 4)) if empty else resample(body, fps_in, t_out)
    weight = _paw_up_weight(t_out, paw_targets_m, cfg.min_lift_m)[:, None]
    low = (1 - weight) * four_feet.low + weight * paw_up.low
    high = (1 - weight) * four_feet.high + weight * paw_up.high
    v_max = np.minimum(four_feet.max_speed, paw_up.max_speed)
    a_max = np.minimum(four_feet.max_accel, paw_up.max_accel)
    dt = float(t_out[1] - t_out[0]) if n > 1 else 1.0

    out = np.clip(wanted, low, high)
    for c in range(4):
        smooth = _bounded_smooth(
            out[:, c], low[:, c], high[:, c], dt, float(v_max[c]), float(a_max[c])
        )
        # The filter brakes before the range edges; the clip only removes rounding.
        out[:, c] = np.clip(smooth, low[:, c], high[:, c])

    change = np.abs(out - wanted)
    report: dict = {"samples": int(n)}
    for c, name in enumerate(BODY_COLUMNS):
        report[name] = {
            "clamped": int(np.count_nonzero(change[:, c] > 1e-6)),
            "max": float(change[:, c].max(initial=0.0)),
            "mean": float(change[:, c].mean()) if n else 0.0,
        }
    return out, report
