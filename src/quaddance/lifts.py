"""Minimum-jerk lifts: the shape of every paw lift and trunk gesture.

A lift rises from rest to its peak and falls back to rest along `min_jerk`, so height,
velocity and acceleration stay continuous. The choreographer plans lifts (`LiftPlan`) and
the targets re-plan them within the robot's bounds; both render them with `render_lifts`.
This module sits below both and imports nothing of quaddance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Peak speed of a minimum-jerk move of height h over duration d is this times h / d.
MIN_JERK_PEAK_SPEED = 1.875
#: Peak |acceleration| of a minimum-jerk move of height h over duration d is this * h / d^2.
MIN_JERK_PEAK_ACCEL = 10.0 / np.sqrt(3.0)


@dataclass
class LiftPlan:
    """Lifts as parallel (N,) arrays, in time order: which foot (0 = left, 1 = right), the
    peak time (s), peak height (m), and the rise and fall durations (s)."""

    foot: np.ndarray
    peak_s: np.ndarray
    height_m: np.ndarray
    rise_s: np.ndarray
    fall_s: np.ndarray

    def __len__(self) -> int:
        return int(self.peak_s.size)


def min_jerk(u: np.ndarray) -> np.ndarray:
    """Minimum-jerk blend 10u^3 - 15u^4 + 6u^5 for u in [0, 1]: from 0 to 1 with zero
    velocity and acceleration at both ends. Peak slope 1.875, peak |curvature| 10/sqrt(3)."""
    return u * u * u * (10.0 + u * (-15.0 + 6.0 * u))


def render_lifts(t_s: np.ndarray, plan: LiftPlan, n_feet: int = 2) -> np.ndarray:
    """Sample lift bumps at the sorted times ``t_s`` (T,), s. Returns (T, n_feet) heights, m.

    Each lift rises from 0 at ``peak - rise`` to its height at ``peak`` and falls back to 0
    at ``peak + fall``, both along `min_jerk`; heights are exactly 0 elsewhere. The lifts of
    one foot must not overlap (later ones would overwrite earlier ones).
    """
    t_s = np.asarray(t_s, dtype=np.float64)
    out = np.zeros((t_s.size, n_feet))
    if len(plan) == 0 or t_s.size == 0:
        return out
    lo = np.searchsorted(t_s, plan.peak_s - plan.rise_s, side="left")
    hi = np.searchsorted(t_s, plan.peak_s + plan.fall_s, side="right")
    counts = hi - lo
    ev = np.repeat(np.arange(len(plan)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    idx = np.arange(ev.size) - first + np.repeat(lo, counts)
    dt = t_s[idx] - plan.peak_s[ev]
    u = np.where(dt < 0, 1.0 + dt / plan.rise_s[ev], 1.0 - dt / plan.fall_s[ev])
    out[idx, plan.foot[ev]] = plan.height_m[ev] * min_jerk(np.clip(u, 0.0, 1.0))
    return out
