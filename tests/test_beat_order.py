"""Beats always increase, at least `MIN_BEAT_GAP_S` apart, offline and online (issue 32).

Properties over drawn audio (noise, clicks at any tempo, swells, silence, very short and very
fast material), and the cases that made the analyser and the tracker go backwards: swells into
the beats (the offline refinement moved a beat to the vertex of a parabola fitted on a slope,
past its neighbour), the start of a benchmark song where the online tracker reported a beat
of a held grid and then, its offset dropped, the score's own beat 60 ms after it, and a change
of the listener that the tracker follows.
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchmarks.real_music import ROOT
from quaddance.music.analysis import MIN_BEAT_GAP_S, analyze
from quaddance.music.audio import DEFAULT_SR
from quaddance.music.live import FileSource, track_samples
from quaddance.music.online_beats import BeatEvent, OnlineBeatTracker

SR_HZ = DEFAULT_SR

_SETTINGS = settings(
    deadline=None,  # shared CPUs: time is a benchmark's business
    database=None,  # nothing written into the checkout
    derandomize=True,  # the same examples on every run: a failure reproduces
    suppress_health_check=list(HealthCheck),
)


def assert_spaced(beats_s: np.ndarray, downbeats_s: np.ndarray, duration_s: float) -> None:
    """Each beat at least `MIN_BEAT_GAP_S` after the one before, all inside the audio, the
    downbeats among them."""
    gaps = np.diff(beats_s)
    assert np.all(gaps >= MIN_BEAT_GAP_S - 1e-9), (gaps.min(), beats_s[np.argmin(gaps)])
    assert np.all((beats_s >= 0.0) & (beats_s <= duration_s)), beats_s
    assert np.isin(downbeats_s, beats_s).all()


def swells(bpm: float, rise_s: float, depth_db: float, duration_s: float, seed: int) -> np.ndarray:
    """Noise that fades in by ``depth_db`` over ``rise_s`` into every beat, then stops (a
    reversed cymbal): its onset envelope is a slope, not a peak, around the beats."""
    rng = np.random.default_rng(seed)
    y = np.zeros(int(duration_s * SR_HZ))
    n = int(rise_s * SR_HZ)
    fade_in = 10 ** (np.linspace(-depth_db, 0.0, n) / 20.0)
    for t_s in np.arange(0.2, duration_s - rise_s, 60.0 / bpm):
        i = int(t_s * SR_HZ)
        y[i : i + n] += 0.5 * fade_in * rng.standard_normal(n)
    return y.astype(np.float32)


def clicks(times_s: np.ndarray, duration_s: float, decay_s: float, rng: np.random.Generator):
    """Noise clicks with a ``decay_s`` tail at ``times_s`` (inside the audio), random levels."""
    y = np.zeros(int(duration_s * SR_HZ))
    n = max(1, int(5 * decay_s * SR_HZ))
    tail = np.exp(-np.arange(n) / (decay_s * SR_HZ))
    for t_s in times_s:
        i = int(t_s * SR_HZ)
        part = y[i : i + n]
        part += rng.uniform(0.05, 1.0) * tail[: len(part)] * rng.standard_normal(len(part))
    return y


KINDS = ("silence", "noise", "tempo", "random", "swells")


@st.composite
def audio(draw: st.DrawFn, max_s: float, kinds: tuple[str, ...] = KINDS) -> np.ndarray:
    """Up to three parts, one after another, of the ``kinds`` (Hypothesis draws the first
    most): silence, noise bursts, clicks at a steady tempo (20-900 BPM, jittered), clicks at
    random times, or swells into beats."""
    duration_s = draw(st.floats(0.05, max_s))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n_parts = draw(st.integers(1, 3))
    edges_s = np.sort(rng.uniform(0.0, duration_s, n_parts - 1))
    y = np.zeros(int(duration_s * SR_HZ))
    for a_s, b_s in zip([0.0, *edges_s], [*edges_s, duration_s], strict=True):
        kind = draw(st.sampled_from(kinds))
        length_s = b_s - a_s
        if kind == "noise":
            part = clicks(rng.uniform(0, length_s, draw(st.integers(1, 8))), length_s, 0.2, rng)
        elif kind == "tempo":
            bpm = draw(st.floats(20.0, 900.0))
            beats_s = np.arange(rng.uniform(0, 60.0 / bpm), length_s, 60.0 / bpm)
            beats_s += draw(st.floats(0.0, 0.05)) * rng.standard_normal(len(beats_s))
            part = clicks(np.clip(beats_s, 0.0, length_s), length_s, 0.01, rng)
        elif kind == "random":
            part = clicks(rng.uniform(0, length_s, rng.integers(1, 60)), length_s, 0.01, rng)
        elif kind == "swells":
            bpm, rise_s = draw(st.floats(60.0, 200.0)), draw(st.floats(0.05, 0.3))
            part = swells(bpm, rise_s, draw(st.floats(20.0, 80.0)), length_s, int(rng.integers(9)))
        else:
            continue
        i = int(a_s * SR_HZ)
        y[i : i + len(part)] += part[: len(y) - i]
    return y.astype(np.float32)


# --- offline ----------------------------------------------------------------------------------


def test_offline_beats_stay_in_order_where_swells_lead_into_the_beats():
    # Seen going backwards by 386 ms: the parabola through a slope of the onset envelope put
    # its vertex 40 frames from the beat.
    y = swells(bpm=120.0, rise_s=0.2, depth_db=30.0, duration_s=6.0, seed=7)
    result = analyze(y, SR_HZ)
    assert_spaced(result.beats_s, result.downbeats_s, result.duration_s)
    assert len(result.beats_s) >= 10  # 11 swells: the beats are still found


@settings(_SETTINGS, max_examples=120)
@given(audio(max_s=10.0, kinds=KINDS[::-1]))  # swells: the refinement's slopes
def test_offline_beats_increase_at_least_the_gap_apart(y: np.ndarray):
    result = analyze(y, SR_HZ)
    assert_spaced(result.beats_s, result.downbeats_s, result.duration_s)


# --- online -----------------------------------------------------------------------------------


def test_online_beats_stay_in_order_on_a_real_song():
    # boogie_marabi from its start, around 19.8 s, where a held grid that is dropped can
    # report a beat 60 ms before the score's own (that case, with the times it had, is
    # replayed below with a stand-in listener).
    source = FileSource(ROOT / "audio" / "boogie_marabi.ogg", realtime=False)
    y = source.y[: int(20.5 * source.sr_hz)]
    track = track_samples(y, source.sr_hz)
    assert_spaced(track.beats_s, track.downbeats_s, len(y) / source.sr_hz)


class _Listener:
    """Stands in for one of the tracker's listeners: reports what it is given."""

    def __init__(self) -> None:
        self.locked, self.heard_s, self.beats = False, 0.0, []

    def feed(self, spectra, frames_end_s: float, t_end_s: float) -> list[BeatEvent]:
        beats, self.beats = self.beats, []
        return beats


def _beat(time_s: float) -> BeatEvent:
    return BeatEvent(time_s, time_s, 0, 0, 120.0, True, 1.0)


def _reported_s(tracker: OnlineBeatTracker, t_end_s: float) -> list[float]:
    return [b.time_s for b in tracker.update(np.zeros(0), t_end_s)]


def _stand_in_tracker() -> tuple[OnlineBeatTracker, _Listener, _Listener]:
    """A tracker whose two listeners are stand-ins; the first is locked."""
    tracker = OnlineBeatTracker()
    first, joined = _Listener(), _Listener()
    tracker._first, tracker._joined = first, joined
    first.locked = True
    return tracker, first, joined


def test_online_beats_stay_in_order_when_the_tracker_changes_listener():
    tracker, first, joined = _stand_in_tracker()
    first.beats = [_beat(1.0)]
    assert _reported_s(tracker, 1.0) == [1.0]
    # The first listener loses its lock; the other, locked on its own grid, takes over.
    first.locked, joined.locked, joined.heard_s = False, True, 10.0
    first.heard_s = 10.0
    joined.beats = [_beat(0.9), _beat(1.1), _beat(1.3)]
    assert _reported_s(tracker, 1.3) == [1.3]


def test_online_beats_stay_in_order_where_a_held_grid_is_dropped():
    # A listener held a grid after the score's beats and reported its beat at 19.816 s; the
    # grid dropped (a lost lock), the score's own next beat came at 19.876 s.
    tracker, first, _ = _stand_in_tracker()
    first.beats = [_beat(19.816)]
    assert _reported_s(tracker, 19.82) == [19.816]
    first.beats = [_beat(19.876), _beat(20.27)]
    assert _reported_s(tracker, 20.3) == [20.27]


@settings(_SETTINGS, max_examples=60)
@given(audio(max_s=12.0))
def test_online_beats_increase_at_least_the_gap_apart(y: np.ndarray):
    track = track_samples(y, SR_HZ)
    assert_spaced(track.beats_s, track.downbeats_s, len(y) / SR_HZ)
