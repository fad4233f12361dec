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
    typer.Option(help="Choreographer style: mixed, calm, energetic or footwork (or --moves' own)."),
]
SeedOpt = Annotated[
    int, typer.Option(help="Choreographer seed: another seed, another dance.", **SeedRange)
]
MovesOpt = Annotated[
    Path | None,
    typer.Option(help="TOML file of extra body moves and styles (see choreo/moves_file.py)."),
]


def dance_spec(
    mode: str,
    style: str,
    seed: int,
    moves: Path | None,
    targets: TargetConfig | None = None,
    beats: Path | None = None,
    timed: dict[str, Path | None] | None = None,
) -> DanceSpec:
    """The `DanceSpec` of the dance options, with ``targets``' other settings (its robot
    among them). The moves file and the ``--beats`` file are read here (the moves against
    that robot's trunk range), so that a bad one fails before any work. ``timed``: the
    command's options that bring their own timing and moves (``{"--motion": path}``):
    ``--beats``, ``--style``, ``--seed`` or ``--moves`` with one of them is a usage error."""
    from quaddance.layout import MODES
    from quaddance.pipeline import DanceSpec
    from quaddance.targets import TargetConfig

    if mode not in MODES:
        raise typer.BadParameter(f"--mode must be one of {', '.join(MODES)}, got {mode!r}")
    given = [name for name, path in (timed or {}).items() if path is not None]
    asked = {"--style": style != "mixed", "--seed": seed != 0, "--moves": moves is not None}
    chosen = [name for name, yes in asked.items() if yes]
    if given and chosen:  # they would change nothing, silently
        raise typer.BadParameter(
            f"{chosen[0]} chooses the choreographer's dance; {given[0]} brings its own moves"
        )
    targets = dataclasses.replace(targets or TargetConfig(), mode=mode)
    move_set = None
    if moves is not None:
        from quaddance.choreo.moves_file import load_moves

        move_set = load_moves(moves, targets.robot.body_four_feet)
    beat_list = None
    if beats is not None:
        if given:
            raise typer.BadParameter(f"--beats gives a SONG's beats: not with {given[0]}")
        from quaddance.music.beat_file import read_beats

        beat_list = read_beats(beats)
    return DanceSpec(style=style, seed=seed, moves=move_set, targets=targets, beats=beat_list)


def policy_dance_spec(
    robot: str | None,
    policy: Path | None,
    mode: str,
    style: str,
    seed: int,
    moves: Path | None,
    beats: Path | None = None,
    timed: dict[str, Path | None] | None = None,
) -> tuple[DanceSpec, Path]:
    """The `DanceSpec` of the dance options for the robot of ``--robot`` and ``--policy``,
    and the policy file (`quaddance.play.policy.choose_policy`); ``beats`` and ``timed`` as
    in `dance_spec`."""
    from quaddance.play.policy import choose_policy
    from quaddance.targets import TargetConfig

    robot_cfg, path = choose_policy(robot, policy)
    spec = dance_spec(mode, style, seed, moves, TargetConfig(robot=robot_cfg), beats, timed)
    return spec, path
