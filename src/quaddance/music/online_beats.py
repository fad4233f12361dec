"""Online (causal) beat, tempo, downbeat and energy tracking for ``quaddance live``.

The tracker sees the audio block by block and never looks ahead. Per 11.6 ms frame (hop 256 at
22.05 kHz) it computes, from a 46 ms window that ends at the newest sample:

1. Onset envelopes, as in the offline analyser (``music/analysis.py``) but with causal
   normalisation (running means instead of centred ones) and without its own learned
   activation: mel dB flux plus kick/bass-band flux for the tempo, mel dB flux plus treble flux
   for placing beats, each half BeatNet's causal beat activation (`music.beatnet`, its 20 ms
   frames run as they end: `beatnet.SpeedsActivationStream`; ``BEATNET_WEIGHT``,
   ``BEATNET_STRETCHES``).
2. Tempo, every 0.25 s: the harmonic autocorrelation salience of the last ``TEMPO_WINDOW_S`` of
   the tempo envelope (the same "lag whose multiples line up" score and log-normal prior as the
   offline analyser, which prefers the true tempo to half tempo in the dance range), followed
   by an online Viterbi filter over a log-tempo grid spanning the dance range
   (`layout.DANCE_TEMPO_BPM`, 60-180 BPM): tempo drifts cheaply and jumps at a fixed
   cost; a recent-weighted window lets a tempo change win within a few seconds (a shorter
   one once the beats start missing their onsets), and the beat score is then recomputed on
   the new period so the beats move onto the new grid at once.
   Before the lock, a tempo heard at half a snare backbeat doubles (`backbeat_heard`, on the
   recent music folded over the beat period); once locked, the
   metrical level is held: a filter tempo of double, half, 3/2 or 2/3 of the locked one
   (``HELD_LEVEL_RATIOS``) keeps the tempo at the locked level. Syncopated parts that repeat
   every 3 sixteenths (3+3+2, a clave) make the autocorrelation as strong at 4/3 of the
   beat's tempo as at it; the bar tells them apart: the three-four test (``THREE_FOUR``)
   moves the tempo to 3/4 of the filter's when the autocorrelation at 2 and 4 periods of the
   slower tempo (the half bar and the bar) clearly beats that at 2 and 4 of the faster, and
   then holds 4/3 and 3/2 of it as the same music.
3. Beat phase with a cumulative beat score (Ellis' dynamic program run forwards, as in Stark's
   real-time BTrack): each frame scores its onset plus the best score one beat period back.
   Half-way between beats the score is projected one period ahead and the next beat is
   predicted; a beat is reported as soon as the audio reaches its predicted time, so reporting
   is at most one block late (``LATENCY_S``) and the motion can be planned on ``next_beat_s``.
4. Lock: a (reported) beat is "supported" when the onset envelope peaks near it; the tracker
   is locked when most of the last beats (``LOCK_SUPPORT`` of at least ``LOCK_BEATS`` beats
   spanning ``LOCK_SPAN_S``) were supported at a steady tempo, or, retrospectively, when the
   current grid carried back over as many beats of the music already heard lands on onsets as
   often, the last ``LOCK_RETRO_BEATS`` reported beats were supported, the tempo stayed steady
   since the first of them (this saves the wait for beats that were heard before the first
   tempo estimate or before the tempo settled); the heard grid also passes when its last two
   bars were supported on the same two or more beats of the bar, not every other one (a clave
   leaves beats 2 and 3 empty: ``LOCK_BAR_BEATS``). Either way the tempo's periodicity must stand
   out of white noise's (``LOCK_PERIODICITY``), and the flux must come in bursts, not as steady
   noise's does (``BURSTY_CV``). It unlocks after
   ``UNLOCK_MISSES`` unsupported beats in a row or when the music stops (``SILENCE_RESET_S`` of
   silence also resets the tempo and phase, so a restart is found afresh, and the music after
   it is heard as from the stream's start: the loudness reference and the running means of
   item 1 start again, item 8); beats predicted into a silence a beat long or longer are not
   reported (``SILENT_BEAT_PERIODS``).
5. Phase hold (off-beat guard): once locked, the reported beats keep their grid. When the
   score's next beat lands more than ``PHASE_JUMP_BEATS`` of a beat off the grid of the
   reported beats (the score has switched to another, louder pulse: off-beat or swung hats
   that come in after the intro, a snare on the "and"), the reported beats stay on the old grid
   (an offset from the score's beats) for as long as that grid stays supported; when it loses
   the lock, or the tempo changes, the reported beats follow the score again. A held grid
   follows its own onsets: each supported beat moves the next ones onto its onset peak
   (``HOLD_FOLLOW``).
   BeatNet's vote (off by default): the flux and BeatNet can put the beat half a beat apart
   (loud off-beat chords or bass, and a lock that came on them). Since the lock, BeatNet's
   activation is summed at the reported beats and at their midpoints; when the midpoints carry
   clearly more (``OFFBEAT_VOTE_RATIO``), the grid moves half a beat onto them. A sum since the
   lock, not a recent window: BeatNet itself hears some passages on the off-beat.
   Swing: the held grid can be the swung off-beats themselves (swung hats heard before the
   drums, or chosen after a tempo change), which stay supported. Every ``SWING_BEATS`` beats
   the onsets are folded over the reported grid, and the swing test (`swing_shift`) moves
   the grid onto the beat.
   At the lock the swing test also runs on the heard grid, so that a lock reached on swung
   off-beats is moved before its beats are danced to. (The offline analyser's bass-harmony
   off-beat test is not run here: on real music it moved the grid off the beat more often than
   onto it.)
6. Downbeats (4/4): the bar position whose beats carry the most kick/bass-band onsets, chord
   changes and BeatNet's downbeat probability over the last bars, with hysteresis.
7. Energy: RMS mapped to [0, 1] by the 5th and 95th percentiles of the last 30 s (the offline
   choreographer's ``normalized_energy``, causally), smoothed over about 1 s.
8. Two listeners. The running means of item 1 must start somewhere. Started at the first
   frame's zero flux, they divide the first second's onsets by almost nothing (up to 259 times
   the later peaks), so the first sound heard dominates the first tempo estimates and the beat
   score: right when the tracker hears a song from its start (its first sound is a downbeat),
   wrong when it joins music already playing (the first sound is any sound, often an
   off-beat, and a wrong phase or tempo then holds for seconds: locks after 6 s). Started
   evenly (the mean of what has been heard), no sound dominates, but songs led by off-beat
   hats, skanks or no drums lose the phase their first downbeat gave them. So two listeners
   (items 1-7 each, on the same spectra) hear the audio, one each way. Told that the audio
   starts with the song (``song_start``: a file played from its start), the tracker follows
   the first whenever it is locked, and the second while it is locked once ``FALLBACK_S`` of
   music has passed (since the start or a silence reset) without a lock of the first. Told
   that the music may already be playing (a microphone), it follows the second until it has
   heard a silence (``SILENCE_RESET_S``): the music after it starts where it is heard, and
   from then on the tracker chooses as from a song's start. Where both are locked on
   different grids of a song joined mid-song, the second is the right one on nearly every
   tuning song, while from a song's start the first is (most often on songs led by off-beats).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from quaddance.layout import BEATS_PER_BAR, DANCE_TEMPO_BPM
from quaddance.music import beatnet
from quaddance.music.analysis import (
    MIN_BEAT_GAP_S,
    autocorrelation,
    blend,
    harmonic_salience,
)
from quaddance.music.audio import DEFAULT_SR

SR_HZ = DEFAULT_SR
"""Sample rate the tracker runs at, Hz (sources resample to it)."""

HOP = 256
"""Samples per onset frame (11.6 ms at 22.05 kHz)."""

N_FFT = 1024
"""Analysis window, samples (46 ms): long enough for the kick band, short for low latency."""

FRAME_S = HOP / SR_HZ
"""Onset frame period, seconds."""

BLOCK_S = HOP / SR_HZ
"""Default audio block of the live sources, seconds (one frame)."""

LATENCY_S = 0.025
"""A beat is reported at most this long after it happens, for blocks of at most this length
(the default block is 11.6 ms): beats are predicted half a beat ahead and reported by the first
``update`` whose block ends at or after the predicted time."""

WINDOW_DELAY_S = (N_FFT / 2) / SR_HZ
"""An onset shows in the flux when it reaches the middle of the window: onset frame times are
the window centres, this much before the newest sample."""

N_MELS = 64
LOW_BAND_HZ = 160.0
"""Kick/bass band upper edge, Hz (as the offline analyser)."""
HIGH_BAND_HZ = 3000.0
"""Treble band lower edge, Hz: snare noise, hats and cymbals."""
CHORD_BAND_HZ = (200.0, 2000.0)
"""Band where chord changes are looked for (downbeats), Hz."""

MIN_BPM, MAX_BPM = DANCE_TEMPO_BPM
"""Tempo search range, BPM: the dance range, in which the offline analyser reports its beats
too (it searches wider and folds its beats into it)."""
PRIOR_CENTER_BPM = 120.0
PRIOR_SIGMA_OCTAVES = 1.2
"""Log-normal tempo prior: the offline analyser's (centre of the usual dance tempi 80-160 BPM)."""
TEMPO_HARMONICS = 4
TEMPO_WINDOW_S = 8.0
"""Autocorrelation window of the tempo estimate, seconds."""
MIN_TEMPO_WINDOW_S = 2.0
"""No tempo (and no beats) before this much music has been heard, seconds."""
TEMPO_HOP_S = 0.25
"""Tempo estimate period, seconds."""
TEMPO_GRID_STEP = 0.01
"""Log-tempo grid step (natural log units: 1 %)."""
TEMPO_DRIFT_STEPS = 2.0
"""Tempo drifts by about this many grid steps (2 %) per tempo hop at no great cost."""
TEMPO_JUMP_COST = 3.0
"""Cost of a tempo jump, in units of one hop of the clearest evidence (offline analyser's)."""

FAST_MISSES = 2
FAST_OF_BEATS = 3
FAST_WINDOW_S = 3.0
"""While locked, when ``FAST_MISSES`` of the last ``FAST_OF_BEATS`` beats found no onset (the
music has left the grid: a tempo change), the tempo is estimated from the last
``FAST_WINDOW_S`` only, where the new tempo dominates: the new tempo is reported 2.4 s after
the change instead of 3.6-3.9 s (the songs of ``test_tracker_follows_a_tempo_change_...``)."""
REBUILD_TEMPO_RATIO = 1.05
"""A tempo change larger than this ratio recomputes the cumulative beat score ..."""
REBUILD_S = 4.0
"""... over the last this many seconds."""
CUMSCORE_ALPHA = 0.9
"""Weight of the past in the cumulative beat score (BTrack's)."""
TIGHTNESS = 5.0
"""Width of the log-Gaussian weight on beat intervals off the period (BTrack's)."""
BEATNET_WEIGHT = 0.5
"""Share of BeatNet's causal activation in both onset envelopes. The stream hears the song
once, at its own speed, so the offline analyser's share (0.75 of an average over five
speeds) is not its; an even share was chosen on the tuning songs of the real-music sets."""
BEATNET_STRETCHES: tuple[float, ...] = (1.0,)
"""Speeds at which the stream hears the song (`beatnet.SpeedsActivationStream`): once. The
offline analyser's five speeds, heard causally, lose on the songs outside the held-out parts
(``python -m benchmarks.online_mix``: the tracker then locks half a beat off on songs it had
right), whatever the share."""

LOCK_BEATS = 3
"""Supported beats at a steady tempo needed for a lock ..."""
LOCK_SPAN_S = 1.5
"""... spanning at least this long (4 beats at 120 BPM, 3 at 60 BPM)."""
LOCK_MIN_WINDOW_BEATS = 4
LOCK_SUPPORT = 0.75
"""Fraction of the beats (at least the last ``LOCK_MIN_WINDOW_BEATS``) that must be supported
for a lock."""
LOCK_BAR_BEATS = 2
"""Supported beats per bar that the retrospective lock's bar test needs (item 4)."""
SUPPORT_RATIO = 1.4
"""A beat is supported when its onset peak is this many times the period's mean onset."""
LOCK_RETRO_BEATS = 2
"""Reported beats, supported at a steady tempo, that a retrospective lock needs (item 4): two,
so that the interval between reported beats, not just one beat, agrees with the grid."""
LOCK_PERIODICITY = 2.0
"""Either lock (item 4) needs the tempo's autocorrelation salience to stand this many standard
errors above white noise's (whose autocorrelation over n frames has a standard error of
1 / sqrt(n)): onset peaks are everywhere in noise (nearly all of its beats are "supported").
Alone it does not tell music from steady noise: the recency window (the autocorrelation is
divided by the window's own, small at long lags) and the max over the tempo grid let noise
pass, and its first onsets stand out as a song's first sound does (item 8). Without
``BURSTY_CV``, 18 of 18 clips of white, pink and brown noise (12 s) locked from the stream's
start; 10 % of the tuning songs' locks come at a salience below 3.1, so a higher threshold
would cost music its locks."""
BURSTY_S = 3.0
BURSTY_CV = 0.36
"""Either lock (item 4) also needs the full-band flux of the last ``BURSTY_S`` to vary by this
coefficient of variation (std / mean) at least: music's flux comes in bursts, steady noise's
does not. Over 3 s, white, pink and brown noise stayed at or below 0.31; per tuning
song, the 5th percentile over the song is 0.5-3 (median 1.7), so noise clips do not lock
while music with noise 10 dB down still does."""
SUPPORT_RADIUS = 3
"""A beat is supported by an onset peak within this many frames (+-35 ms)."""
UNLOCK_MISSES = 4
"""Unsupported beats in a row that lose the lock (a break without drums keeps it a while)."""
HELD_LEVEL_RATIOS = (2.0, 1.5)
"""Once locked, a tempo this many times the locked one, or this fraction of it, is the same
music heard at another metrical level, and the reported tempo stays (item 2): double or half
(every beat, or every other one, stays on the grid), and 3:2, the cross-rhythm of syncopated
parts (3+3+2 accents of eighth notes) that a syncopated groove pulls the autocorrelation
towards. A real tempo change by one of these ratios loses the lock once the old grid goes
unsupported (``UNLOCK_MISSES``), and is followed then."""
THREE_FOUR = 4.0 / 3.0
THREE_FOUR_MARGIN = 0.1
THREE_FOUR_VOTES = 2
"""The three-four test (item 2): the tempo moves to 3/4 of the filter's (to 3/2 where 3/4
falls below ``MIN_BPM``: the same beats twice as fast) when the autocorrelation at 2 and 4
periods of the slower tempo exceeds that at 2 and 4 of its own by ``THREE_FOUR_MARGIN`` at
``THREE_FOUR_VOTES`` tempo estimates in a row. On the tuning set, at a tempo right to within a
metrical level of 2 the margin was passed at 2 of 8347 estimates, never twice in a row; at
4/3, 2/3 or 8/3 of the beat's tempo, at 12 % of the estimates before the lock."""
BACKBEAT_PERIODS = 4
BACKBEAT_MIN_PERIODS = 3
"""Beat periods of the recent music that the backbeat test (item 2) folds together: the last
4, at least 3 (2 let the first second's noise through: a 60 BPM click track doubled)."""
BACKBEAT_RATIO = 0.75
"""The backbeat test (`backbeat_heard`): the tempo doubles when the midpoints between the beats
carry hits this strong relative to the beats (a snare backbeat heard at half tempo; tuned)..."""
BACKBEAT_CONTRAST = 1.5
"""... and at least this much stronger than the quarter-beat positions, so that a steady stream
of notes (an arpeggio) does not count as a backbeat (tuned)..."""
MAX_DOUBLED_BPM = 165.0
"""... while the doubled tempo stays at most this: the top of the usual dance tempi 80-160 BPM
plus a margin."""
STEADY_TEMPO_RATIO = 1.04
"""Tempo counts as steady when it stays within this ratio over the lock's beats."""
PHASE_JUMP_BEATS = 0.15
"""While locked, a next beat of the score further than this fraction of a beat from the
reported grid is a jump to another pulse, which the reported beats do not follow (item 5).
Well beyond the drift of a steady or ramping tempo (BTrack's TIGHTNESS weight of an interval
4 % off a period is 0.98), and below the smallest jump to another pulse: a quarter beat, the
off-beat of the music's beat when the grid runs at half its tempo (a song of 170 BPM danced at
85). Chosen on the songs outside the held-out parts among 0.25, 0.2, 0.15 and 0.1
(``docs/results``)."""

HOLD_FOLLOW = 1.0
"""A held grid follows its own onsets (item 5): each supported beat moves the next ones this
fraction of the way to its onset peak. All of the way pays for itself on the real music made by
others outside the held-out parts (`python -m benchmarks.online_mix --also
benchmarks/real_music_fit`; half of it, or none, fell there: ``docs/results``)."""

OFFBEAT_VOTE_RATIO = float("inf")
OFFBEAT_VOTE_BEATS = 8
"""BeatNet's vote on the phase (item 5): while locked, its activation is summed at the reported
beats and at their midpoints since the lock; when the midpoints' sum exceeds this ratio times the
beats' after at least this many beats, the grid moves half a beat (and the sums swap). Off
(infinite): a ratio of 2 lifted the songs outside the held-out parts (`python -m
benchmarks.online_mix --also benchmarks/real_music_fit --mix 'beatnet 0.5 x 1, vote 2'`), all
of it on rendered songs that had locked on the off-beat, and moved 2 of the 5 held-out band
recordings half a beat off, early after a lock (``docs/results``)."""

SWING_BEATS = 6
"""While locked, the onsets of the last this many beat intervals are folded over the reported
grid, and the grid moves onto the beat when it sits on swung off-beats (item 5, `swing_shift`;
6 rather than 8 moved the one tuning song it moves 2 beats sooner, and no other); then as many
new beats before the next test."""
SWING_SHIFT_RANGE = (0.3, 0.42)
"""Shifts (fractions of a beat) the online swing test makes: off-beats swung to 0.58-0.7."""
SWING_NEAR = 0.1
"""Profile positions within this fraction of a beat of the grid, or of the shift, belong to
them."""
SWING_GRID_MIN = 0.3
SWING_REST_MAX = 0.3
"""The grid's own onsets are at least, and any onsets away from the grid and the shift at
most, this fraction of the profile's peak."""
SWING_LOCK_MIN_BEATS = 4
"""At the lock the swing test runs on the grid carried back over the music heard, at most
``SWING_BEATS`` and at least this many beat intervals of it."""

FALLBACK_S = 5.5
"""Music heard (since the start or a silence reset) after which a tracker told ``song_start``
follows the listener with evenly started means, while it is locked and the first listener is
not (item 8). Chosen on the tuning set, against issue 11's goal of a lock within 6 s: 3.5 /
4.5 / 5.0 / 5.5 s kept the same 65 of 67 songs in time and 57 within 0.1 of the offline F from
their start, and put 64 of 67 joined mid-song (by a tracker told ``song_start``) in time (one
listener: 45) and 45 / 47 / 48 / 49 within the F gap (one listener: 48); waiting longer lets
the first listener, when it locks, keep its phase. Told that the music may be playing, the
tracker follows the second listener from the start instead: 64 and 55 of 67 joined."""

SILENCE_DB = -50.0
"""Frames quieter than this, dB relative to the running loudness peak, are silence."""
SILENCE_ABS_RMS = 1e-4
"""... and frames below this RMS (-80 dBFS) always are."""
SILENCE_RESET_S = 1.5
"""Silence this long loses the lock and resets tempo and phase, seconds (longer than the
gap between clicks at the slowest tempo); the music after it is heard as from the stream's
start (item 4). A microphone that hears 2 s of -90 dBFS hiss before each tuning song: mean F
0.831 without that restart, 0.872 with it (4 offsets of the song within a frame; each song
from its start: 0.897; measured before ``BURSTY_CV``)."""
SILENCE_RESET_FRAMES = round(SILENCE_RESET_S / FRAME_S)
SILENT_BEAT_PERIODS = 1.0
"""A predicted beat is not reported when the input has been silent for this many beat periods
when it comes: the music has stopped, and the grid's beats until ``SILENCE_RESET_S`` are
guesses into silence that a robot should not dance to (the breaks of the live and heldout
sets: F +0.01 to +0.03 on each of their 6 songs with breaks). A whole period, not less: sparse
music (clicks, staccato notes) is digitally silent between its beats."""

BAR_EVIDENCE_DECAY = 0.95
"""Per-beat decay of the downbeat evidence (a memory of about 5 bars)."""
BAR_SWITCH_RATIO = 1.25
"""Another bar phase takes over when its evidence is this many times the current one's."""
ENERGY_HISTORY_S = 30.0
ENERGY_SMOOTH_S = 1.0


@dataclass(frozen=True)
class BeatEvent:
    """A beat, reported once the audio has reached it.

    Attributes:
        time_s: when the beat happens, song seconds.
        reported_s: song time of the end of the block that reported it (``<= time_s +
            LATENCY_S`` for blocks no longer than ``LATENCY_S``).
        index: beats counted since the tracker last (re)started.
        beat_in_bar: 0 for a downbeat, then 1, 2, 3.
        tempo_bpm: tempo when the beat was reported.
        locked: whether the tracker was locked.
        confidence: 0..1, see ``TrackerState.confidence``.
    """

    time_s: float
    reported_s: float
    index: int
    beat_in_bar: int
    tempo_bpm: float
    locked: bool
    confidence: float

    @property
    def downbeat(self) -> bool:
        return self.beat_in_bar == 0


SWING_FRACTIONS = np.linspace(0.0, 1.0, 41)[1:-1]
"""Positions inside a beat (fractions of it) at which `swing_shift` reads the onset profile."""


def beat_profile(beat_frames: np.ndarray, onset: np.ndarray) -> np.ndarray:
    """(len(SWING_FRACTIONS),) mean onset at each fraction of the intervals between
    ``beat_frames`` (frames of ``onset``, ascending, at least two)."""
    starts, ends = beat_frames[:-1], beat_frames[1:]
    pos = starts[:, None] + SWING_FRACTIONS[None, :] * (ends - starts)[:, None]
    return np.interp(pos, np.arange(len(onset)), onset).mean(axis=0)


def swing_shift(profile: np.ndarray) -> float:
    """Fraction of a beat to move the beats by when they sit on swung off-beats, else 0.

    Swing delays the off-beat (to 0.55-0.7 of the beat); it never anticipates it. So when the
    strongest onset inside the tracked beats (``profile``, from `beat_profile`) comes early
    (before 0.47 of the beat) and its mirror position is empty, the tracker has locked onto the
    swung off-beats and the true beats lie that fraction later.
    """
    middle = (SWING_FRACTIONS > 0.25) & (SWING_FRACTIONS < 0.75)
    i = int(np.argmax(np.where(middle, profile, -np.inf)))
    f = SWING_FRACTIONS[i]
    mirror = float(np.interp(1.0 - f, SWING_FRACTIONS, profile))
    if f < 0.47 and profile[i] > 2.0 * mirror:
        return float(f)
    return 0.0


def backbeat_heard(hits: np.ndarray) -> bool:
    """The backbeat test on the mean hit strength at 0, 1/4, 1/2 and 3/4 of the beat (4,): the
    midpoints carry hits about as strong as the beats (`BACKBEAT_RATIO`) and clearly stronger
    than the quarter-beat positions (`BACKBEAT_CONTRAST`)."""
    beat, q1, mid, q3 = (float(h) for h in hits)
    return mid >= BACKBEAT_RATIO * beat and mid >= BACKBEAT_CONTRAST * max(q1, q3)


@dataclass(frozen=True)
class TrackerState:
    """What the tracker believes now.

    Attributes:
        time_s: song time of the newest sample seen.
        tempo_bpm: current tempo, BPM (0 before any tempo estimate).
        beat_period_s: 60 / tempo_bpm, seconds (0 before any tempo estimate).
        locked: a stable lock (see the module's docstring, item 4).
        confidence: 0..1, the fraction of the last ``LOCK_BEATS`` beats that were supported.
        next_beat_s: predicted time of the next beat, song seconds (NaN when none is known).
        next_beat_in_bar: position of that beat in its bar, 0 = downbeat.
        last_beat_s: time of the last beat reported, song seconds (NaN before any).
        energy: loudness, 0..1 (normalised RMS, smoothed).
        silent: the input is silent now.
        lock_s: song time of the first stable lock (NaN before it).
    """

    time_s: float
    tempo_bpm: float
    beat_period_s: float
    locked: bool
    confidence: float
    next_beat_s: float
    next_beat_in_bar: int
    last_beat_s: float
    energy: float
    silent: bool
    lock_s: float

    @property
    def beat_phase(self) -> float:
        """Fraction (0..1) of the current beat that has passed (NaN before the first beat)."""
        if not (np.isfinite(self.last_beat_s) and self.beat_period_s > 0):
            return float("nan")
        return float(np.clip((self.time_s - self.last_beat_s) / self.beat_period_s, 0.0, 1.0))

    @property
    def next_downbeat_s(self) -> float:
        """Predicted time of the next downbeat, song seconds (NaN when no beat is predicted)."""
        if not np.isfinite(self.next_beat_s):
            return float("nan")
        beats_to_go = (BEATS_PER_BAR - self.next_beat_in_bar) % BEATS_PER_BAR
        return self.next_beat_s + beats_to_go * self.beat_period_s


def _steady(periods: list[float]) -> bool:
    """Whether the beat ``periods`` (a non-empty list) stay within ``STEADY_TEMPO_RATIO``."""
    return max(periods) / max(min(periods), 1e-9) <= STEADY_TEMPO_RATIO


class _Ema:
    """Exponential moving average with a time constant in frames.

    Args:
        tau_frames: time constant, frames.
        even_start: the mean of the samples seen so far, their weights normalised (an average
            started at zero, divided by the weight it has gathered); else the first sample
            stands for the whole past, as if it had always been there.
    """

    def __init__(self, tau_frames: float, even_start: bool = False) -> None:
        self.k = 1.0 - np.exp(-1.0 / max(tau_frames, 1e-9))
        self.even_start = even_start
        self.value = 0.0
        self._sum = 0.0
        self._weight = 0.0  # gathered so far: 1 - (1 - k)^n

    def __call__(self, x: float) -> float:
        if self.even_start:
            self._sum += self.k * (x - self._sum)
            self._weight += self.k * (1.0 - self._weight)
            self.value = self._sum / self._weight
        elif self._weight == 0.0:
            self.value, self._weight = x, 1.0
        else:
            self.value += self.k * (x - self.value)
        return self.value


class _Spectrum(NamedTuple):
    """What `_Features` computes per onset frame, the same for every listener."""

    full_flux: float  # mel dB flux, mean over the bands
    low_flux: float  # ... over the kick/bass band
    high_flux: float  # log1p flux, mean over the treble band
    rms: float
    mel_db: np.ndarray  # (N_MELS,) mel spectrum, dB below the loudness reference
    silent_frames: int  # silent frames in a row, this one included (0: not silent; silent is
    # quieter than SILENCE_DB below the loudness peak, or than SILENCE_ABS_RMS)
    restart: bool  # the first sound after SILENCE_RESET_S of silence: heard as a stream start
    learned: float  # BeatNet's P(beat) + P(downbeat), its newest frame that ends by this one's end
    learned_down: float  # ... its P(downbeat)


class _Frame(NamedTuple):
    """What a listener hears per onset frame (`_Onsets`)."""

    tempo_onset: float
    beat_onset: float
    low_onset: float
    full_flux: float  # the front end's, not normalised (steady noise has a steady flux)
    rms: float
    mel_db: np.ndarray  # (N_MELS,)
    learned: float  # BeatNet's P(beat) + P(downbeat), not normalised
    learned_down: float  # BeatNet's P(downbeat)


REF_DECAY = 10 ** (-0.6 * FRAME_S / 10.0)
"""Per-frame decay of the loudness references (onsets, silence): 6 dB per 10 s, so a song that
gets quieter keeps its 80 dB onset range, while one loud hit does not deafen the tracker for
long."""


class _Features:
    """Causal framing, mel spectrum, its fluxes, RMS and BeatNet's activation (shared by the
    listeners)."""

    def __init__(self) -> None:
        from quaddance.music.spectral import filterbanks

        self.window = np.hanning(N_FFT + 1)[:-1]
        banks = filterbanks(SR_HZ, N_FFT, N_MELS)
        # float64 like the spectrum: a mixed-precision matmul leaves BLAS for a slow loop.
        self.mel_fb_t = np.ascontiguousarray(banks.mel.T, dtype=np.float64)
        mel_hz = banks.mel_hz
        self.low = mel_hz <= LOW_BAND_HZ
        self.high = mel_hz >= HIGH_BAND_HZ
        self.chord_bands = (mel_hz >= CHORD_BAND_HZ[0]) & (mel_hz <= CHORD_BAND_HZ[1])
        self.tail = np.zeros(N_FFT - HOP, dtype=np.float32)
        self.pending = np.zeros(0, dtype=np.float32)
        self.ref_power = 0.0
        self.prev_db: np.ndarray | None = None
        self.prev_log: np.ndarray | None = None
        self.peak_rms = 0.0
        self.silent_frames = 0  # silent frames in a row
        self.silences = 0  # silences of SILENCE_RESET_S so far (the listeners reset at each)
        self.learned = beatnet.SpeedsActivationStream(BEATNET_STRETCHES)
        self.learned_now = np.zeros(2)  # its newest P(beat), P(downbeat)
        self.learned_fed = 0  # samples given to that stream so far

    def push(self, samples: np.ndarray) -> list[_Spectrum]:
        """Add samples; return the features of each new frame."""
        self.pending = np.concatenate([self.pending, samples])
        n_frames = len(self.pending) // HOP
        if n_frames == 0:
            return []
        used = n_frames * HOP
        new = self.pending[:used]
        audio = np.concatenate([self.tail, new])
        self.pending = self.pending[used:]
        self.tail = audio[-(N_FFT - HOP) :]
        idx = np.arange(n_frames)[:, None] * HOP + np.arange(N_FFT)[None, :]
        frames = audio[idx].astype(np.float64)
        rms = np.sqrt(np.mean(frames**2, axis=1))
        power = np.abs(np.fft.rfft(frames * self.window, axis=1)) ** 2
        mel = power @ self.mel_fb_t  # (n_frames, n_mels)
        silent, restart = zip(*(self._silence(float(r)) for r in rms), strict=True)
        # BeatNet's stream starts again with the music after a silence, as from a file's start.
        cuts = [0, *(i for i in range(1, n_frames) if restart[i]), n_frames]
        learned = np.concatenate(
            [self._learned(new[a * HOP : b * HOP], restart[a]) for a, b in itertools.pairwise(cuts)]
        )
        return [
            self._spectrum(mel[i], float(rms[i]), learned[i], silent[i], restart[i])
            for i in range(n_frames)
        ]

    def _silence(self, rms: float) -> tuple[int, bool]:
        """(silent frames in a row, this one included; whether this frame restarts the music)."""
        self.peak_rms = max(self.peak_rms * REF_DECAY, rms)
        silent = rms < max(SILENCE_ABS_RMS, self.peak_rms * 10 ** (SILENCE_DB / 20))
        restart = not silent and self.silent_frames >= SILENCE_RESET_FRAMES
        self.silent_frames = self.silent_frames + 1 if silent else 0
        self.silences += self.silent_frames == SILENCE_RESET_FRAMES
        return self.silent_frames, restart

    def _learned(self, audio: np.ndarray, restart: bool) -> np.ndarray:
        """(len(audio) // HOP, 2) BeatNet's newest P(beat), P(downbeat) that has ended by each
        onset frame's end (its frames are 20 ms apart, ours 11.6 ms); a new stream from the
        first sample if ``restart``."""
        if restart:
            self.learned, self.learned_fed, self.learned_now = (
                beatnet.SpeedsActivationStream(BEATNET_STRETCHES), 0, np.zeros(2)
            )  # fmt: skip
        start = self.learned.samples
        probs = self.learned.push(audio)
        learned_end = start + beatnet.HOP * np.arange(1, len(probs) + 1)
        ends = self.learned_fed + HOP * np.arange(1, len(audio) // HOP + 1)
        self.learned_fed += len(audio)
        latest = np.searchsorted(learned_end, ends, side="right") - 1
        out = np.vstack([self.learned_now[None, :], probs])[latest + 1]
        if len(probs):
            self.learned_now = probs[-1]
        return out

    def _spectrum(
        self,
        mel: np.ndarray,
        rms: float,
        learned: np.ndarray,
        silent_frames: int,
        restart: bool,
    ) -> _Spectrum:
        """One frame's fluxes against the previous frame, in dB below a decaying reference."""
        if restart:
            # Music after a silence is heard as from the stream's start: no frame before its
            # first one (no flux), and its own loudness reference.
            self.ref_power, self.prev_db, self.prev_log = 0.0, None, None
        self.ref_power = max(self.ref_power * REF_DECAY, float(mel.max()), 1e-10)
        db = 10.0 * np.log10(np.maximum(mel, self.ref_power * 1e-8) / self.ref_power)
        log = np.log1p(1e5 * mel / self.ref_power)
        if self.prev_db is None or self.prev_log is None:
            self.prev_db, self.prev_log = db, log
        flux_db = np.maximum(0.0, db - self.prev_db)
        flux_log = np.maximum(0.0, log - self.prev_log)
        self.prev_db, self.prev_log = db, log
        return _Spectrum(
            float(flux_db.mean()),
            float(flux_db[self.low].mean()),
            float(flux_log[self.high].mean()),
            rms,
            db,
            silent_frames,
            restart,
            float(learned.sum()),
            float(learned[1]),
        )


class _Onsets:
    """The two normalised onset envelopes of one listener, from the shared fluxes and BeatNet's
    activation (causal normalisation: running means instead of the offline analyser's centred
    ones).

    Args:
        even_start: running means of the samples heard so far (`_Ema`'s ``even_start``), for
            the listener that joins music already playing; else they start at the first
            frame's zero flux, and the first second's onsets stand out (see `FALLBACK_S`).
    """

    def __init__(self, even_start: bool) -> None:
        self.even_start = even_start
        self.restart()

    def restart(self) -> None:
        """Start the running means afresh, as at the stream's start."""
        fps = 1.0 / FRAME_S
        even_start = self.even_start
        self.mean_full = _Ema(5.0 * fps, even_start)
        self.mean_high = _Ema(5.0 * fps, even_start)
        self.norm = {
            k: (
                _Ema(0.25 * fps, even_start),
                _Ema(3.0 * fps, even_start),
                _Ema(30.0 * fps, even_start),
            )
            for k in "tbl"
        }

    def frame(self, spectrum: _Spectrum) -> _Frame:
        """The listener's frame: its onset envelopes and what the spectrum carries."""
        full, low, high = spectrum.full_flux, spectrum.low_flux, spectrum.high_flux
        tempo = self._normalise("t", full + low)
        beat_raw = full / max(self.mean_full(full), 1e-6) + high / max(self.mean_high(high), 1e-6)
        beat = self._normalise("b", beat_raw)
        # BeatNet's activation, normalised as the flux is: its broad humps between the beats
        # sink below the floor, its peaks stay.
        learned = self._normalise("l", spectrum.learned)
        tempo = blend(tempo, learned, BEATNET_WEIGHT)
        beat = blend(beat, learned, BEATNET_WEIGHT)
        return _Frame(
            tempo, beat, low, full, spectrum.rms, spectrum.mel_db, spectrum.learned,
            spectrum.learned_down,
        )  # fmt: skip

    def _normalise(self, key: str, x: float) -> float:
        """Remove the slow floor, divide by the local level (3 s); the floor on the divisor
        (a tenth of the 30 s level) keeps quiet passages quiet."""
        floor, level, long = self.norm[key]
        x = max(0.0, x - floor(x))
        lvl = level(x)
        return x / max(lvl, 0.1 * long(x), 1e-6)


class OnlineBeatTracker:
    """Causal beat, tempo, downbeat and energy tracker; feed it audio with ``update``.

    Two listeners track the same audio (item 8 of the module's docstring); ``update`` returns
    the beats, and ``state`` the beliefs, of the one followed.

    Args:
        sr_hz: sample rate of the blocks given to ``update``; must be ``SR_HZ`` (the sources
            resample to it).
        song_start: the audio starts where the music starts (a song file played from its
            start). False where the music may already be playing (a microphone, a file
            started part-way): then the first sound heard is any sound, and the listener
            that trusts it is followed only once the music has started after a silence.
    """

    def __init__(self, sr_hz: int = SR_HZ, song_start: bool = True) -> None:
        if sr_hz != SR_HZ:
            raise ValueError(f"OnlineBeatTracker runs at {SR_HZ} Hz, got blocks at {sr_hz} Hz")
        self._feats = _Features()
        self._first = _Listener(self._feats, even_start=False)
        self._joined = _Listener(self._feats, even_start=True)
        self._first_trusted = song_start
        self._followed = self._first if song_start else self._joined
        self._lock_s = float("nan")
        self._last_beat_s = -np.inf  # the last beat returned, by either listener

    def update(self, block: np.ndarray, t_end_s: float) -> list[BeatEvent]:
        """Process the next audio block; return the beats whose time the audio has reached.

        Args:
            block: (n,) mono samples at ``SR_HZ`` (float; any n >= 0).
            t_end_s: song time of the end of the block, seconds.

        Returns:
            The beats with ``time_s <= t_end_s`` not reported before, each at least
            `MIN_BEAT_GAP_S` after the one before (a beat sooner is dropped).
        """
        spectra = self._feats.push(np.asarray(block, dtype=np.float32).reshape(-1))
        # Samples short of a whole frame wait in ``pending``: the newest frame ends before them.
        frames_end_s = t_end_s - len(self._feats.pending) / SR_HZ
        first = self._first.feed(spectra, frames_end_s, t_end_s)
        joined = self._joined.feed(spectra, frames_end_s, t_end_s)
        if not self._first_trusted and self._feats.silences > 0:
            # The music after a silence starts where it is heard, as a song does.
            self._first_trusted = True
            self._followed = self._first
        if self._first.locked and self._first_trusted:
            self._followed = self._first
        elif self._joined.locked and (self._first.heard_s >= FALLBACK_S or not self._first_trusted):
            self._followed = self._joined
        if self._followed.locked and not np.isfinite(self._lock_s):
            self._lock_s = t_end_s
        # A beat can come sooner than `MIN_BEAT_GAP_S` after the last one returned, or before
        # it: a held grid's beats are scheduled up to a period or more ahead (its offset grows
        # past a beat), and when the offset is dropped (a lost lock, a new tempo) the score's
        # next beat comes before or just after them; or the listener followed has changed.
        # Such a beat is dropped, not reported out of order (its listener has counted it, so
        # the bar position stays on the grid).
        beats = []
        for beat in first if self._followed is self._first else joined:
            if beat.time_s >= self._last_beat_s + MIN_BEAT_GAP_S:
                beats.append(beat)
                self._last_beat_s = beat.time_s
        return beats

    @property
    def state(self) -> TrackerState:
        """A snapshot of what the tracker believes now."""
        return self._followed.state(self._lock_s)


class _Listener:
    """One causal tracker over the shared spectra (items 1-7 of the module's docstring).

    Args:
        feats: the tracker's spectral front end (its bands).
        even_start: the onset normalisation of `_Onsets`.
    """

    def __init__(self, feats: _Features, even_start: bool) -> None:
        self._chord_bands = feats.chord_bands
        self._onsets = _Onsets(even_start)
        fps = 1.0 / FRAME_S
        self._fps = fps
        self._n_frames = 0  # frames processed since the start
        self._time_s = 0.0
        # Tempo grid (log spaced) and its online Viterbi filter.
        # Anchored on the prior's centre, 120 BPM, so that the commonest dance tempo lies on a
        # grid point (0.5 % off, a 120 BPM click track locked a beat later at some phases).
        k = np.arange(
            np.ceil(np.log(MIN_BPM / PRIOR_CENTER_BPM) / TEMPO_GRID_STEP),
            np.floor(np.log(MAX_BPM / PRIOR_CENTER_BPM) / TEMPO_GRID_STEP) + 1,
        )
        self._log_bpm = np.log(PRIOR_CENTER_BPM) + TEMPO_GRID_STEP * k
        steps = np.arange(len(self._log_bpm))
        drift = -0.5 * ((steps[:, None] - steps[None, :]) / TEMPO_DRIFT_STEPS) ** 2
        self._trans = np.maximum(drift, -TEMPO_JUMP_COST)
        z = (self._log_bpm - np.log(PRIOR_CENTER_BPM)) / np.log(2.0) / PRIOR_SIGMA_OCTAVES
        self._prior = np.exp(-0.5 * z * z)
        self._tempo_hop = max(1, round(TEMPO_HOP_S * fps))
        hist = round(TEMPO_WINDOW_S * fps)
        self._hist_len = hist
        # Energy.
        self._rms_hist = np.zeros(0)
        self._rms_range: tuple[float, float] | None = None  # 5th, 95th percentile of RMS
        self._rms_hist_every = max(1, round(0.1 * fps))
        self._energy = _Ema(ENERGY_SMOOTH_S * fps)
        self._weights_period = 0.0  # period of the cached _best_past weights
        self._lags = np.zeros(0, dtype=int)
        self._weights = np.zeros(0)
        self._silent_frames = 0  # silent frames in a row (the front end's count)
        self._reset_tracking()

    # --- public ----------------------------------------------------------------------------

    @property
    def locked(self) -> bool:
        return self._locked

    @property
    def heard_s(self) -> float:
        """Music heard since the start or the last silence reset, seconds."""
        return self._heard_frames * FRAME_S

    def feed(
        self, spectra: list[_Spectrum], frames_end_s: float, t_end_s: float
    ) -> list[BeatEvent]:
        """Take the spectra of the frames that end at ``frames_end_s``, the block ending at
        ``t_end_s``; return the beats whose time the audio has reached."""
        self._time_s = t_end_s
        for k, spectrum in enumerate(spectra):
            # Onsets show when they reach the window centre: frame time = centre time.
            frame_t = frames_end_s - (len(spectra) - 1 - k) * FRAME_S - WINDOW_DELAY_S
            self._frame(spectrum, frame_t)
        events = []
        while self._scheduled and self._scheduled[0] <= t_end_s:
            # Counted even when not reported, so that the bar position stays on the grid.
            beat = self._emit(self._scheduled.pop(0), t_end_s)
            if self._silent_frames < SILENT_BEAT_PERIODS * self._period:
                events.append(beat)
        return events

    def state(self, lock_s: float) -> TrackerState:
        """A snapshot of what this listener believes now; ``lock_s`` is the tracker's first
        lock (the listener followed may have changed since)."""
        period_s = self._period * FRAME_S if self._period > 0 else 0.0
        next_s = self._scheduled[0] if self._scheduled else float("nan")
        if not self._scheduled and period_s > 0 and np.isfinite(self._last_beat_s):
            # Between a beat and the next prediction (made half a beat later): one period on.
            next_s = self._last_beat_s + period_s
        return TrackerState(
            time_s=self._time_s,
            tempo_bpm=60.0 / period_s if period_s > 0 else 0.0,
            beat_period_s=period_s,
            locked=self._locked,
            confidence=self._confidence(),
            next_beat_s=next_s,
            next_beat_in_bar=self._beat_in_bar(self._beat_index),
            last_beat_s=self._last_beat_s,
            energy=float(self._energy.value),
            silent=self._silent_frames >= SILENCE_RESET_FRAMES,
            lock_s=lock_s,
        )

    # --- per frame ---------------------------------------------------------------------------

    def _reset_tracking(self) -> None:
        """Forget tempo, phase, lock and bar position (at start and after silence)."""
        self._onset_t: list[float] = []  # tempo onset history (last TEMPO_WINDOW_S)
        self._onset_b: list[float] = []  # beat onset history, aligned with _cum
        self._low: list[float] = []
        self._flux: list[float] = []  # full-band flux per frame (`_bursty`)
        self._mel: list[np.ndarray] = []  # mel spectrum per frame, dB
        self._down: list[float] = []  # BeatNet's P(downbeat) per frame
        self._learned: list[float] = []  # BeatNet's P(beat) + P(downbeat) per frame
        self._vote = np.zeros(2)  # BeatNet at the reported beats, at their midpoints (item 5)
        self._vote_beats = 0  # beats in that vote
        self._pending_bar: list[int] = []  # frames of reported beats not yet in the bar count
        self._beats_counted = 0
        # Per-beat means that scale the three cues, evenly started: a first beat that misses
        # its cue (no kick in reach yet) must not stand for the past, or the next one's cue
        # counts many times over and holds the bar phase for bars.
        self._mean_low = _Ema(2 * BEATS_PER_BAR, even_start=True)
        self._mean_change = _Ema(2 * BEATS_PER_BAR, even_start=True)
        self._mean_down = _Ema(2 * BEATS_PER_BAR, even_start=True)
        self._cum: list[float] = []
        self._hist_start = self._n_frames  # frame number of the first history entry
        self._viterbi: np.ndarray | None = None
        self._period = 0.0  # beat period, frames (0 = unknown)
        self._period_at_beats: list[float] = []
        self._beat_frames: list[int] = []  # frame numbers of the scored beats
        self._tempo_track: list[tuple[int, float]] = []  # (frame number, period) per estimate
        self._periodicity = 0.0  # salience of the tempo, white-noise standard errors
        self._m0 = -1  # frames to the next beat prediction
        self._scheduled: list[float] = []  # predicted beat times not yet reported, s
        self._pending_support: list[int] = []  # frames of beats not yet scored
        self._support: list[bool] = []
        self._beat_index = 0
        self._bar_evidence = np.zeros(BEATS_PER_BAR)
        self._bar_phase = 0  # index (mod 4) of the beats that are downbeats
        self._beat_offset = 0.0  # reported beats follow the score's beats by this, periods
        self._phase_free = False  # the next beat is the score's, not held (a new tempo)
        self._locked = False
        self._doubled = False  # the backbeat test doubled the filter's tempo (item 2)
        self._slowed = False  # the three-four test slowed the filter's tempo (item 2)
        self._three_four_votes = 0  # tempo estimates in a row at which it said so
        self._misses = 0
        self._swing_tested = 0  # len(self._support) when the swing test last moved the grid
        self._last_beat_s = float("nan")
        self._heard_frames = 0

    def _frame(self, spectrum: _Spectrum, t_s: float) -> None:
        self._n_frames += 1
        self._update_energy(spectrum.rms)
        if spectrum.restart:
            self._onsets.restart()  # the music starts again where it is heard, as a song does
        frame = self._onsets.frame(spectrum)
        self._silent_frames = spectrum.silent_frames
        if self._silent_frames == SILENCE_RESET_FRAMES:
            self._reset_tracking()
        if self._silent_frames >= SILENCE_RESET_FRAMES:
            self._hist_start = self._n_frames  # the history restarts after the silence
            return
        self._heard_frames += 1
        self._push_history(frame)
        if self._heard_frames % self._tempo_hop == 0:
            self._update_tempo()
        if self._period <= 0:
            return
        self._check_support()
        self._count_bar()
        self._m0 -= 1
        if self._m0 <= 0:
            self._predict_beat(t_s)

    def _update_energy(self, rms: float) -> None:
        if self._n_frames % self._rms_hist_every == 0:
            keep = round(ENERGY_HISTORY_S * self._fps / self._rms_hist_every)
            self._rms_hist = np.append(self._rms_hist[-keep + 1 :], rms)
            if len(self._rms_hist) >= 10:
                self._rms_range = tuple(np.percentile(self._rms_hist, [5.0, 95.0]))
        if self._rms_range is None:
            self._energy(0.5 if rms > SILENCE_ABS_RMS else 0.0)
            return
        lo, hi = self._rms_range
        self._energy(float(np.clip((rms - lo) / max(hi - lo, 1e-9), 0.0, 1.0)))

    def _push_history(self, frame: _Frame) -> None:
        p = self._period
        cum = (1.0 - CUMSCORE_ALPHA) * frame.beat_onset
        if p > 0 and len(self._cum) > p / 2:
            prev = np.asarray(self._cum[-(round(2 * p) + 1) :])  # only the window is needed
            cum += CUMSCORE_ALPHA * self._best_past(prev, len(prev))
        self._onset_t.append(frame.tempo_onset)
        self._onset_b.append(frame.beat_onset)
        self._low.append(frame.low_onset)
        self._flux.append(frame.full_flux)
        self._mel.append(frame.mel_db)
        self._down.append(frame.learned_down)
        self._learned.append(frame.learned)
        self._cum.append(cum)
        excess = len(self._cum) - self._hist_len
        if excess > 0:
            for h in (
                self._onset_t,
                self._onset_b,
                self._low,
                self._flux,
                self._mel,
                self._down,
                self._learned,
                self._cum,
            ):
                del h[:excess]
            self._hist_start += excess

    def _best_past(self, cum: np.ndarray, end: int) -> float:
        """The best cumulative score 2 periods to half a period before index ``end``, each
        weighted by how far that interval is from one period (log-Gaussian, BTrack's)."""
        if self._weights_period != self._period:  # cached: called for every frame
            lags = np.arange(round(2 * self._period), round(self._period / 2) - 1, -1)
            self._lags = lags[lags >= 1]  # frames back, far to near
            self._weights = np.exp(-0.5 * (TIGHTNESS * np.log(self._lags / self._period)) ** 2)
            self._weights_period = self._period
        lags, weights = self._lags, self._weights
        if end >= lags[0]:  # the usual case: the whole window exists, a contiguous slice
            return float(np.max(cum[end - lags[0] : end - lags[-1] + 1] * weights))
        ok = lags <= end
        return float(np.max(cum[end - lags[ok]] * weights[ok])) if ok.any() else 0.0

    def _update_tempo(self) -> None:
        onset = np.asarray(self._onset_t)
        if len(onset) < MIN_TEMPO_WINDOW_S * self._fps:
            return
        span = self._hist_len  # frames the window rises over
        if self._locked and self._support[-FAST_OF_BEATS:].count(False) >= FAST_MISSES:
            span = round(FAST_WINDOW_S * self._fps)  # the grid is failing: recent music only
            onset = onset[-span:]
        periods = 60.0 * self._fps / np.exp(self._log_bpm)
        max_lag = min(len(onset) - 1, int(TEMPO_HARMONICS * periods.max()) + 2)
        # Recent music weighs more (a rising half-Hann window over TEMPO_WINDOW_S, by the age
        # of each frame, so that a short history at the start is weighed almost evenly), so
        # that a tempo change shows within a few seconds; dividing by the window's own
        # autocorrelation removes its pull towards short lags.
        window = np.hanning(2 * span + 1)[1 : span + 1][-len(onset) :]
        ac = autocorrelation((onset - onset.mean()) * window, max_lag)
        ac /= np.maximum(autocorrelation(window, max_lag, demean=False), 0.05)
        raw_sal = harmonic_salience(ac, periods, range(1, TEMPO_HARMONICS + 1))
        sal = raw_sal * self._prior
        emis = sal / max(float(np.abs(sal).max()), 1e-9)
        if self._viterbi is None:
            self._viterbi = emis
        else:
            self._viterbi = np.max(self._viterbi[:, None] + self._trans, axis=0) + emis
            self._viterbi -= self._viterbi.max()
        best = int(np.argmax(self._viterbi))
        held = HELD_LEVEL_RATIOS if self._locked or self._doubled else ()
        held += (THREE_FOUR, 2.0 / THREE_FOUR) if self._slowed else ()
        if held and self._period > 0:
            # Metrical level hold: once locked (or doubled by the backbeat test), a tempo at
            # another metrical level of the current one (`HELD_LEVEL_RATIOS`; after the
            # three-four test, 4/3 and 3/2 at any time) is the same music
            # heard another way, not a tempo change; the reported tempo stays at the current
            # level (the best tempo near it), as a dancer keeps the step tempo it chose. A real
            # tempo change (other ratios) or a lost lock lets the filter's best through.
            best = self._at_level(best, np.log(60.0 * self._fps / self._period), held)
        if self._three_four(ac, float(periods[best])):
            # Below the tempo range, the same beats at twice the rate (3/2 of the filter's).
            slow = self._log_bpm[best] - np.log(THREE_FOUR)
            best = self._best_near(slow if slow >= np.log(MIN_BPM) else slow + np.log(2.0))
            self._slowed = True
            # The same music at another level: the tempo heard so far, re-expressed at it,
            # stays steady (the lock's tests compare the periods at the beats).
            scale = float(periods[best]) / self._period if self._period > 0 else 1.0
            self._period_at_beats = [p * scale for p in self._period_at_beats]
            self._tempo_track = [(f, p * scale) for f, p in self._tempo_track]
        # The level is chosen before the lock and then held: doubling a locked tempo moved
        # every other reported beat (random11_dembow: F 0.97 -> 0.89, measured).
        if not self._locked and self._backbeat_double(float(periods[best])):
            best = self._best_near(self._log_bpm[best] + np.log(2.0))
            self._doubled = True
        # How clearly the chosen tempo is periodic, in standard errors (1 / sqrt(n)) of the
        # autocorrelation of n frames of white noise.
        self._periodicity = float(raw_sal[best]) * np.sqrt(len(onset))
        old_period, self._period = self._period, float(periods[best])
        self._tempo_track.append((self._n_frames, self._period))
        if len(self._tempo_track) > 2 * self._hist_len / self._tempo_hop:
            del self._tempo_track[0]  # older than any lock window
        if old_period <= 0:
            self._rebuild_cumscore()  # the history so far was scored without a period
            self._m0 = 1  # predict the first beat now
        elif abs(np.log(self._period / old_period)) > np.log(REBUILD_TEMPO_RATIO):
            self._rebuild_cumscore()
            # A new period: the offset found on the old one no longer applies, nor does the
            # old grid's phase: the change is heard seconds after it happened, and by then the
            # old grid has drifted off the music (held across the change, it kept an off-beat
            # phase that off-beat onsets then supported; funk_104_sync F 0.23 -> 0.41).
            self._beat_offset = 0.0
            self._phase_free = True

    def _best_near(self, log_bpm: float) -> int:
        """The filter's best tempo within `STEADY_TEMPO_RATIO` of ``log_bpm``."""
        near = np.abs(self._log_bpm - log_bpm) <= np.log(STEADY_TEMPO_RATIO)
        if not near.any():
            return int(np.argmin(np.abs(self._log_bpm - log_bpm)))
        return int(np.flatnonzero(near)[np.argmax(self._viterbi[near])])

    def _at_level(self, best: int, here: float, held: tuple[float, ...]) -> int:
        """``best``, or the best tempo near ``here`` (log BPM) where ``best`` is ``here`` at
        another metrical level (one of the ratios ``held``); a tempo change of any other size
        ends a backbeat doubling and a three-four slowing."""
        ratio = abs(self._log_bpm[best] - here)
        if any(abs(ratio - np.log(r)) <= np.log(STEADY_TEMPO_RATIO) for r in held):
            return self._best_near(here)
        if ratio > np.log(STEADY_TEMPO_RATIO):
            self._doubled = self._slowed = False
        return best

    def _three_four(self, ac: np.ndarray, period: float) -> bool:
        """Whether ``period`` (frames) has been 3/4 of the beat at `THREE_FOUR_VOTES` tempo
        estimates in a row, this one included: the autocorrelation ``ac`` at 2 and 4 periods of
        4/3 ``period`` beats that at 2 and 4 of ``period`` by `THREE_FOUR_MARGIN`."""
        slow = THREE_FOUR * period
        if 2 * slow > len(ac) - 1:
            self._three_four_votes = 0
            return False
        bars = harmonic_salience(ac, np.array([slow, period]), (2, 4))  # half bar and bar
        if bars[0] - bars[1] <= THREE_FOUR_MARGIN:
            self._three_four_votes = 0
            return False
        self._three_four_votes += 1
        if self._three_four_votes < THREE_FOUR_VOTES:
            return False
        self._three_four_votes = 0
        return True

    def _backbeat_double(self, period: float) -> bool:
        """Whether the music heard so far, folded over ``period`` (frames), shows a snare
        backbeat heard at half tempo (`backbeat_heard`): the onsets are averaged at 16
        phases of the period over its last `BACKBEAT_PERIODS` (fewer right after a restart,
        at least `BACKBEAT_MIN_PERIODS`); the strongest phase stands for the beat."""
        if 60.0 * self._fps / period * 2.0 > MAX_DOUBLED_BPM:
            return False
        onset = np.asarray(self._onset_b)
        n = min(BACKBEAT_PERIODS, int((len(onset) - 2) // period))
        if n < BACKBEAT_MIN_PERIODS:
            return False
        # A hit may land a frame off the interpolated position: take the local maximum.
        hit = np.max([onset[:-2], onset[1:-1], onset[2:]], axis=0)
        start = len(hit) - n * period
        pos = start + period * (np.arange(n)[:, None] + np.arange(16)[None, :] / 16.0)
        profile = np.interp(pos, np.arange(len(hit)), hit).mean(axis=0)
        k = int(np.argmax(profile))
        return backbeat_heard(profile[(k + np.array([0, 4, 8, 12])) % 16])

    def _rebuild_cumscore(self) -> None:
        """Recompute the cumulative beat score over the history with the new period: scores
        built on the old period would keep the beats on the old grid for several beats."""
        onset = np.asarray(self._onset_b)
        cum = np.asarray(self._cum, dtype=float)
        # Only the last REBUILD_S: the score forgets older beats anyway (alpha^k), and the
        # rebuild must stay a small fraction of the live loop's 20 ms.
        for i in range(max(0, len(onset) - round(REBUILD_S * self._fps)), len(onset)):
            cum[i] = (1.0 - CUMSCORE_ALPHA) * onset[i]
            if i > self._period / 2:
                cum[i] += CUMSCORE_ALPHA * self._best_past(cum, i)
        self._cum = cum.tolist()

    def _predict_beat(self, now_t_s: float) -> None:
        """Project the cumulative score one period ahead and schedule the next beat there
        (BTrack's prediction, made half-way between beats)."""
        p = self._period
        n_future = max(1, round(p))
        cum = np.asarray(self._cum, dtype=float)
        future = np.concatenate([cum, np.zeros(n_future)])
        n = len(cum)
        for i in range(n, n + n_future):
            future[i] = CUMSCORE_ALPHA * self._best_past(future, i)
        v = np.arange(1, n_future + 1)
        weight = np.exp(-0.5 * ((v - p / 2) / (p / 2)) ** 2)
        ahead = int(np.argmax(future[n:] * weight)) + 1  # frames after the newest frame
        self._hold_phase(now_t_s + (ahead + self._beat_offset * p) * FRAME_S)
        # The reported beat follows the score's by ``_beat_offset``; support and downbeats are
        # scored at the reported beats, so that a held grid that loses its onsets loses the lock.
        if ahead + self._beat_offset * p < 1:
            self._beat_offset += 1.0  # that beat of the held grid is past: the next one
        beat_frames = ahead + self._beat_offset * p
        self._scheduled.append(now_t_s + beat_frames * FRAME_S)
        self._pending_support.append(self._n_frames + round(beat_frames))
        self._pending_bar.append(self._n_frames + round(beat_frames))
        self._m0 = ahead + round(p / 2)

    def _hold_phase(self, beat_s: float) -> None:
        """While locked, keep the reported beats on their grid when the score's next beat
        (reported at ``beat_s`` with the current offset) jumps off it (item 5 of the module's
        docstring): move the offset by the jump, so the reported beat lands one period after
        the previous one."""
        if self._phase_free:  # the first beat after a tempo change: the score's own
            self._phase_free = False
            return
        prev_s = self._scheduled[-1] if self._scheduled else self._last_beat_s
        if not (self._locked and np.isfinite(prev_s)):
            return
        jump = (beat_s - prev_s) / (self._period * FRAME_S) - 1.0  # beats off the grid
        jump -= np.round(jump)  # the nearest grid beat: within half a beat
        if abs(jump) > PHASE_JUMP_BEATS:
            self._beat_offset -= jump

    def _support_at(self, onset: np.ndarray, i: int) -> tuple[bool, int] | None:
        """Whether history frame ``i`` has an onset peak within +-35 ms that stands out of the
        period before it (``SUPPORT_RATIO``), and where that peak is; None if not all heard."""
        radius = SUPPORT_RADIUS
        lo = max(0, i - radius)
        if i + radius >= len(onset) or lo >= len(onset) or i < 0:
            return None
        near = float(onset[lo : i + radius + 1].max())
        start = max(0, i - round(self._period))
        level = float(onset[start : i + radius + 1].mean())
        peak = lo + int(np.argmax(onset[lo : i + radius + 1]))
        return near > SUPPORT_RATIO * level and near > 0.0, peak

    def _check_support(self) -> None:
        """Score beats whose neighbourhood (+-35 ms) has been heard: supported or not."""
        cum_end = self._hist_start + len(self._onset_b)  # frame number after the newest
        while self._pending_support and self._pending_support[0] + SUPPORT_RADIUS <= cum_end:
            frame = self._pending_support.pop(0)
            i = frame - self._hist_start - 1
            onset = np.asarray(self._onset_b)
            scored = self._support_at(onset, i)
            if scored is None:
                continue
            supported, peak = scored
            if supported and self._beat_offset != 0.0:
                # A held grid is not the score's: it follows its own onsets, moving the next
                # beats by the frames this one's onset peak lay off it.
                self._beat_offset += HOLD_FOLLOW * (peak - i) / self._period
            self._support.append(supported)
            self._period_at_beats.append(self._period)
            self._beat_frames.append(frame)
            was_locked = self._locked
            self._update_lock(supported, onset, i)
            if self._locked and not was_locked:
                # The lock's grid has few reported beats, but the music before them was
                # heard: the swing test runs on the grid carried back over it.
                self._swing_at_lock(onset, i)
                self._vote[:], self._vote_beats = 0.0, 0
            elif self._locked:
                self._swing_guard(onset)
                self._offbeat_vote(i)

    def _grid_frames(self, i: int, n: int) -> np.ndarray:
        """History frames of the last ``n`` beats of the current grid that ends at history
        frame ``i``, carried back at the current period (oldest first; may be negative)."""
        return np.array([round(i - k * self._period) for k in range(n - 1, -1, -1)])

    def _swing_at_lock(self, onset: np.ndarray, i: int) -> None:
        """The swing test (`_swing_test`) on the heard grid that ends at history frame ``i``:
        up to `SWING_BEATS` intervals of it, at least `SWING_LOCK_MIN_BEATS`."""
        n = min(SWING_BEATS, int(i // self._period))
        if n >= SWING_LOCK_MIN_BEATS:
            self._swing_test(onset, self._grid_frames(i, n + 1))

    def _swing_guard(self, onset: np.ndarray) -> None:
        """The swing test (`_swing_test`) on the last `SWING_BEATS` intervals of reported beats,
        as many new beats after the last move of the grid."""
        n = SWING_BEATS + 1
        if len(self._support) - self._swing_tested < n:
            return
        frames = np.asarray(self._beat_frames[-n:]) - self._hist_start - 1
        if frames[0] < 0 or not _steady(self._period_at_beats[-n:]):
            return
        self._swing_test(onset, frames)

    def _swing_test(self, onset: np.ndarray, frames: np.ndarray) -> None:
        """Move the reported grid onto the beat when the onsets folded over the beats at history
        ``frames`` show it on swung off-beats (`swing_shift`)."""
        profile = beat_profile(frames, onset)
        shift = swing_shift(profile)
        # Stricter than offline, where the beats sit on their onsets: the reported grid may lie
        # a frame or two off them, which moves a straight off-beat to 0.45 or leaves the
        # beat's own onset tail above 0.25, and a grid at a wrong tempo folds its onsets
        # anywhere. So only a clear swing moves the grid: a late eighth at 0.58-0.7 of the beat
        # seen from the off-beat (a shift of 0.3-0.42), the profile's peak, the grid on onsets
        # of its own (the swung eighths), and nothing else of note in the beat.
        peak = float(profile.max())
        k = int(np.argmin(np.abs(SWING_FRACTIONS - shift)))
        near_grid = np.abs(SWING_FRACTIONS - np.round(SWING_FRACTIONS)) <= SWING_NEAR
        rest = ~near_grid & (np.abs(SWING_FRACTIONS - shift) > SWING_NEAR)
        if not (
            SWING_SHIFT_RANGE[0] <= shift <= SWING_SHIFT_RANGE[1]
            and profile[k] == peak
            and profile[near_grid].max() >= SWING_GRID_MIN * peak
            and profile[rest].max() <= SWING_REST_MAX * peak
        ):
            return
        self._shift_grid(shift)
        self._swing_tested = len(self._support)

    def _offbeat_vote(self, i: int) -> None:
        """Add BeatNet's activation at the reported beat at history frame ``i`` and at the
        midpoint before it to the vote since the lock; move the grid half a beat when the
        midpoints have carried ``OFFBEAT_VOTE_RATIO`` times as much over ``OFFBEAT_VOTE_BEATS``
        beats or more (item 5)."""
        learned = self._learned
        r = SUPPORT_RADIUS
        mid = round(i - self._period / 2)
        if mid - r < 0 or i + r >= len(learned):
            return
        self._vote += (max(learned[i - r : i + r + 1]), max(learned[mid - r : mid + r + 1]))
        self._vote_beats += 1
        if self._vote_beats >= OFFBEAT_VOTE_BEATS and self._vote[1] > OFFBEAT_VOTE_RATIO * max(
            self._vote[0], 1e-9
        ):
            self._shift_grid(0.5)
            self._vote = self._vote[::-1].copy()  # the midpoints are the beats now
            self._vote_beats = 0

    def _shift_grid(self, beats: float) -> None:
        """Move the reported grid ``beats`` later, the beats already predicted on it too; the
        next beat is not held back onto the old grid (`_hold_phase`)."""
        self._beat_offset += beats
        self._phase_free = True
        frames = beats * self._period
        self._scheduled = [t + frames * FRAME_S for t in self._scheduled]
        # Only beats still to come move: the frames already scored stay as they were.
        self._pending_support = [
            f + round(frames) if f > self._n_frames else f for f in self._pending_support
        ]
        self._pending_bar = [
            f + round(frames) if f > self._n_frames else f for f in self._pending_bar
        ]

    def _count_bar(self) -> None:
        """Downbeat evidence for beats heard up to one period after them: the kick/bass onset
        at the beat plus the change of the spectrum (chords change on beat 1) from the beat
        before to the beat after, and BeatNet's downbeat probability, each divided by its recent
        mean (the offline analyser's bass onsets + chord changes + BeatNet's vote; the mel
        spectrum stands in for chroma)."""
        period = max(1, round(self._period))
        newest = self._hist_start + len(self._mel)  # frame number of the newest frame
        while self._pending_bar and self._pending_bar[0] + period <= newest:
            beat = self._pending_bar.pop(0) - self._hist_start - 1  # history index
            index = self._beats_counted
            self._beats_counted += 1
            if beat - period < 0:
                continue
            low = max(self._low[max(0, beat - 3) : beat + 4])
            # Medians over the frames of a beat skip the drum hits and keep what sustains
            # (chords, bass); only the bands where chords lie count.
            mid = self._chord_bands
            before = np.median(np.asarray(self._mel[beat - period : beat])[:, mid], axis=0)
            after = np.median(np.asarray(self._mel[beat : beat + period])[:, mid], axis=0)
            change = float(np.mean(np.abs(after - before)))  # dB
            evidence = low / max(self._mean_low(low), 1e-9)
            evidence += change / max(self._mean_change(change), 1e-9)
            down = max(self._down[max(0, beat - 3) : beat + 4])
            evidence += down / max(self._mean_down(down), 1e-9)
            self._add_bar_evidence(evidence, index)

    def _add_bar_evidence(self, evidence: float, index: int) -> None:
        """Leaky per-position sums (about 5 bars) of the downbeat evidence."""
        pos = index % BEATS_PER_BAR
        self._bar_evidence *= BAR_EVIDENCE_DECAY
        self._bar_evidence[pos] += evidence
        # Hysteresis: the bar phase moves only when another phase is clearly stronger, so
        # that the count does not flicker where kicks fall on beats 1 and 3 alike.
        best = int(np.argmax(self._bar_evidence))
        if self._bar_evidence[best] > BAR_SWITCH_RATIO * self._bar_evidence[self._bar_phase]:
            self._bar_phase = best

    def _lock_need(self) -> int:
        """Beats in the lock's window: at least ``LOCK_MIN_WINDOW_BEATS``, spanning
        ``LOCK_SPAN_S``."""
        need = max(LOCK_BEATS, 1 + int(np.ceil(LOCK_SPAN_S / (self._period * FRAME_S) - 1e-9)))
        return max(need, LOCK_MIN_WINDOW_BEATS)

    def _grid_heard(self, onset: np.ndarray, i: int, n: int) -> list[bool] | None:
        """Whether each of the ``n`` beats of the current grid that end at history frame ``i``
        (a reported, supported beat), carried back over the music already heard, is supported
        as a reported beat would be (oldest first); None where the grid reaches back before
        the music (or the silence) began."""
        grid = [int(g) for g in self._grid_frames(i, n)]
        scored = [self._support_at(onset, g) for g in grid]
        if grid[0] - round(self._period) < 0 or any(s is None for s in scored):
            return None
        return [s[0] for s in scored if s is not None]

    def _heard_grid_fits(self, onset: np.ndarray, i: int, need: int, reported: bool) -> bool:
        """The retrospective lock's test of the heard grid (`_grid_heard`): with the last
        ``LOCK_RETRO_BEATS`` reported beats supported (``reported``), most of its last
        ``need`` beats supported (``LOCK_SUPPORT``); or, whatever the beat before, its last
        two bars supported on the same beats of the bar, at least ``LOCK_BAR_BEATS`` of each:
        a clave or a two-hit figure marks the same beats every bar and leaves the others
        empty, so two supported beats in a row come once a bar (every other beat does not
        count)."""
        bar = BEATS_PER_BAR
        if reported:
            heard = self._grid_heard(onset, i, need)
            if heard is not None and np.mean(heard) >= LOCK_SUPPORT:
                return True
        bars = self._grid_heard(onset, i, 2 * bar)
        if bars is None or bars[:bar] != bars[bar:] or sum(bars[bar:]) < LOCK_BAR_BEATS:
            return False
        # Every other beat supported is no bar figure: the grid runs at twice the rate of its
        # supported beats (a 4:3 tempo error on eighth-note hats does this), not at the beat.
        return bars[bar:] not in ([True, False] * (bar // 2), [False, True] * (bar // 2))

    def _steady_since(self, frame: int) -> bool:
        """Whether every tempo estimate in force since frame number ``frame`` stayed within
        ``STEADY_TEMPO_RATIO``: the tempo at the beats alone misses a tempo that flickered
        between them (an octave back and forth while the filter settles)."""
        after = [p for f, p in self._tempo_track if f > frame]
        before = [p for f, p in self._tempo_track if f <= frame][-1:]
        periods = before + after
        return bool(periods) and _steady(periods)

    def _update_lock(self, supported: bool, onset: np.ndarray, i: int) -> None:
        self._misses = 0 if supported else self._misses + 1
        need = self._lock_need()
        recent = self._support[-need:]
        periods = self._period_at_beats[-need:]
        steady = _steady(periods)
        if not self._locked:
            # Most, not all, beats must be supported: some styles leave one beat of the bar
            # empty (beat 3 of a clave pattern).
            forward = len(recent) == need and np.mean(recent) >= LOCK_SUPPORT and steady
            # Retrospective: the beats reported so far are few (the first tempo estimate
            # needs MIN_TEMPO_WINDOW_S, and 4 beats at 60 BPM take 4 s), but the music heard
            # before them is in the history: when the current grid, carried back over the
            # lock's window, lands on onsets there as it would on reported beats, the grid
            # has been supported for as long, only not reported. The tempo must have been
            # steady since the last LOCK_RETRO_BEATS reported beats (it is not an estimate of
            # a moment), and those beats supported (the score's phase has settled), unless the
            # heard grid shows a bar figure (`_heard_grid_fits`).
            retro = (
                len(recent) >= LOCK_RETRO_BEATS
                and self._steady_since(self._beat_frames[-LOCK_RETRO_BEATS])
                and self._heard_grid_fits(onset, i, need, all(recent[-LOCK_RETRO_BEATS:]))
            )
            periodic = self._periodicity >= LOCK_PERIODICITY
            if (forward or retro) and recent[-1] and periodic and self._bursty():
                self._locked = True
        elif self._misses >= UNLOCK_MISSES or (
            max(periods) / max(min(periods), 1e-9) > 1.25 and not all(recent[-2:])
        ):
            self._locked = False
            self._beat_offset = 0.0  # the held grid lost its onsets: follow the score again

    def _bursty(self) -> bool:
        """Whether the full-band flux of the last ``BURSTY_S`` varies as music's does
        (``BURSTY_CV``), not as steady noise's."""
        flux = np.asarray(self._flux[-round(BURSTY_S * self._fps) :])
        return float(flux.std()) >= BURSTY_CV * float(flux.mean())

    def _confidence(self) -> float:
        recent = self._support[-LOCK_BEATS:]
        return float(np.mean(recent)) if recent else 0.0

    def _beat_in_bar(self, index: int) -> int:
        return (index - self._bar_phase) % BEATS_PER_BAR

    def _emit(self, beat_s: float, now_s: float) -> BeatEvent:
        self._beat_index += 1
        self._last_beat_s = beat_s
        period_s = self._period * FRAME_S
        return BeatEvent(
            time_s=beat_s,
            reported_s=now_s,
            index=self._beat_index,
            beat_in_bar=self._beat_in_bar(self._beat_index - 1),
            tempo_bpm=60.0 / period_s if period_s > 0 else 0.0,
            locked=self._locked,
            confidence=self._confidence(),
        )
