"""A click track over a song (``analyze --click``): a short tone at each beat, a higher one at
each downbeat, so that one listen tells whether the beats are on the music's beat, half a beat
off, or at the wrong tempo, before a dance or a robot depends on them."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from quaddance.music.beat_file import DOWNBEAT_ON_BEAT_S

CLICK_HZ = 1000.0
"""Pitch of a beat's click, Hz (above most bass and drums, where the ear finds it at once)."""

DOWNBEAT_CLICK_HZ = 2000.0
"""Pitch of a downbeat's click, Hz: an octave above, so the bar is heard too."""

CLICK_S = 0.05
"""Length of a click, s: shorter than the shortest gap between beats (0.2 s), so clicks never
overlap."""

CLICK_DECAY_S = 0.008
"""Time constant of a click's fade, s: a sharp start, the click's time, then a fast fade."""

SONG_PEAK = 0.6
"""Peak of the song in the mix; the clicks take the rest of full scale (0.4), so the mix never
clips."""


def click_track(
    n_samples: int, sr: int, beats_s: Sequence[float], downbeats_s: Sequence[float] = ()
) -> np.ndarray:
    """(n_samples,) clicks at peak 1: each starts at its beat (rounded to a sample), at
    `DOWNBEAT_CLICK_HZ` where a downbeat is within `DOWNBEAT_ON_BEAT_S`, else `CLICK_HZ`.
    Beats outside ``[0, n_samples / sr)`` are skipped; a click near the end is cut short."""
    out = np.zeros(n_samples, dtype=np.float32)
    t_s = np.arange(round(CLICK_S * sr)) / sr
    fade = np.exp(-t_s / CLICK_DECAY_S)
    shapes = {
        hz: (np.sin(2.0 * np.pi * hz * t_s) * fade).astype(np.float32)
        for hz in (CLICK_HZ, DOWNBEAT_CLICK_HZ)
    }
    down = np.asarray(downbeats_s, dtype=float)
    for beat_s in np.asarray(beats_s, dtype=float):
        start = round(beat_s * sr)
        if not 0 <= start < n_samples:
            continue
        near = np.abs(down - beat_s).min() if len(down) else np.inf
        shape = shapes[DOWNBEAT_CLICK_HZ if near <= DOWNBEAT_ON_BEAT_S else CLICK_HZ]
        n = min(len(shape), n_samples - start)
        out[start : start + n] += shape[:n]
    return out


def with_clicks(
    y: np.ndarray, sr: int, beats_s: Sequence[float], downbeats_s: Sequence[float] = ()
) -> np.ndarray:
    """(n,) the song ``y`` scaled to peak `SONG_PEAK`, plus `click_track` at the remaining
    0.4 of full scale: the peak stays within [-1, 1]."""
    y = np.asarray(y, dtype=np.float32)
    song = y * (SONG_PEAK / max(float(np.abs(y).max(initial=0.0)), 1e-9))
    return song + (1.0 - SONG_PEAK) * click_track(len(y), sr, beats_s, downbeats_s)
