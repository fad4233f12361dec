"""Song or motion file -> `Dance`; and a bank of synthetic target sequences for training.

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
from quaddance.dancefile import Dance
from quaddance.errors import QuaddanceError
from quaddance.targets import (
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
