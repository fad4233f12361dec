"""Visible motion accents of a dance and how many beats they cover.

An accent is a moment a viewer reads as "the robot hit the beat":

- a paw lift peak: a local maximum of a front paw target above `ACCENT_MIN_LIFT_M`;
- a body extremum: a local maximum or minimum of a trunk column (where its motion turns
  round) whose prominence is at least the visibility threshold of that column,
  `ACCENT_MIN_HEIGHT_M` (1 cm) or `ACCENT_MIN_ANGLE_RAD` (2 degrees). A held pose (a flat
  stretch longer than `ACCENT_MAX_HOLD_S`) is a rest, not an accent.

This module must not import librosa or `quaddance.music`.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import find_peaks

#: Lowest paw lift peak that counts as an accent, m (`TargetConfig.min_lift_m`).
ACCENT_MIN_LIFT_M = 0.03
#: Smallest trunk height swing that counts, m: about what a viewer sees on a 0.3 m trunk.
ACCENT_MIN_HEIGHT_M = 0.01
#: Smallest trunk angle swing that counts, rad (2 degrees).
ACCENT_MIN_ANGLE_RAD = float(np.deg2rad(2.0))
#: Longest flat top of an extremum that still counts as one moment, s.
ACCENT_MAX_HOLD_S = 0.1
#: Default beat tolerance, s (the +-100 ms of the issue's beat coverage).
BEAT_TOLERANCE_S = 0.1


def _extrema(x: np.ndarray, prominence: float, max_hold: int = 1_000_000) -> np.ndarray:
    """Indices of local maxima and minima of ``x`` with at least ``prominence`` and a flat
    top of at most ``max_hold`` samples (counted once, at its middle)."""
    hi, _ = find_peaks(x, prominence=prominence, plateau_size=(1, max_hold))
    lo, _ = find_peaks(-x, prominence=prominence, plateau_size=(1, max_hold))
    return np.concatenate([hi, lo])


def motion_accents_s(
    time_s: np.ndarray,
    paw_targets_m: np.ndarray | None,
    body_targets: np.ndarray | None = None,
) -> np.ndarray:
    """Times of the visible motion accents (see module), s, sorted; (N,).

    ``paw_targets_m`` (T, 4) FL, FR, RL, RR and ``body_targets`` (T, 4) `BODY_COLUMNS`, at
    ``time_s`` (T,); either may be None.
    """
    t = np.asarray(time_s, dtype=np.float64)
    found: list[np.ndarray] = []
    if paw_targets_m is not None:
        paws = np.asarray(paw_targets_m, dtype=np.float64)
        for k in (0, 1):
            peaks, _ = find_peaks(paws[:, k], height=ACCENT_MIN_LIFT_M)
            found.append(t[peaks])
    if body_targets is not None:
        body = np.asarray(body_targets, dtype=np.float64)
        dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
        max_hold = max(1, round(ACCENT_MAX_HOLD_S / dt))
        thresholds = (ACCENT_MIN_HEIGHT_M,) + (ACCENT_MIN_ANGLE_RAD,) * 3
        for c, threshold in enumerate(thresholds):
            found.append(t[_extrema(body[:, c], threshold, max_hold)])
    if not found:
        return np.zeros(0)
    return np.sort(np.concatenate(found))


def accent_offsets_s(accents_s: np.ndarray, beats_s: np.ndarray) -> np.ndarray:
    """Distance from each of ``beats_s`` to its nearest accent, s; (N,), inf without
    accents."""
    beats = np.asarray(beats_s, dtype=np.float64).reshape(-1)
    accents = np.sort(np.asarray(accents_s, dtype=np.float64).reshape(-1))
    if accents.size == 0:
        return np.full(beats.size, np.inf)
    i = np.clip(np.searchsorted(accents, beats), 1, accents.size) - 1
    j = np.clip(i + 1, 0, accents.size - 1)
    return np.minimum(np.abs(accents[i] - beats), np.abs(accents[j] - beats))


def beat_coverage(
    accents_s: np.ndarray, beats_s: np.ndarray, tol_s: float = BEAT_TOLERANCE_S
) -> float:
    """Fraction of ``beats_s`` with an accent within +-``tol_s``; 0 when there are no beats."""
    offsets = accent_offsets_s(accents_s, beats_s)
    return float(np.mean(offsets <= tol_s)) if offsets.size else 0.0
