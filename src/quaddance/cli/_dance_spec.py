"""The options that choose a dance (``--mode``, ``--style``, ``--seed``, ``--moves``), the
same in choreograph, dance, deploy and live, and the `DanceSpec` they make (for the robot
that ``--robot`` or the policy names, `policy_dance_spec`); ``--beats`` (choreograph, dance,
deploy) gives a song's beats from a file."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from quaddance.cli.options import SeedRange

if TYPE_CHECKING:
    from quaddance.music.beat_file import BeatList
    from quaddance.pipeline import DanceSpec
    from quaddance.targets import TargetConfig

ModeOpt = Annotated[
    str,
    typer.Option(
        help="Targets: feasible (reachable, returns to 0), paper (eq. 4) or minmax (released code)."
    ),
]
StyleOpt = Annotated[
    str,
    typer.Option(help="Choreographer style: mixed, calm, energetic or footwork (or --moves')."),
]
SeedOpt = Annotated[
    int, typer.Option(help="Choreographer seed: another seed, another dance.", **SeedRange)
]
MovesOpt = Annotated[
    Path | None,
    typer.Option(help="TOML file of extra body moves and styles (see choreo/moves_file.py)."),
]

BeatsOpt = Annotated[
    Path | None,
    typer.Option(
        help="The song's beats from another tool, in place of the tracker's: a text file, one "
        "time (s) a line (a first column of a label export), or JSON with beats_s (and "
        "downbeats_s).",
    ),
]


def read_beats_option(
    beats: Path | None, motion: Path | None, dance: Path | None = None
) -> BeatList | None:
    """The beat file of ``--beats``, read and checked now so that a bad one fails before any
    work; a usage error with ``--motion`` or ``--dance``, which bring their own timing."""
    if beats is None:
        return None
    if motion is not None or dance is not None:
        raise typer.BadParameter("--beats gives a SONG's beats: not with --motion or --dance")
    from quaddance.music.beat_file import read_beats

    return read_beats(beats)


def dance_spec(
    mode: str,
    style: str,
    seed: int,
    moves: Path | None,
    targets: TargetConfig | None = None,
    beats: BeatList | None = None,
) -> DanceSpec:
    """The `DanceSpec` of the dance options, with ``targets``' other settings (its robot
    among them) and ``beats`` (`read_beats_option`). The moves file is read here, against
    that robot's trunk range, so that a bad one fails before any work."""
    from quaddance.layout import MODES
    from quaddance.pipeline import DanceSpec
    from quaddance.targets import TargetConfig

    if mode not in MODES:
        raise typer.BadParameter(f"--mode must be one of {', '.join(MODES)}, got {mode!r}")
    targets = dataclasses.replace(targets or TargetConfig(), mode=mode)
    move_set = None
    if moves is not None:
        from quaddance.choreo.moves_file import load_moves

        move_set = load_moves(moves, targets.robot.body_four_feet)
    return DanceSpec(style=style, seed=seed, moves=move_set, targets=targets, beats=beats)


def policy_dance_spec(
    robot: str | None,
    policy: Path | None,
    mode: str,
    style: str,
    seed: int,
    moves: Path | None,
    beats: BeatList | None = None,
) -> tuple[DanceSpec, Path]:
    """The `DanceSpec` of the dance options for the robot of ``--robot`` and ``--policy``,
    and the policy file (`quaddance.play.policy.choose_policy`)."""
    from quaddance.play.policy import choose_policy
    from quaddance.targets import TargetConfig

    robot_cfg, path = choose_policy(robot, policy)
    return dance_spec(mode, style, seed, moves, TargetConfig(robot=robot_cfg), beats), path
