"""The dance composer: one `DanceSpec` and the music (or a human motion) in, a `Dance` out.

`compose` is the one chain that makes a dance: choreograph the human dance (paws and trunk)
on a `MusicGrid`, or take a motion file's, then turn it into robot targets the policy can
follow (`targets.robot_targets`, `targets.feasible_body_targets`). Every dance is made by it:
`quaddance choreograph`, `dance` and `deploy` through `make_dance` (a song or motion file),
the training bank (`target_bank`, synthetic songs) and the live planner (a grid of the next
bar's predicted beats). The ``choreograph`` command's job and tables are here too.

`make_dance` imports the audio stack only when it has a song to analyse; the rest never
does, so the bank builds on a training machine without librosa.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import quaddance
from quaddance.choreo.body import MoveSet, choreograph_body
from quaddance.choreo.choreographer import STYLES, choreograph
from quaddance.choreo.grid import MusicGrid, synthetic_grid
from quaddance.dancefile import Dance, save_dance
from quaddance.errors import QuaddanceError, not_a_file
from quaddance.fileio import check_outputs
from quaddance.layout import (
    BODY,
    BODY_COLUMNS,
    CHOREO_FPS,
    DANCE_TEMPO_BPM,
    FRONT_PAWS,
    N_BODY,
    PAWS,
    TargetMode,
    row_width,
)
from quaddance.targets import (
    TargetConfig,
    feasible_body_targets,
    fit_body,
    paw_clamp_report,
    resample,
    robot_targets,
)

if TYPE_CHECKING:
    from quaddance.choreo.motion import HumanMotion
    from quaddance.music.analysis import Analysis
    from quaddance.music.beat_file import BeatList
    from quaddance.robots import RobotCfg

#: Tempo range of the training bank, BPM: the dance range, in which both beat trackers report
#: the beat level (dance music is mostly 80-135, AIST++ 80-130), so that a policy has seen
#: every tempo it is asked to dance.
BANK_TEMPO_BPM = DANCE_TEMPO_BPM


@dataclass(frozen=True)
class DanceSpec:
    """Which dance to make of the music: everything that decides it but the music itself.

    Attributes:
        style: choreographer style, a key of `quaddance.choreo.choreographer.STYLES` (or of
            ``moves``' styles).
        seed: choreographer seed: another seed, another dance.
        moves: body moves and styles of a ``--moves`` file
            (`quaddance.choreo.moves_file.load_moves`); None: the built-in ones.
        targets: how the human dance becomes robot targets: the robot (`robot`), whose
            paw and trunk limits the dance keeps to, the mode (`mode`), the output rate.
        beats: beats from a file (``--beats``, `quaddance.music.beat_file.read_beats`) that
            replace the music's in the grid (`MusicGrid.with_beats`); None: the music's.
    """

    style: str = "mixed"
    seed: int = 0
    moves: MoveSet | None = None
    targets: TargetConfig = field(default_factory=TargetConfig)
    beats: BeatList | None = None

    def __post_init__(self) -> None:
        names = (self.moves or MoveSet()).style_names
        if self.style not in names:
            raise QuaddanceError(
                f"unknown choreography style {self.style!r}; choose one of {sorted(names)}"
            )

    @property
    def mode(self) -> TargetMode:
        """The target mode (`quaddance.layout.MODES`)."""
        return self.targets.mode

    @property
    def robot(self) -> RobotCfg:
        """The robot the dance is for."""
        return self.targets.robot


def compose(
    spec: DanceSpec,
    grid: MusicGrid | None = None,
    motion: HumanMotion | None = None,
    music_name: str = "the music",
    whole_body: bool = True,
    music_notes: Sequence[str] = (),
) -> Dance:
    """The dance of ``spec`` on ``grid``, or of a human ``motion``.

    Parameters:
        spec: which dance (style, seed, moves, targets).
        grid: the music: the built-in choreographer dances to it; with ``motion`` it only
            supplies the beats (stored in the dance, used to snap feasible targets).
            ``spec.beats`` replace its beats (one line if one falls after its end).
        motion: a human dance (`quaddance.choreo.motion.HumanMotion`) to dance instead of
            the choreographer's; a motion without a trunk dances with a still one.
        music_name: what the music is called in ``dance.source``.
        whole_body: False: paw targets only, for a paws-only policy; the trunk's dance is
            skipped (``body_targets`` zeros).
        music_notes: what the user should hear about the music's beats (`Analysis.notes`);
            dropped where ``spec.beats`` replace them.

    Returns:
        The `Dance` at ``spec.targets.out_fps``. Its ``body_targets`` are the trunk targets
        (the choreographer's body moves, or the motion's pelvis scaled by `fit_body`), made
        feasible by `feasible_body_targets` in every mode. ``dance.clamp_report`` (not
        saved) says what was clamped: ``{"paw": paw_clamp_report(...), "body":
        feasible_body_targets' report}`` (no ``"body"`` without ``whole_body``).
    """
    cfg = spec.targets
    four_feet = cfg.robot.body_four_feet
    notes = tuple(music_notes)
    if spec.beats is not None:
        if grid is None:
            raise QuaddanceError(f"{spec.beats.path}: beats from a file need a song")
        spec.beats.check_within(grid.duration_s)
        notes = tuple(spec.beats.notes(grid.duration_s))
        grid = grid.with_beats(spec.beats.beats_s, spec.beats.downbeats_s)
        music_name += f", beats of {spec.beats.name}"
    if motion is not None:
        feet_m, fps = np.asarray(motion.feet_m, dtype=np.float64), float(motion.fps)
        # Motions without a trunk (or stand-ins that carry only feet) dance with a still body.
        trunk = getattr(motion, "body", None)
        body = (
            fit_body(trunk, four_feet) if trunk is not None else np.zeros((feet_m.shape[0], N_BODY))
        )
        source = motion.source if grid is None else f"{motion.source}; beats of {music_name}"
    elif grid is not None:
        fps = CHOREO_FPS
        feet_m = choreograph(grid, seed=spec.seed, fps=fps, style=spec.style, moves=spec.moves)
        body = None
        if whole_body:
            body = choreograph_body(grid, feet_m, fps, spec.seed, spec.style, spec.moves, four_feet)
        source = f"choreographer (style {spec.style}, seed {spec.seed}) on {music_name}"
        if spec.moves is not None and spec.moves.source != "built-in":
            source += f", moves {spec.moves.source}"
    else:
        raise QuaddanceError("give a song, a motion file, or both")

    empty = np.zeros(0)
    beats_s = grid.beats_s if grid is not None else empty
    time_s, targets_m = robot_targets(feet_m, fps, beats_s, cfg)
    report = {"paw": paw_clamp_report(feet_m, fps, targets_m, cfg)}
    body_targets = None
    if whole_body:
        body_targets, report["body"] = feasible_body_targets(body, fps, time_s, targets_m, cfg)
    return Dance(
        fps=cfg.out_fps,
        time_s=time_s,
        human_feet_m=resample(feet_m, fps, time_s),
        targets_m=targets_m,
        beats_s=beats_s,
        downbeats_s=grid.downbeats_s if grid is not None else empty,
        mode=cfg.mode,
        source=source,
        seed=int(spec.seed),
        version=quaddance.__version__,
        body_targets=body_targets,
        robot=cfg.robot.name,
        clamp_report=report,
        notes=notes,
    )


def make_dance(
    song: Path | None,
    motion: Path | None,
    spec: DanceSpec | None = None,
    analysis: Analysis | Any | None = None,
    human: HumanMotion | None = None,
) -> tuple[Dance, Analysis | None]:
    """`compose` a dance from a song (built-in choreographer) or from a human motion file.

    Parameters:
        song: audio file; analysed unless ``analysis`` is given. With ``motion`` it only
            supplies beat times.
        motion: a human motion file (see `quaddance.choreo.motion`); if given, its foot
            heights and trunk are danced instead of the choreographer's.
        spec: which dance; default `DanceSpec()`.
        analysis: a ready `quaddance.music.analysis.Analysis` of ``song``.
        human: ``motion`` already read by `quaddance.choreo.motion.load_motion` (eval reads
            each file before any work, to fail early): it is not read again.

    Returns:
        The `Dance` and the song's analysis (None without a song).
    """
    if song is None and motion is None and analysis is None:
        raise QuaddanceError("give a song, a motion file, or both")
    if analysis is None and song is not None:
        from quaddance.music.analysis import analyze_file

        analysis = analyze_file(song)
    if human is None and motion is not None:
        from quaddance.choreo.motion import load_motion

        human = load_motion(motion)
    grid = MusicGrid.from_analysis(analysis) if analysis is not None else None
    music_name = Path(song).name if song is not None else "analysis"
    # A stand-in analysis (tests, the online tracker's result) may have no notes.
    notes = analysis.notes(music_name) if hasattr(analysis, "notes") else []
    return compose(spec or DanceSpec(), grid, human, music_name, music_notes=notes), analysis


def target_bank(
    n: int,
    duration_s: float,
    seed: int = 0,
    cfg: TargetConfig | None = None,
    progress: Callable[[int], None] | None = None,
    body: bool = False,
) -> np.ndarray:
    """``n`` robot target sequences from synthetic songs, for training without audio.

    Each song draws a tempo uniformly in `BANK_TEMPO_BPM`, some swing (30 % of songs),
    3/4 time (10 %), a choreography style and a seed; all from ``seed``, so the bank is
    reproducible. ``progress(i)`` is called after each sequence.

    Returns:
        (n, T, 4) float32 foot-height targets (FL, FR, RL, RR), m, at ``cfg.out_fps``,
        T = ceil(duration_s * out_fps). With ``body=True``: (n, T, 8), the 4 foot targets
        then the 4 feasible body targets (`quaddance.targets.BODY_COLUMNS`); the foot
        targets are the same as with ``body=False``.
    """
    if n < 1:
        raise QuaddanceError(f"target bank size must be >= 1, got {n}")
    if not duration_s > 0:
        raise QuaddanceError(f"target bank duration_s must be > 0, got {duration_s}")
    cfg = cfg or TargetConfig()
    n_out = int(np.ceil(duration_s * cfg.out_fps - 1e-9))
    bank = np.zeros((n, n_out, row_width(body)), dtype=np.float32)
    rng = np.random.default_rng(seed)
    styles = sorted(STYLES)
    for i in range(n):
        tempo_bpm = rng.uniform(*BANK_TEMPO_BPM)
        swing = rng.uniform(0.0, 0.15) if rng.random() < 0.3 else 0.0
        beats_per_bar = 3 if rng.random() < 0.1 else 4
        grid = synthetic_grid(tempo_bpm, duration_s, rng, swing=swing, beats_per_bar=beats_per_bar)
        style = styles[int(rng.integers(len(styles)))]
        spec = DanceSpec(style=style, seed=int(rng.integers(2**31)), targets=cfg)
        dance = compose(spec, grid, whole_body=body)
        m = min(n_out, dance.targets_m.shape[0])
        bank[i, :m, PAWS] = dance.targets_m[:m]
        if body:
            bank[i, :m, BODY] = dance.body_targets[:m]
        if progress is not None:
            progress(i)
    return bank


@dataclass(frozen=True)
class ChoreographJob:
    """A dance to make and save (``quaddance choreograph``).

    Attributes:
        song: audio file, or None with ``motion``.
        motion: human motion file to dance instead of the choreographer's, or None.
        out: where to write the dance (.npz); unused with ``check``.
        spec: which dance.
        check: only make the dance (to report what feasible targets clamp); write nothing.
    """

    song: Path | None
    motion: Path | None
    out: Path
    spec: DanceSpec = field(default_factory=DanceSpec)
    check: bool = False


def dance_inputs(song: Path | None, motion: Path | None, spec: DanceSpec) -> dict[str, Path | None]:
    """The files a dance is made from, by the option that names them (None: not given)."""
    return {
        "SONG": song,
        "--motion": motion,
        "--beats": spec.beats.path if spec.beats else None,
        "--moves": spec.moves.path if spec.moves else None,
    }


def run_choreograph(job: ChoreographJob) -> tuple[Dance, Analysis | None]:
    """Make ``job``'s dance with `make_dance` and save it to ``job.out`` (unless ``job.check``).

    The inputs and the output path are checked before the work, so that a bad one fails in a
    moment. Returns the dance and the song's analysis (None without a song).
    """
    for path in (job.song, job.motion):
        if path is not None and not path.is_file():
            raise not_a_file(path)
    if not job.check:
        check_outputs({"--out": job.out}, dance_inputs(job.song, job.motion, job.spec))
    dance, analysis = make_dance(job.song, job.motion, job.spec)
    if not job.check:
        save_dance(job.out, dance)
    return dance, analysis


def dance_table(dance: Dance, analysis: Analysis | None, out: Path) -> Any:
    """A rich table that sums up a dance saved to ``out``: source, length, tempo, front-paw
    lifts and heights, and the trunk's range."""
    from rich.table import Table

    from quaddance.music.analysis import median_beat_period_s

    front = dance.targets_m[:, FRONT_PAWS]
    up = front > 0
    n_lifts = [
        int(np.count_nonzero(np.diff(up[:, k].astype(np.int8)) == 1) + up[0, k]) for k in (0, 1)
    ]
    table = Table(title=f"dance -> {out}", show_header=False)
    table.add_row("source", dance.source)
    table.add_row("duration", f"{dance.duration_s:.1f} s at {dance.fps:g} Hz")
    if analysis is not None and dance.beats_s.size > 1:
        # The dance's beats: the analyser's, or a beat file's (its tempo as the analyser's).
        tempo_bpm = 60.0 / median_beat_period_s(dance.beats_s)
        table.add_row("tempo", f"{tempo_bpm:.1f} BPM, {dance.beats_s.size} beats")
    table.add_row("mode", dance.mode)
    table.add_row("lifts FL / FR", f"{n_lifts[0]} / {n_lifts[1]}")
    table.add_row("highest target", f"{front.max():.3f} m")
    table.add_row("a front foot up", f"{100 * up.any(axis=1).mean():.0f} % of the time")
    table.add_row("both front feet up", f"{100 * up.all(axis=1).mean():.0f} % of the time")
    body = dance.body_targets
    table.add_row(
        "trunk range",
        f"height {body[:, 0].min():+.3f}..{body[:, 0].max():+.3f} m, roll/pitch/yaw "
        + " / ".join(f"{np.rad2deg(np.ptp(body[:, c])):.0f}" for c in (1, 2, 3))
        + " deg",
    )
    return table


def clamp_table(dance: Dance) -> Any:
    """A rich table of ``dance.clamp_report`` (`compose`): what feasible targets clamped
    (paw lifts dropped, merged or clipped; trunk samples per body column), and by how much."""
    from rich.table import Table

    report = dance.clamp_report or {}
    paw = report.get("paw", {})
    table = Table(title=f"clamp check: {dance.source}")
    for name in ("what", "clamped", "max", "mean"):
        table.add_column(name)
    table.add_row(
        "paw lifts",
        f"{paw.get('human_lifts', 0)} human -> {paw.get('robot_lifts', 0)} robot "
        f"({paw.get('dropped_or_merged', 0)} dropped or merged)",
        f"{paw.get('clipped_to_max_height', 0)} clipped to {paw.get('max_height_m', 0):.2f} m",
        f"highest {paw.get('highest_target_m', 0):.3f} m",
    )
    body = report.get("body", {})
    n = max(int(body.get("samples", 0)), 1)
    for name in BODY_COLUMNS:
        col = body.get(name, {"clamped": 0, "max": 0.0, "mean": 0.0})
        unit, scale = ("m", 1.0) if name.endswith("_m") else ("deg", float(np.rad2deg(1.0)))
        table.add_row(
            f"body {name}",
            f"{col['clamped']} samples ({100 * col['clamped'] / n:.0f} %)",
            f"{col['max'] * scale:.3f} {unit}",
            f"{col['mean'] * scale:.4f} {unit}",
        )
    return table
