"""Song or motion file -> `Dance` (and the ``choreograph`` command's job and tables); and a
bank of synthetic target sequences for training.

`make_dance` imports the audio stack only when it has a song to analyse; `target_bank` never
does, so it runs on a training machine without librosa.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import quaddance
from quaddance.choreo.body import MoveSet, choreograph_body
from quaddance.choreo.choreographer import STYLES, choreograph
from quaddance.choreo.grid import MusicGrid, synthetic_grid
from quaddance.dancefile import Dance, save_dance
from quaddance.errors import InputFileError, QuaddanceError
from quaddance.fileio import check_output_file
from quaddance.targets import (
    BODY_COLUMNS,
    TargetConfig,
    TargetMode,
    feasible_body_targets,
    fit_body,
    paw_clamp_report,
    resample,
    robot_targets,
)

if TYPE_CHECKING:
    from quaddance.music.analysis import Analysis

#: Rate at which the built-in choreographer writes human foot heights, Hz (AIST++ rate).
CHOREO_FPS = 60.0
#: Tempo range of the training bank, BPM: dance music is mostly 80-135 (AIST++ 80-130),
#: widened so that octave errors of a beat tracker stay inside what the policy has seen.
BANK_TEMPO_BPM = (80.0, 160.0)


def make_dance(
    song: Path | None,
    motion: Path | None,
    mode: TargetMode = "feasible",
    seed: int = 0,
    target_cfg: TargetConfig | None = None,
    analysis: Analysis | Any | None = None,
    style: str = "mixed",
    moves: MoveSet | None = None,
) -> tuple[Dance, Analysis | None]:
    """Make a dance from a song (built-in choreographer) or from a human motion file.

    Parameters:
        song: audio file; analysed unless ``analysis`` is given. With ``motion`` it only
            supplies beat times (stored in the dance, used to snap feasible targets).
        motion: a human motion file (see `quaddance.choreo.motion`); if given, its foot
            heights are danced instead of the choreographer's.
        mode: target mode; it overrides ``target_cfg.mode``.
        seed: choreographer seed.
        target_cfg: the other target settings; default `TargetConfig()`.
        analysis: a ready `quaddance.music.analysis.Analysis` of ``song``.
        style: choreographer style, a key of `quaddance.choreo.choreographer.STYLES` (or
            of the ``moves`` file's styles).
        moves: body moves and styles of a ``--moves`` file
            (`quaddance.choreo.moves_file.load_moves`); None: the built-in ones.

    Returns:
        The `Dance` (curves at ``cfg.out_fps``) and the song's analysis (None without a song).
        ``dance.body_targets`` are the trunk targets (the choreographer's body moves, or the
        motion's pelvis, scaled by `fit_body`), made feasible by `feasible_body_targets` in
        every mode. ``dance.clamp_report`` (not saved) says what was clamped:
        ``{"paw": paw_clamp_report(...), "body": feasible_body_targets' report}``.
    """
    if song is None and motion is None and analysis is None:
        raise QuaddanceError("give a song, a motion file, or both")
    cfg = dataclasses.replace(target_cfg or TargetConfig(), mode=mode)
    if analysis is None and song is not None:
        from quaddance.music.analysis import analyze_file

        analysis = analyze_file(song)
    song_name = Path(song).name if song is not None else "analysis"

    if motion is not None:
        from quaddance.choreo.motion import load_motion

        human = load_motion(motion)
        feet_m, fps = np.asarray(human.feet_m, dtype=np.float64), float(human.fps)
        # Motions without a trunk (or stand-ins that carry only feet) dance with a still body.
        trunk = getattr(human, "body", None)
        body = fit_body(trunk) if trunk is not None else np.zeros((feet_m.shape[0], 4))
        source = human.source if analysis is None else f"{human.source}; beats of {song_name}"
    else:
        grid = MusicGrid.from_analysis(analysis)
        feet_m = choreograph(grid, seed=seed, fps=CHOREO_FPS, style=style, moves=moves)
        fps = CHOREO_FPS
        body = choreograph_body(grid, feet_m, fps, seed=seed, style=style, moves=moves)
        source = f"choreographer (style {style}, seed {seed}) on {song_name}"
        if moves is not None and moves.source != "built-in":
            source += f", moves {moves.source}"

    beats_s = np.asarray(analysis.beats_s if analysis is not None else [], dtype=np.float64)
    downbeats_s = np.asarray(analysis.downbeats_s if analysis is not None else [], dtype=np.float64)
    time_s, targets_m = robot_targets(feet_m, fps, beats_s, cfg)
    body_targets, body_report = feasible_body_targets(
        body, fps, time_s, targets_m, min_lift_m=cfg.min_lift_m
    )
    dance = Dance(
        fps=cfg.out_fps,
        time_s=time_s,
        human_feet_m=resample(feet_m, fps, time_s),
        targets_m=targets_m,
        beats_s=beats_s,
        downbeats_s=downbeats_s,
        mode=cfg.mode,
        source=source,
        seed=int(seed),
        version=quaddance.__version__,
        body_targets=body_targets,
        clamp_report={
            "paw": paw_clamp_report(feet_m, fps, targets_m, cfg),
            "body": body_report,
        },
    )
    return dance, analysis


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
    bank = np.zeros((n, n_out, 8 if body else 4), dtype=np.float32)
    rng = np.random.default_rng(seed)
    styles = sorted(STYLES)
    for i in range(n):
        tempo_bpm = rng.uniform(*BANK_TEMPO_BPM)
        swing = rng.uniform(0.0, 0.15) if rng.random() < 0.3 else 0.0
        beats_per_bar = 3 if rng.random() < 0.1 else 4
        grid = synthetic_grid(tempo_bpm, duration_s, rng, swing=swing, beats_per_bar=beats_per_bar)
        style = styles[int(rng.integers(len(styles)))]
        dance_seed = int(rng.integers(2**31))
        feet_m = choreograph(grid, seed=dance_seed, fps=CHOREO_FPS, style=style)
        time_s, targets_m = robot_targets(feet_m, CHOREO_FPS, grid.beats_s, cfg)
        m = min(n_out, targets_m.shape[0])
        bank[i, :m, :4] = targets_m[:m]
        if body:
            trunk = choreograph_body(grid, feet_m, CHOREO_FPS, seed=dance_seed, style=style)
            trunk, _ = feasible_body_targets(
                trunk, CHOREO_FPS, time_s, targets_m, min_lift_m=cfg.min_lift_m
            )
            bank[i, :m, 4:] = trunk[:m]
        if progress is not None:
            progress(i)
    return bank


@dataclasses.dataclass(frozen=True)
class ChoreographJob:
    """A dance to make and save (``quaddance choreograph``).

    Attributes:
        song: audio file, or None with ``motion``.
        motion: human motion file to dance instead of the choreographer's, or None.
        out: where to write the dance (.npz); unused with ``check``.
        mode: target mode (`quaddance.targets.MODES`).
        h0_m: paper mode's h0 (eq. 4), m.
        scale: minmax mode's scale s.
        max_height_m: feasible mode's highest front-foot target, m; None: `TargetConfig`'s.
        seed: choreographer seed.
        style: choreographer style.
        moves: TOML file of extra body moves and styles, or None.
        check: only make the dance (to report what feasible targets clamp); write nothing.
    """

    song: Path | None
    motion: Path | None
    out: Path
    mode: TargetMode = "feasible"
    h0_m: float = 2.0
    scale: float = 1.0
    max_height_m: float | None = None
    seed: int = 0
    style: str = "mixed"
    moves: Path | None = None
    check: bool = False


def run_choreograph(job: ChoreographJob) -> tuple[Dance, Analysis | None]:
    """Make ``job``'s dance with `make_dance` and save it to ``job.out`` (unless ``job.check``).

    The inputs, the moves file and the output path are checked before the work, so that a bad
    one fails in a moment. Returns the dance and the song's analysis (None without a song).
    """
    for path in (job.song, job.motion):
        if path is not None and not path.is_file():
            raise InputFileError(path, "no such file")
    move_set = None
    if job.moves is not None:
        from quaddance.choreo.moves_file import load_moves

        move_set = load_moves(job.moves)
    if not job.check:
        check_output_file(job.out)
    cfg = TargetConfig(mode=job.mode, h0_m=job.h0_m, scale=job.scale)
    if job.max_height_m is not None:
        cfg = dataclasses.replace(cfg, max_height_m=job.max_height_m)
    dance, analysis = make_dance(
        job.song,
        job.motion,
        mode=job.mode,
        seed=job.seed,
        target_cfg=cfg,
        style=job.style,
        moves=move_set,
    )
    if not job.check:
        save_dance(job.out, dance)
    return dance, analysis


def dance_table(dance: Dance, analysis: Analysis | None, out: Path) -> Any:
    """A rich table that sums up a dance saved to ``out``: source, length, tempo, front-paw
    lifts and heights, and the trunk's range."""
    from rich.table import Table

    front = dance.targets_m[:, :2]
    up = front > 0
    n_lifts = [
        int(np.count_nonzero(np.diff(up[:, k].astype(np.int8)) == 1) + up[0, k]) for k in (0, 1)
    ]
    table = Table(title=f"dance -> {out}", show_header=False)
    table.add_row("source", dance.source)
    table.add_row("duration", f"{dance.duration_s:.1f} s at {dance.fps:g} Hz")
    if analysis is not None:
        table.add_row("tempo", f"{analysis.tempo_bpm:.1f} BPM, {dance.beats_s.size} beats")
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
    """A rich table of ``dance.clamp_report`` (`make_dance`): what feasible targets clamped
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
