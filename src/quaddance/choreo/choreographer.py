"""The built-in choreographer: a beat-synchronous human foot dance from a `MusicGrid`.

A dance is a sequence of *moves* from a small vocabulary (`MOVES`), one chosen at a time by a
seeded random generator, weighted by how loud the music is there and by the section's
signature move. A move is a few *steps*, each a lift of one foot (`LIFTS`) on a beat or a
half beat. Lifts **peak on the beat**: the foot is highest, and still, on the count, which is
where beat-alignment metrics (BAS) look for motion beats.

Human plausibility is kept by construction:
- one foot is always on the ground: lifts never overlap in time, and between any two lifts
  both feet rest on the floor for at least `MIN_GROUND_S`;
- curves are smooth: each lift rises and falls along a minimum-jerk profile, so height,
  velocity and acceleration are continuous (C2) and every lift starts and ends at rest;
- heights stay human: taps mostly 0.08-0.15 m, knee lifts up to about 0.4 m, never above
  `MAX_HEIGHT_M`, and never faster than `MAX_FOOT_SPEED_M_S`.

To add a move, add one `Move` line to `MOVES` (and, for a new kind of lift, one entry to
`LIFTS`). This module must not import librosa or `quaddance.music`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from quaddance.choreo.grid import MusicGrid
from quaddance.errors import QuaddanceError
from quaddance.lifts import MIN_JERK_PEAK_SPEED, LiftPlan, render_lifts

if TYPE_CHECKING:
    from quaddance.choreo.body import MoveSet

#: Highest a human foot goes in this dance, m (a high knee lift of an adult).
MAX_HEIGHT_M = 0.45
#: Fastest vertical foot speed allowed, m/s (quick dance steps; estimate, not measured).
MAX_FOOT_SPEED_M_S = 3.0
#: Time both feet rest on the floor between two lifts, s (about two frames at 60 fps).
MIN_GROUND_S = 0.03
#: Shortest rise or fall of a lift, s; a lift too cramped for it is dropped.
MIN_PHASE_S = 0.03
#: Height factor for a step that lands on a downbeat (the accent on "one").
DOWNBEAT_ACCENT = 1.3
#: Weight factor of the section's signature move: dances repeat a motif within a section.
SIGNATURE_BOOST = 3.0


@dataclass(frozen=True)
class Lift:
    """One kind of foot lift: its nominal height (m, before energy and accent) and the time
    it takes to rise to the peak and fall back, as fractions of the local beat period."""

    height_m: float
    rise_beats: float
    fall_beats: float


#: The kinds of lift, from a quick eighth-note step to a knee lift.
LIFTS: dict[str, Lift] = {
    "run": Lift(height_m=0.06, rise_beats=0.2, fall_beats=0.2),
    "step": Lift(height_m=0.08, rise_beats=0.3, fall_beats=0.35),
    "tap": Lift(height_m=0.11, rise_beats=0.3, fall_beats=0.35),
    "kick": Lift(height_m=0.22, rise_beats=0.4, fall_beats=0.5),
    "knee": Lift(height_m=0.32, rise_beats=0.55, fall_beats=0.8),
}


@dataclass(frozen=True)
class Step:
    """A lift of one foot at ``at_beats`` beats after the move starts (0, 0.5, 1, ...).
    ``foot`` is relative: the move's leading foot or the other one."""

    at_beats: float
    foot: Literal["lead", "other"]
    lift: str


@dataclass(frozen=True)
class Move:
    """A move of ``n_beats`` beats made of ``steps`` (in time order; none = a hold).
    Its choice weight goes linearly from ``weight_quiet`` (energy 0) to ``weight_loud``
    (energy 1), so loud passages get more and bigger moves."""

    name: str
    n_beats: int
    steps: tuple[Step, ...]
    weight_quiet: float
    weight_loud: float


def _s(at_beats: float, foot: Literal["lead", "other"], lift: str) -> Step:
    return Step(at_beats, foot, lift)


#: The move vocabulary. Add a move here and every style and song can use it.
MOVES: tuple[Move, ...] = (
    Move("hold", 2, (), weight_quiet=3.0, weight_loud=0.2),
    Move("tap", 1, (_s(0, "lead", "tap"),), weight_quiet=2.0, weight_loud=0.8),
    Move("tap_rest", 2, (_s(0, "lead", "tap"),), weight_quiet=1.5, weight_loud=0.3),
    Move(
        "step_pair",
        2,
        (_s(0, "lead", "step"), _s(1, "other", "step")),
        weight_quiet=2.0,
        weight_loud=1.5,
    ),
    Move(
        "double_tap",
        2,
        (_s(0, "lead", "tap"), _s(1, "lead", "tap")),
        weight_quiet=1.0,
        weight_loud=1.0,
    ),
    Move(
        "run",
        2,
        (
            _s(0, "lead", "run"),
            _s(0.5, "other", "run"),
            _s(1, "lead", "run"),
            _s(1.5, "other", "run"),
        ),
        weight_quiet=0.2,
        weight_loud=2.0,
    ),
    Move(
        "pickup",
        2,
        (_s(0, "lead", "step"), _s(1.5, "other", "run")),
        weight_quiet=0.4,
        weight_loud=1.0,
    ),
    Move(
        "kick_step",
        2,
        (_s(0, "lead", "kick"), _s(1, "other", "tap")),
        weight_quiet=0.3,
        weight_loud=1.5,
    ),
    Move("knee_lift", 2, (_s(0, "lead", "knee"),), weight_quiet=0.2, weight_loud=1.2),
)

#: Styles re-weight the vocabulary by move name; names not listed keep weight 1.
STYLES: dict[str, dict[str, float]] = {
    "mixed": {},
    "calm": {"hold": 2.0, "tap_rest": 2.0, "run": 0.2, "kick_step": 0.3, "knee_lift": 0.3},
    "energetic": {"hold": 0.3, "tap_rest": 0.3, "run": 2.0, "kick_step": 2.0, "knee_lift": 2.0},
    "footwork": {"run": 3.0, "pickup": 2.0, "step_pair": 2.0, "knee_lift": 0.3, "kick_step": 0.5},
}


def _beat_time(beats_s: np.ndarray, pos: float) -> float:
    """Time of fractional beat position ``pos`` (0 = first beat), s, between beats linearly."""
    i = min(int(pos), beats_s.size - 2)
    return float(beats_s[i] + (pos - i) * (beats_s[i + 1] - beats_s[i]))


def plan_dance(
    grid: MusicGrid,
    seed: int = 0,
    style: str = "mixed",
    styles: dict[str, dict[str, float]] | None = None,
) -> LiftPlan:
    """Choose the moves for ``grid`` and return their lifts, timed and sized (see module).
    ``styles`` replaces `STYLES` (a ``--moves`` file adds styles)."""
    styles = STYLES if styles is None else styles
    if style not in styles:
        raise QuaddanceError(
            f"unknown choreography style {style!r}; choose one of {sorted(styles)}"
        )
    beats_s = grid.beats_s
    n_beats = beats_s.size
    empty = np.zeros(0)
    if n_beats < 2:
        return LiftPlan(np.zeros(0, dtype=np.int64), empty, empty, empty, empty)
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, grid.fingerprint()])

    # Loudness that steers each choice: half the beat's own, half its section's mean, so a
    # loud section stays lively through its quieter bars.
    beat_e = grid.energy_at(beats_s)
    section = grid.section_of(beats_s)
    section_e = np.bincount(section, weights=beat_e) / np.maximum(np.bincount(section), 1)
    energy = 0.5 * beat_e + 0.5 * section_e[section]

    period_s = np.diff(beats_s)
    period_s = np.append(period_s, period_s[-1])
    if grid.downbeats_s.size:
        near = np.abs(beats_s[:, None] - grid.downbeats_s[None, :]).min(axis=1)
        downbeat = near < 0.25 * period_s
    else:
        downbeat = np.arange(n_beats) % 4 == 0

    w_quiet = np.array([m.weight_quiet for m in MOVES])
    w_loud = np.array([m.weight_loud for m in MOVES])
    w_style = np.array([styles[style].get(m.name, 1.0) for m in MOVES])
    # Each section gets a signature move, drawn by the section's loudness.
    signature = []
    for e in section_e:
        w = (w_quiet + (w_loud - w_quiet) * e) * w_style
        signature.append(int(rng.choice(len(MOVES), p=w / w.sum())))

    feet, peaks, heights, rises, falls = [], [], [], [], []
    last_foot = int(rng.integers(2))
    i = 0
    while i < n_beats:
        e = energy[i]
        w = (w_quiet + (w_loud - w_quiet) * e) * w_style
        w[signature[section[i]]] *= SIGNATURE_BOOST
        move = MOVES[int(rng.choice(len(MOVES), p=w / w.sum()))]
        # Mostly alternate the leading foot, as dancers do, but not always.
        lead = 1 - last_foot if rng.random() < 0.75 else last_foot
        for step in move.steps:
            pos = i + step.at_beats
            if pos > n_beats - 1:
                break  # the music has no beat left to put this step on
            beat = int(pos)
            lift = LIFTS[step.lift]
            height = lift.height_m * (0.75 + 0.5 * e) * rng.uniform(0.9, 1.1)
            if pos == beat and downbeat[beat]:
                height *= DOWNBEAT_ACCENT
            foot = lead if step.foot == "lead" else 1 - lead
            feet.append(foot)
            peaks.append(_beat_time(beats_s, pos))
            heights.append(height)
            rises.append(lift.rise_beats * period_s[beat])
            falls.append(lift.fall_beats * period_s[beat])
            last_foot = foot
        i += move.n_beats

    plan = LiftPlan(
        foot=np.asarray(feet, dtype=np.int64),
        peak_s=np.asarray(peaks, dtype=np.float64),
        height_m=np.asarray(heights, dtype=np.float64),
        rise_s=np.asarray(rises, dtype=np.float64),
        fall_s=np.asarray(falls, dtype=np.float64),
    )
    return _make_plausible(plan, grid.duration_s)


def _make_plausible(plan: LiftPlan, duration_s: float) -> LiftPlan:
    """Squeeze rises and falls so lifts never overlap and leave `MIN_GROUND_S` between
    them, keep them inside the song, and cap heights by `MAX_HEIGHT_M` and speed."""
    if len(plan) == 0:
        return plan
    peak, rise, fall = plan.peak_s, plan.rise_s.copy(), plan.fall_s.copy()
    # Each fall belongs to one gap and each rise to one gap, so the squeeze is vectorised.
    room = np.diff(peak) - MIN_GROUND_S
    need = fall[:-1] + rise[1:]
    squeeze = np.where(need > room, np.maximum(room, 0.0) / need, 1.0)
    fall[:-1] *= squeeze
    rise[1:] *= squeeze
    rise = np.minimum(rise, peak)
    fall = np.minimum(fall, duration_s - peak)
    keep = (rise >= MIN_PHASE_S) & (fall >= MIN_PHASE_S)
    height = np.minimum(plan.height_m, MAX_HEIGHT_M)
    height = np.minimum(height, MAX_FOOT_SPEED_M_S * np.minimum(rise, fall) / MIN_JERK_PEAK_SPEED)
    return LiftPlan(plan.foot[keep], peak[keep], height[keep], rise[keep], fall[keep])


def choreograph(
    grid: MusicGrid,
    seed: int = 0,
    fps: float = 60.0,
    style: str = "mixed",
    moves: MoveSet | None = None,
) -> np.ndarray:
    """Dance to ``grid``: human foot heights above the floor, m, shape (T, 2) = (left,
    right), sampled at ``fps`` Hz from t = 0, T = ceil(duration_s * fps).

    Deterministic for a given (grid, seed, style); another seed or another song gives
    another dance. ``style`` is a key of `STYLES`. Lifts peak on beats (or half beats in
    double-time moves); at every frame at least one foot is on the floor. ``moves`` (a
    ``--moves`` file, `quaddance.choreo.moves_file.load_moves`) may add styles. The trunk's
    dance is `quaddance.choreo.body.choreograph_body`.
    """
    if not fps > 0:
        raise QuaddanceError(f"fps must be > 0, got {fps}")
    n_frames = int(np.ceil(grid.duration_s * fps - 1e-9))
    t_s = np.arange(n_frames) / fps
    styles = None if moves is None else moves.paw_styles()
    return render_lifts(t_s, plan_dance(grid, seed=seed, style=style, styles=styles))
