"""Body moves: the trunk bounces, sways, nods and twists to the beat, beside the paw moves.

Body motion is data, like the paw moves of `quaddance.choreo.choreographer`: a `BodyMove`
lasts ``n_beats`` beats and is made of `Gesture` s, each driving one trunk column
(`quaddance.layout.BODY_COLUMNS`: height offset m, roll, pitch, yaw rad) with hits every
``every_beats`` beats. Two shapes:

- ``"dip"``: from rest to the amplitude and back around each hit (bounce, nod);
- ``"swing"``: from one side to the other, the hits alternating +A / -A (sway, twist).

A curve is rendered from *keyframes* (time, value): between two keyframes it follows a
minimum-jerk blend, so it rests (zero velocity and acceleration) at each of them and is C2
everywhere. Each hit is a keyframe on a beat, so every extremum of the motion - the visible
accent - lands ON the beat. Amplitudes are in robot units and scaled by loudness
(``0.4 + 0.6 * energy``), by `DOWNBEAT_BOOST` on downbeats and `SECTION_BOOST` on the first
downbeat of a section; a keyframe never asks for more change than the four-feet speed and
acceleration limits allow over its segment, so the shapes stay minimum-jerk on the robot.
Roll also leans the trunk away from a lifted foot (towards the stance side).

Sign conventions (right-handed, x forward, y left, z up): roll > 0 tilts the trunk to the
right (its left side up), pitch > 0 lowers the nose, yaw > 0 turns it to the left.

Users add moves and styles in a TOML file: `quaddance.choreo.moves_file.load_moves`.
This module must not import librosa or `quaddance.music`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from quaddance.choreo.choreographer import MOVES, STYLES
from quaddance.choreo.grid import MusicGrid, _moving_average
from quaddance.errors import QuaddanceError
from quaddance.layout import BODY_COLUMNS
from quaddance.lifts import MIN_JERK_PEAK_ACCEL, MIN_JERK_PEAK_SPEED, min_jerk
from quaddance.robots import GO1, BodyLimits

#: Amplitude factor on a downbeat ("one" gets a bigger gesture).
DOWNBEAT_BOOST = 1.3
#: Amplitude factor on the first downbeat of a section (a new part of the song).
SECTION_BOOST = 1.6
#: Weight factor of the section's signature body move (a motif within a section).
SIGNATURE_BOOST = 2.0
#: Keyframes closer than this are merged (the later one wins), s.
MIN_KEY_GAP_S = 0.04
#: Lean away from a lifted foot: roll per metre of left-minus-right foot height, rad/m,
#: saturating smoothly at `LEAN_MAX_RAD` (inside the paw-up roll range, 0.12 rad).
LEAN_RAD_PER_M = 0.8
LEAN_MAX_RAD = 0.10
#: While a foot is above this height the lean replaces the other roll gestures, m; the
#: hand-over is blended over `LEAN_BLEND_S` (averaged twice), so it never jerks the trunk.
LEAN_TAKEOVER_M = 0.02
LEAN_BLEND_S = 0.4
#: The lean follows the feet averaged over this window (twice), s: human feet move faster
#: than a trunk may turn; a centred average keeps the lean's peak on the lift's.
LEAN_SMOOTH_S = 0.2

Shape = Literal["dip", "swing"]
SHAPES: tuple[str, ...] = ("dip", "swing")


@dataclass(frozen=True)
class Gesture:
    """One trunk column moved by hits every ``every_beats`` beats from the move's start.

    ``amplitude`` is in the column's robot unit (m or rad), signed; ``width_beats`` is the
    time a dip takes down and back up, in beats (ignored by swings, which run from hit to
    hit).
    """

    column: str
    amplitude: float
    every_beats: float = 1.0
    shape: Shape = "dip"
    width_beats: float = 0.9

    @property
    def index(self) -> int:
        return BODY_COLUMNS.index(self.column)


@dataclass(frozen=True)
class BodyMove:
    """A body move of ``n_beats`` beats made of ``gestures`` (none = stand still). Its
    choice weight goes linearly from ``weight_quiet`` (energy 0) to ``weight_loud`` (1)."""

    name: str
    n_beats: int
    gestures: tuple[Gesture, ...]
    weight_quiet: float
    weight_loud: float


def _g(
    column: str, amplitude: float, every: float = 1.0, shape: Shape = "dip", width: float = 0.9
) -> Gesture:
    return Gesture(column, amplitude, every, shape, width)


# A dip every beat is as deep as the trunk's speed limits allow in a beat (about 3 cm at
# 120 BPM); the squat takes two beats to go deeper.
_BOUNCE = _g("height_offset_m", -0.04, width=1.0)
_NOD = _g("pitch_rad", 0.14)
_SWAY = _g("roll_rad", 0.12, 2.0, "swing")
_TWIST = _g("yaw_rad", 0.12, 2.0, "swing")

#: The body move vocabulary. Add a move here and every style and song can use it.
BODY_MOVES: tuple[BodyMove, ...] = (
    BodyMove("still", 2, (), weight_quiet=1.5, weight_loud=0.05),
    BodyMove("breathe", 4, (_g("height_offset_m", -0.02, 2.0),), 3.0, 0.1),
    BodyMove("bounce", 4, (_BOUNCE,), weight_quiet=1.0, weight_loud=2.0),
    BodyMove("sway", 4, (_SWAY,), weight_quiet=2.0, weight_loud=0.6),
    BodyMove("nod", 4, (_NOD,), weight_quiet=0.6, weight_loud=1.5),
    BodyMove("twist", 4, (_TWIST,), weight_quiet=0.8, weight_loud=0.5),
    BodyMove("bounce_sway", 4, (_BOUNCE, _SWAY), weight_quiet=0.5, weight_loud=2.0),
    BodyMove("nod_twist", 4, (_NOD, _TWIST), weight_quiet=0.3, weight_loud=1.5),
    BodyMove(
        "groove",
        4,
        (_g("height_offset_m", -0.025), _g("pitch_rad", 0.06), _SWAY),
        weight_quiet=0.2,
        weight_loud=2.0,
    ),
    BodyMove("shimmy", 2, (_g("roll_rad", 0.08, 1.0, "swing"),), 0.1, 1.0),
    BodyMove("rock", 4, (_g("pitch_rad", 0.08, 1.0, "swing"),), weight_quiet=0.3, weight_loud=1.2),
    BodyMove("squat", 4, (_g("height_offset_m", -0.05, 2.0, width=1.8),), 0.3, 1.0),
)

#: Styles re-weight the body moves by name; names not listed keep weight 1. Same style
#: names as the paw styles (`quaddance.choreo.choreographer.STYLES`).
BODY_STYLES: dict[str, dict[str, float]] = {
    "mixed": {},
    "calm": {"still": 2.0, "breathe": 2.0, "sway": 2.0, "groove": 0.3, "shimmy": 0.3},
    "energetic": {"still": 0.2, "breathe": 0.2, "bounce": 2.0, "groove": 2.0, "shimmy": 2.0},
    "footwork": {"bounce": 2.0, "nod": 1.5, "sway": 0.5, "twist": 0.5},
}


@dataclass
class MoveSet:
    """Moves and styles in use: the built-in ones plus those of a ``--moves`` file.

    ``styles`` map a style name to weights of body *and* paw move names; the paw part is
    passed to the paw choreographer, the body part used here.
    """

    body_moves: tuple[BodyMove, ...] = BODY_MOVES
    styles: dict[str, dict[str, float]] = field(default_factory=dict)
    source: str = "built-in"
    path: Path | None = field(default=None, compare=False)  #: the --moves file, if any

    def body_style(self, style: str) -> dict[str, float]:
        """The body-move weights of ``style``. A style of this set with a built-in name
        replaces the built-in's body weights only where it names a body move, as
        `paw_styles` does for paw moves: a style that re-weights the paws keeps its trunk."""
        body_names = {m.name for m in self.body_moves}
        if style in self.styles:
            body = {k: v for k, v in self.styles[style].items() if k in body_names}
            if body or style not in BODY_STYLES:
                return body
        if style in BODY_STYLES:
            return BODY_STYLES[style]
        raise QuaddanceError(
            f"unknown choreography style {style!r}; choose one of {sorted(self.style_names)}"
        )

    @property
    def style_names(self) -> set[str]:
        return set(BODY_STYLES) | set(STYLES) | set(self.styles)

    def paw_styles(self) -> dict[str, dict[str, float]]:
        """The paw styles in use: the built-in ones and the paw part of this set's styles (a
        style here may also be a built-in name: it then replaces that style's paw weights
        only where it names a paw move)."""
        styles = dict(STYLES)
        paw_names = {m.name for m in MOVES}
        for name, weights in self.styles.items():
            paw = {k: v for k, v in weights.items() if k in paw_names}
            styles[name] = paw or styles.get(name, {})
        return styles


@dataclass
class Keys:
    """Keyframes of one column: times (s) and values, appended in any order."""

    t_s: list[float] = field(default_factory=list)
    value: list[float] = field(default_factory=list)

    def add(self, t_s: float, value: float) -> None:
        self.t_s.append(float(t_s))
        self.value.append(float(value))


def render_keys(t_s: np.ndarray, key_t_s: np.ndarray, key_value: np.ndarray) -> np.ndarray:
    """Sample the minimum-jerk keyframe curve at times ``t_s`` (T,). Keyframe times must be
    increasing; before the first and after the last keyframe the curve holds its value."""
    t_s = np.asarray(t_s, dtype=np.float64)
    if key_t_s.size == 0:
        return np.zeros(t_s.size)
    if key_t_s.size == 1:
        return np.full(t_s.size, key_value[0])
    seg = np.clip(np.searchsorted(key_t_s, t_s, side="right") - 1, 0, key_t_s.size - 2)
    t0, t1 = key_t_s[seg], key_t_s[seg + 1]
    u = np.clip((t_s - t0) / (t1 - t0), 0.0, 1.0)
    return key_value[seg] + (key_value[seg + 1] - key_value[seg]) * min_jerk(u)


def _tidy_keys(keys: Keys, limits: BodyLimits, column: int) -> tuple[np.ndarray, np.ndarray]:
    """Sort keyframes, merge those closer than `MIN_KEY_GAP_S` (the later wins) and cap each
    step so the minimum-jerk segment keeps the column's speed and acceleration limits."""
    order = np.argsort(np.asarray(keys.t_s), kind="stable")
    t = np.asarray(keys.t_s)[order]
    v = np.asarray(keys.value)[order]
    keep = np.append(np.diff(t) >= MIN_KEY_GAP_S, True)
    t, v = t[keep], v[keep].copy()
    v_max, a_max = limits.max_speed[column], limits.max_accel[column]
    for k in range(1, t.size):
        d = t[k] - t[k - 1]
        room = min(v_max * d / MIN_JERK_PEAK_SPEED, a_max * d * d / MIN_JERK_PEAK_ACCEL)
        v[k] = v[k - 1] + np.clip(v[k] - v[k - 1], -room, room)
    return t, v


def _beat_time(beats_s: np.ndarray, period_s: np.ndarray, pos: float) -> float:
    """Time of fractional beat position ``pos``, s; past the last beat at its period."""
    i = min(int(pos), beats_s.size - 1)
    return float(beats_s[i] + (pos - i) * period_s[i])


def plan_body(
    grid: MusicGrid, seed: int = 0, style: str = "mixed", moves: MoveSet | None = None
) -> list[tuple[int, BodyMove]]:
    """Choose the body moves: a list of (first beat index, move), in time order."""
    moves = moves or MoveSet()
    weights_style = moves.body_style(style)
    vocab = moves.body_moves
    beats_s = grid.beats_s
    n_beats = beats_s.size
    if n_beats < 2 or not vocab:
        return []
    # Its own stream: adding body moves leaves the paw dance of a seed as it was.
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, grid.fingerprint(), 0xB0D1])
    beat_e = grid.energy_at(beats_s)
    section = grid.section_of(beats_s)
    section_e = np.bincount(section, weights=beat_e) / np.maximum(np.bincount(section), 1)
    energy = 0.5 * beat_e + 0.5 * section_e[section]
    w_quiet = np.array([m.weight_quiet for m in vocab])
    w_loud = np.array([m.weight_loud for m in vocab])
    w_style = np.array([weights_style.get(m.name, 1.0) for m in vocab])

    def weights(e: float) -> np.ndarray:
        w = np.maximum((w_quiet + (w_loud - w_quiet) * e) * w_style, 0.0)
        return w if w.sum() > 0 else np.ones_like(w)

    signature = []
    for e in section_e:
        w = weights(e)
        signature.append(int(rng.choice(len(vocab), p=w / w.sum())))
    plan: list[tuple[int, BodyMove]] = []
    i = 0
    while i < n_beats:
        w = weights(energy[i])
        w[signature[section[i]]] *= SIGNATURE_BOOST
        move = vocab[int(rng.choice(len(vocab), p=w / w.sum()))]
        plan.append((i, move))
        i += move.n_beats
    return plan


def _accent_factors(grid: MusicGrid, period_s: np.ndarray) -> np.ndarray:
    """(B,) amplitude factor of each beat: loudness, downbeats, section starts."""
    beats_s = grid.beats_s
    factor = 0.4 + 0.6 * grid.energy_at(beats_s)
    if grid.downbeats_s.size:
        near = np.abs(beats_s[:, None] - grid.downbeats_s[None, :]).min(axis=1)
        downbeat = near < 0.25 * period_s
    else:
        downbeat = np.arange(beats_s.size) % 4 == 0
    factor = np.where(downbeat, factor * DOWNBEAT_BOOST, factor)
    # The first downbeat at or after each section start gets the biggest gesture.
    for start in grid.sections_s[grid.sections_s > 0]:
        after = np.flatnonzero(downbeat & (beats_s >= start - 0.25 * period_s))
        if after.size:
            factor[after[0]] = factor[after[0]] / DOWNBEAT_BOOST * SECTION_BOOST
    return factor


def body_keys(
    grid: MusicGrid,
    plan: list[tuple[int, BodyMove]],
    limits: BodyLimits = GO1.body_four_feet,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Keyframes (times s, values) of each of the 4 columns for a plan of body moves,
    within the robot's four-feet range ``limits``."""
    beats_s = grid.beats_s
    n_beats = beats_s.size
    period_s = np.diff(beats_s) if n_beats > 1 else np.ones(1)
    period_s = np.append(period_s, period_s[-1])
    factor = _accent_factors(grid, period_s)
    keys = [Keys() for _ in BODY_COLUMNS]
    for col in keys:
        col.add(0.0, 0.0)
    for start, move in plan:
        used = {g.index for g in move.gestures}
        t_start = float(beats_s[start])
        for c in set(range(4)) - used:
            keys[c].add(t_start, 0.0)  # columns the move leaves alone come back to rest
        for g in move.gestures:
            sign = 1.0
            pos = 0.0
            while pos < move.n_beats - 1e-9 and start + pos <= n_beats - 1:
                beat = int(start + pos)
                t_hit = _beat_time(beats_s, period_s, start + pos)
                amp = g.amplitude * factor[beat] * sign
                if g.shape == "dip":
                    half = 0.5 * g.width_beats * period_s[beat]
                    keys[g.index].add(t_hit - half, 0.0)
                    keys[g.index].add(t_hit, amp)
                    keys[g.index].add(t_hit + half, 0.0)
                else:
                    keys[g.index].add(t_hit, amp)
                    sign = -sign
                pos += g.every_beats
    end_s = grid.duration_s
    out = []
    for c, col in enumerate(keys):
        col.add(end_s, 0.0)
        t, v = _tidy_keys(col, limits, c)
        lo, hi = limits.low[c], limits.high[c]
        out.append((t, np.clip(v, lo, hi)))
    return out


def lean_from_feet(feet_m: np.ndarray) -> np.ndarray:
    """Roll that leans away from a lifted foot (towards the stance side), rad, (T,).

    Lifting the left foot (FL on the robot) tilts the trunk to the right, roll > 0. Smooth
    (tanh of the feet's smooth curves), saturating at `LEAN_MAX_RAD`.
    """
    diff = np.asarray(feet_m, dtype=np.float64)[:, 0] - np.asarray(feet_m)[:, 1]
    return LEAN_MAX_RAD * np.tanh(LEAN_RAD_PER_M * diff / LEAN_MAX_RAD)


def choreograph_body(
    grid: MusicGrid,
    feet_m: np.ndarray | None,
    fps: float,
    seed: int = 0,
    style: str = "mixed",
    moves: MoveSet | None = None,
    limits: BodyLimits = GO1.body_four_feet,
) -> np.ndarray:
    """Body motion for ``grid``: (T, 4) = `BODY_COLUMNS` at ``fps`` Hz from t = 0,
    T = ceil(duration_s * fps) (the frames of `choreograph`).

    ``feet_m`` (T, 2) are the dance's human foot heights (from `choreograph` with the same
    fps), used for the lean away from a lifted foot; None: no lean. Deterministic for a
    given (grid, seed, style, moves). The values are in robot units and mostly inside the
    robot's four-feet range ``limits``; `quaddance.targets.feasible_body_targets` makes them
    exact.
    """
    if not fps > 0:
        raise QuaddanceError(f"fps must be > 0, got {fps}")
    n_frames = int(np.ceil(grid.duration_s * fps - 1e-9))
    t_s = np.arange(n_frames) / fps
    plan = plan_body(grid, seed=seed, style=style, moves=moves)
    body = np.zeros((n_frames, 4))
    if plan:
        for c, (kt, kv) in enumerate(body_keys(grid, plan, limits)):
            body[:, c] = render_keys(t_s, kt, kv)
    if feet_m is not None:
        feet = np.asarray(feet_m, dtype=np.float64)
        if feet.shape != (n_frames, 2):
            raise QuaddanceError(f"feet_m must have shape ({n_frames}, 2), got {feet.shape}")
        width = max(1, round(LEAN_SMOOTH_S * fps))
        feet = np.stack([_moving_average(_moving_average(f, width), width) for f in feet.T], axis=1)
        # While a foot is up the lean takes over the roll, so the sway never leans towards
        # the lifted paw.
        blend = max(1, round(LEAN_BLEND_S * fps))
        up = (np.asarray(feet_m).max(axis=1) > LEAN_TAKEOVER_M).astype(np.float64)
        up = np.clip(_moving_average(_moving_average(up, blend), blend), 0.0, 1.0)
        body[:, 1] = body[:, 1] * (1.0 - up) + lean_from_feet(feet)
    return body
