"""Beats and downbeats from a beat activation: a bar-pointer hidden Markov model (the decoder
of the BeatNet tracker that the real-music benchmark compares ours with, `quaddance.music.beatnet`).

The model is the one the field's DBN trackers decode (Whiteley, Cemgil and Godsill 2006; the
discretised state space of Krebs, Böck and Widmer, ISMIR 2015, as madmom's
``DBNDownBeatTrackingProcessor`` uses it): a hidden state is (meter, tempo, position in the
bar); the position advances by one frame per frame; the tempo may change only where a beat
starts, by a factor whose probability falls exponentially with its distance from 1. A state in
the first ``1 / observation_lambda`` of a beat "sees" the activation of a beat (of a downbeat
for the first beat of the bar); any other state sees the rest. ``decode`` finds the most likely
path over a whole song (Viterbi).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DecoderConfig:
    """The model's few settings: madmom's ``DBNDownBeatTrackingProcessor`` defaults (what
    BeatNet's offline mode decodes its activations with), but for the meters (3 and 4)."""

    min_bpm: float = 55.0
    """Slowest beat the model holds, BPM."""
    max_bpm: float = 215.0
    """Fastest beat the model holds, BPM."""
    beats_per_bar: tuple[int, ...] = (3, 4)
    """Meters the model chooses from."""
    transition_lambda: float = 100.0
    """Steepness of the tempo-change probability exp(-lambda |ratio - 1|)."""
    observation_lambda: int = 16
    """A beat's activation is seen in the first 1/lambda of the beat."""
    num_tempi: int = 60
    """Tempi (beat intervals in whole frames, log spaced) at most."""


@dataclass(frozen=True)
class BarStateSpace:
    """All (meter, tempo, position) states, in one flat array per attribute."""

    intervals: np.ndarray  # (n_tempi,) frames per beat
    meters: np.ndarray  # (n_blocks,) beats per bar of each (meter, tempo) block
    block_interval: np.ndarray  # (n_blocks,) frames per beat of each block
    block_start: np.ndarray  # (n_blocks,) first state of each block
    prev: np.ndarray  # (n_states,) the state each state comes from inside its block
    beat_start: np.ndarray  # (n_beat_starts,) states at the start of a beat
    beat_start_block: np.ndarray  # (n_beat_starts,) their block
    beat_start_from: np.ndarray  # (n_beat_starts, n_tempi) last state of the beat before
    log_trans: np.ndarray  # (n_beat_starts, n_tempi) log P(tempo of the start | tempo before)
    position: np.ndarray  # (n_states,) position in the bar, frames
    beat_index: np.ndarray  # (n_states,) beat of the bar (0 = downbeat)
    in_beat: np.ndarray  # (n_states,) bool: in the first 1/lambda of its beat
    interval: np.ndarray  # (n_states,) frames per beat

    @property
    def n_states(self) -> int:
        return len(self.prev)


def _intervals(fps: float, cfg: DecoderConfig) -> np.ndarray:
    lo, hi = 60.0 * fps / cfg.max_bpm, 60.0 * fps / cfg.min_bpm
    lo_i, hi_i = int(np.ceil(lo)), int(np.floor(hi))
    if hi_i - lo_i + 1 <= cfg.num_tempi:
        return np.arange(lo_i, hi_i + 1)
    return np.unique(np.round(np.exp(np.linspace(np.log(lo_i), np.log(hi_i), cfg.num_tempi))))


def state_space(fps: float, cfg: DecoderConfig = DecoderConfig()) -> BarStateSpace:
    """The bar-pointer states for activations at ``fps`` frames/s."""
    intervals = _intervals(fps, cfg).astype(int)
    n_t = len(intervals)
    meters, block_int, starts = [], [], []
    prev, pos, beat_idx, in_beat, interval = [], [], [], [], []
    bs, bs_block, bs_from, bs_trans = [], [], [], []
    # P(new interval | old): exp(-lambda |new / old - 1|), normalised over the new ones.
    ratio = intervals[None, :] / intervals[:, None]
    trans = np.exp(-cfg.transition_lambda * np.abs(ratio - 1.0))
    trans /= trans.sum(axis=1, keepdims=True)
    with np.errstate(divide="ignore"):
        log_trans_old_new = np.log(trans)
    offset = 0
    block_of: dict[tuple[int, int], int] = {}
    for meter in cfg.beats_per_bar:
        for j, ivl in enumerate(intervals):
            block_of[(meter, j)] = len(meters)
            meters.append(meter)
            block_int.append(ivl)
            starts.append(offset)
            n = meter * ivl
            p = np.arange(n)
            pos.append(p)
            prev.append(offset + (p - 1) % n)
            beat_idx.append(p // ivl)
            in_beat.append((p % ivl) < max(1, ivl // cfg.observation_lambda))
            interval.append(np.full(n, ivl))
            offset += n
    block_start = np.array(starts)
    for meter in cfg.beats_per_bar:
        for j, ivl in enumerate(intervals):
            b = block_of[(meter, j)]
            for k in range(meter):
                bs.append(block_start[b] + k * ivl)
                bs_block.append(b)
                # The beat before (k - 1 mod meter) ends at its last frame, at any tempo.
                k_prev = (k - 1) % meter
                bs_from.append(
                    [
                        block_start[block_of[(meter, jj)]] + (k_prev + 1) * intervals[jj] - 1
                        for jj in range(n_t)
                    ]
                )
                bs_trans.append(log_trans_old_new[:, j])
    return BarStateSpace(
        intervals=intervals,
        meters=np.array(meters),
        block_interval=np.array(block_int),
        block_start=block_start,
        prev=np.concatenate(prev),
        beat_start=np.array(bs),
        beat_start_block=np.array(bs_block),
        beat_start_from=np.array(bs_from),
        log_trans=np.array(bs_trans),
        position=np.concatenate(pos),
        beat_index=np.concatenate(beat_idx),
        in_beat=np.concatenate(in_beat),
        interval=np.concatenate(interval),
    )


def log_observation(act: np.ndarray, cfg: DecoderConfig) -> np.ndarray:
    """(n, 3) log densities of the three kinds of state (downbeat, other beat, no beat) for
    (n, 2) activations (P(beat), P(downbeat)); ``state_kind`` says which kind a state is."""
    eps = 1e-7
    beat, down = act[:, 0], act[:, 1]
    none = (1.0 - beat - down) / (cfg.observation_lambda - 1)
    return np.log(np.clip(np.stack([down, beat, none], axis=1), eps, None))


def state_kind(space: BarStateSpace) -> np.ndarray:
    """(n_states,) 0 downbeat region, 1 other beat region, 2 elsewhere."""
    kind = np.full(space.n_states, 2)
    kind[space.in_beat & (space.beat_index == 0)] = 0
    kind[space.in_beat & (space.beat_index > 0)] = 1
    return kind


@dataclass(frozen=True)
class Decoded:
    """A decoded path: its beats, which of them start a bar, and the meter chosen."""

    beat_frames: np.ndarray  # (n_beats,) increasing frames, fractional (the peak's vertex)
    downbeat: np.ndarray  # (n_beats,) bool
    beats_per_bar: int


def decode(act: np.ndarray, fps: float, cfg: DecoderConfig = DecoderConfig()) -> Decoded:
    """The most likely bar-pointer path through (n, 2) activations (Viterbi).

    Each beat is placed at the frame of its beat region where the activation peaks (the path
    enters the region on a frame grid; the peak is where the network heard the beat).
    """
    act = np.asarray(act, dtype=np.float64)
    space = state_space(fps, cfg)
    kind = state_kind(space)
    obs = log_observation(act, cfg)
    n = len(act)
    if n == 0:
        return Decoded(np.zeros(0), np.zeros(0, bool), max(cfg.beats_per_bar))
    # Uniform start over all states.
    delta = obs[0][kind] - np.log(space.n_states)
    back = np.empty((n, len(space.beat_start)), dtype=np.int16)
    for t in range(1, n):
        new = delta[space.prev]
        cand = delta[space.beat_start_from] + space.log_trans
        best = np.argmax(cand, axis=1)
        back[t] = best
        new[space.beat_start] = cand[np.arange(len(best)), best]
        delta = new + obs[t][kind]
        delta -= delta.max()  # keep the numbers in range; the argmax is unchanged
    # Backtrack: inside a beat the state came from `prev`; at a beat start, from `back`.
    start_slot = np.full(space.n_states, -1)
    start_slot[space.beat_start] = np.arange(len(space.beat_start))
    path = np.empty(n, dtype=int)
    s = int(np.argmax(delta))
    for t in range(n - 1, -1, -1):
        path[t] = s
        if t == 0:
            break
        slot = start_slot[s]
        s = int(space.beat_start_from[slot, back[t, slot]]) if slot >= 0 else int(space.prev[s])
    return _beats_of_path(space, path, act)


def _beats_of_path(space: BarStateSpace, path: np.ndarray, act: np.ndarray) -> Decoded:
    in_beat = space.in_beat[path]
    # Runs of frames inside one beat region: a new run starts where the path enters one.
    starts = np.flatnonzero(in_beat & ~np.concatenate([[False], in_beat[:-1]]))
    strength = act.sum(axis=1)
    frames, down = [], []
    for s in starts:
        e = s
        while e + 1 < len(path) and in_beat[e + 1]:
            e += 1
        frames.append(peak_vertex(strength, s + int(np.argmax(strength[s : e + 1]))))
        down.append(space.beat_index[path[s]] == 0)
    meter = int(space.meters[np.searchsorted(space.block_start, path[-1], "right") - 1])
    return Decoded(np.array(frames, float), np.array(down, bool), meter)


def peak_vertex(x: np.ndarray, j: int) -> float:
    """Frame ``j`` of ``x`` moved to the vertex of the parabola through it and its neighbours
    where it is a peak (the vertex then lies within half a frame), else ``j`` itself."""
    if 0 < j < len(x) - 1:
        y0, y1, y2 = x[j - 1], x[j], x[j + 1]
        denom = y0 - 2 * y1 + y2
        if y1 >= max(y0, y2) and denom < 0:
            return j + 0.5 * (y0 - y2) / denom
    return float(j)
