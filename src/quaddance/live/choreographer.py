"""On-the-fly choreography: the dance is planned a bar ahead on the beat grid that the online
tracker predicts, and streamed as robot targets (paws and trunk) at the policy rate.

The dance composer (`pipeline.compose`, the one that makes every dance) plans each segment
on a small `MusicGrid` of the predicted beats of the next segment (one to two bars, ending on
a downbeat), so a live dance is made of the same moves and the same feasible targets as a
planned one. Segments overlap by `TAIL_BEATS`: a lift or gesture on the last beat finishes
in the next segment's time (paws: the higher target; trunk: cross-faded). Without a stable
lock the robot holds a calm standing pose.

Rows are committed up to `planned_until_step` only (what follows is a tail that the next
segment may still change); `LOOKAHEAD_S` keeps them ahead of the dance, preview included
(`CALM_LOOKAHEAD_S` without a lock).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from quaddance.choreo.body import plan_body
from quaddance.choreo.grid import MusicGrid
from quaddance.layout import BEATS_PER_BAR, BODY, FRONT_PAWS, N_BODY, PAWS, row_width
from quaddance.lifts import min_jerk
from quaddance.pipeline import DanceSpec, compose
from quaddance.targets import continue_body_targets

#: While dancing, committed targets reach at least this far (and a bar more) past the song's
#: "now", s: the policy's preview (0.4 s) plus the audio-to-command latency (45 ms), with
#: 0.25 s for planning a bar (at most 14 ms measured).
LOOKAHEAD_S = 0.7
#: Beats each segment runs past its end, for lifts and gestures that land on its last beat.
TAIL_BEATS = 1.0
#: Loudness history the choreographer reads, s: "loud" means loud for this song so far.
ENERGY_HISTORY_S = 20.0
ENERGY_FPS = 10.0
#: Without a lock, calm rows are final only this far past "now", s: the preview plus the
#: latency, with 55 ms for the first plan after a lock, which starts where they end (if it
#: came late, the preview would hold the calm pose a few ticks longer: harmless). 0.2 s less
#: than `LOOKAHEAD_S`, so the first move after a lock comes 0.2 s sooner.
CALM_LOOKAHEAD_S = 0.5
#: Length of a calm chunk, s: short, so that a plan starts soon after a lock.
CALM_CHUNK_S = 0.04


@dataclass
class Segment:
    """A planned stretch of the dance, for logs and the viewer."""

    start_s: float
    end_s: float
    tempo_bpm: float
    move: str  # the trunk's move at its start ("calm" without a lock)


class LiveChoreographer:
    """Turns tracker states into a growing (T, 8) array of target rows (`quaddance.layout`:
    paws, then trunk) from song time 0 at ``policy_hz``. Segment k is the dance of ``spec``
    with seed ``spec.seed + k``."""

    def __init__(self, policy_hz: float, spec: DanceSpec | None = None) -> None:
        self.hz = float(policy_hz)
        spec = spec or DanceSpec()
        self.spec = dataclasses.replace(
            spec, targets=dataclasses.replace(spec.targets, out_fps=self.hz)
        )
        self.cfg = self.spec.targets
        self.rows = np.zeros((0, row_width(body=True)))
        self.planned_until_step = 0  # rows before this are final
        self.segments: list[Segment] = []
        self._energy: list[tuple[float, float]] = []  # (song s, 0..1)

    # --- input -------------------------------------------------------------------------------
    def update(self, state, now_s: float) -> int:
        """Plan as far as needed for song time ``now_s`` given tracker ``state`` (duck-typed
        `music.online_beats.TrackerState`). Returns the number of final rows."""
        if np.isfinite(state.energy):
            self._energy.append((now_s, float(state.energy)))
        locked = bool(state.locked) and state.beat_period_s > 0 and np.isfinite(state.next_beat_s)
        ahead_s = LOOKAHEAD_S + BEATS_PER_BAR * state.beat_period_s if locked else CALM_LOOKAHEAD_S
        while self.planned_until_step / self.hz < now_s + ahead_s:
            if locked:
                self._plan_bar(state)
            else:
                self._calm(CALM_CHUNK_S)
        return self.planned_until_step

    @property
    def current_move(self) -> str:
        return self.segments[-1].move if self.segments else "calm"

    def move_at(self, t_s: float) -> str:
        """The move danced at song time ``t_s``."""
        for seg in reversed(self.segments):
            if seg.start_s <= t_s:
                return seg.move
        return "calm"

    def final_rows(self, start: int) -> np.ndarray:
        """Final rows from index ``start`` on (those not yet handed out)."""
        return self.rows[start : self.planned_until_step]

    # --- planning ----------------------------------------------------------------------------
    def _calm(self, chunk_s: float) -> None:
        start = self.planned_until_step
        n = max(1, round(chunk_s * self.hz))
        self._write(start, np.zeros((n, row_width(body=True))))
        self.planned_until_step = start + n
        if not self.segments or self.segments[-1].move != "calm":
            self.segments.append(Segment(start / self.hz, (start + n) / self.hz, 0.0, "calm"))
        else:
            self.segments[-1].end_s = (start + n) / self.hz

    def _predicted_beats(
        self, state, start_s: float, end_s: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Predicted beat times in [start_s, end_s) and their positions in the bar."""
        period = state.beat_period_s
        k0 = int(np.floor((start_s - state.next_beat_s) / period))
        k = np.arange(k0, k0 + int((end_s - start_s) / period) + 3)
        times = state.next_beat_s + k * period
        in_bar = (state.next_beat_in_bar + k) % BEATS_PER_BAR
        keep = (times >= start_s - 1e-9) & (times < end_s - 1e-9)
        return times[keep], in_bar[keep]

    def _plan_bar(self, state) -> None:
        period = state.beat_period_s
        start_step = self.planned_until_step
        start_s = start_step / self.hz
        # The segment's beats: from half a beat after its start (the beat at the start
        # belongs to the previous segment) to the first predicted downbeat at least a bar
        # away, which opens the next segment.
        beats, in_bar = self._predicted_beats(
            state, start_s + 0.5 * period, start_s + 3 * BEATS_PER_BAR * period
        )
        later = beats[(in_bar == 0) & (beats >= start_s + BEATS_PER_BAR * period - 1e-6)]
        end_s = float(later[0]) if later.size else start_s + (BEATS_PER_BAR + 0.5) * period
        seg = beats < end_s - 1e-6
        seg_beats, seg_in_bar = beats[seg], in_bar[seg]
        # The grid starts ENERGY_HISTORY_S earlier (on a policy step), so that its loudness
        # envelope can say how loud this bar is for the song so far.
        origin_step = max(0, start_step - round(ENERGY_HISTORY_S * self.hz))
        origin_s = origin_step / self.hz
        duration_s = end_s + TAIL_BEATS * period - origin_s
        grid = MusicGrid(
            duration_s=duration_s,
            beats_s=seg_beats - origin_s,
            downbeats_s=seg_beats[seg_in_bar == 0] - origin_s,
            energy=self._energy_envelope(origin_s, duration_s, state.energy),
            energy_fps=ENERGY_FPS,
            sections_s=np.zeros(0),
        )
        spec = dataclasses.replace(self.spec, seed=self.spec.seed + len(self.segments))
        dance = compose(spec, grid)
        rows = np.concatenate([dance.targets_m, dance.body_targets], axis=1)
        rows = rows[start_step - origin_step :]
        _drop_cut_lifts(rows)
        # The trunk hands over from the old plan by the segment's first beat, so that
        # beat's gesture is the new plan's own (a fade past it halved a downbeat's accent).
        self._write(start_step, rows, fade_steps=round((seg_beats[0] - start_s) * self.hz))
        # Final up to the segment's last beat: its lift falls, and the next segment's first
        # lift rises, in the overlap that the next plan blends.
        commit_s = max(start_s + 1.0 / self.hz, end_s - period)
        self.planned_until_step = min(round(commit_s * self.hz), self.rows.shape[0])
        plan = plan_body(grid, seed=spec.seed, style=spec.style, moves=spec.moves)
        move = plan[0][1].name if plan else "hold"
        self.segments.append(Segment(start_s, commit_s, 60.0 / period, move))

    def _energy_envelope(self, origin_s: float, duration_s: float, now: float) -> np.ndarray:
        n = max(2, int(np.ceil(duration_s * ENERGY_FPS)))
        t = origin_s + np.arange(n) / ENERGY_FPS
        if not self._energy:
            return np.full(n, now)
        hist_t, hist_e = np.array(self._energy).T
        # The future is assumed as loud as now; the past is what the tracker measured.
        return np.interp(t, np.append(hist_t, t[-1] + 1.0), np.append(hist_e, now))

    def _write(self, start: int, new: np.ndarray, fade_steps: int = 0) -> None:
        """Put ``new`` rows at ``start``. Over an earlier plan's tail the paws take the
        higher target; the trunk cross-fades from the old plan (or, past its end, from the
        last final pose held) to the new one over ``fade_steps``, with a minimum-jerk weight
        so that position, velocity and acceleration stay continuous at both ends, and within
        the trunk's speed and acceleration bounds (`targets.continue_body_targets`)."""
        have = self.rows.shape[0]
        new = new.copy()
        n_tail = max(0, min(have - start, new.shape[0]))
        old_paws = self.rows[start : start + n_tail, PAWS]
        new[:n_tail, PAWS] = np.maximum(old_paws, new[:n_tail, PAWS])
        n_fade = min(new.shape[0], fade_steps)
        if n_fade > 0:
            last = self.rows[start - 1, BODY] if start > 0 else np.zeros(N_BODY)
            old = np.tile(last, (n_fade, 1))
            n_old = min(n_tail, n_fade)
            old[:n_old] = self.rows[start : start + n_old, BODY]
            w = min_jerk(np.arange(1, n_fade + 1) / (n_fade + 1))[:, None]
            new[:n_fade, BODY] = (1 - w) * old + w * new[:n_fade, BODY]
        if start >= 2:
            # The trunk keeps the offline targets' speed and acceleration bounds across the
            # seam, and when a lost lock sends it back to the calm pose.
            sent = self.rows[start - 2 : start, BODY]
            new[:, BODY] = continue_body_targets(new[:, BODY], sent, 1.0 / self.hz, self.cfg.robot)
        self.rows = np.concatenate([self.rows[:start], new], axis=0)
        _one_paw_at_a_time(self.rows, start, round(self.cfg.min_ground_s * self.hz))


def _drop_cut_lifts(rows: np.ndarray, eps_m: float = 1e-3) -> None:
    """Zero, in place, a front-paw lift already under way at the first row (its rise was
    planned before the segment and cut off): the paw stays down until that lift would end."""
    for k in (0, 1):
        if rows.shape[0] and rows[0, k] > eps_m:
            down = np.flatnonzero(rows[:, k] <= eps_m)
            end = int(down[0]) if down.size else rows.shape[0]
            rows[:end, k] = 0.0


def _lift_runs(paws: np.ndarray, eps_m: float) -> list[tuple[int, int, int]]:
    """(start row, end row, paw) of each run of rows with a front paw above ``eps_m``,
    sorted by start."""
    runs = []
    for k in (0, 1):
        up = np.concatenate([[False], paws[:, k] > eps_m, [False]])
        edges = np.flatnonzero(np.diff(up.astype(np.int8)))
        runs += [(int(a), int(b), k) for a, b in zip(edges[::2], edges[1::2], strict=True)]
    return sorted(runs)


def _one_paw_at_a_time(
    rows: np.ndarray, first_free: int, min_ground_steps: int, eps_m: float = 1e-3
) -> None:
    """Keep, in place, the offline rule that one front paw is up at a time with both down for
    ``min_ground_steps`` between lifts, across a seam: the higher-target blend of an old
    plan's tail and a new plan can overlap a lift of one paw with a lift of the other, and
    with both front paws up the robot falls (seen live at 141 BPM). Of two lifts too close,
    the later one is dropped; rows before ``first_free`` are final and are never changed
    (they obey the rule among themselves, so the later lift always starts after them)."""
    first = max(0, first_free - 1)  # a lift under way at the seam is seen from its row before
    lookback = first
    while lookback > 0 and np.any(rows[lookback - 1, FRONT_PAWS] > eps_m):
        lookback -= 1  # from the start of any lift still under way at the seam
    base = max(0, lookback - min_ground_steps)
    busy_until = -(10**9)  # last row of the lifts kept so far
    for a, b, k in _lift_runs(rows[base:, FRONT_PAWS], eps_m):
        a, b = a + base, b + base
        if a - busy_until <= min_ground_steps and a >= first_free:
            rows[a:b, k] = 0.0
        else:
            busy_until = max(busy_until, b - 1)
