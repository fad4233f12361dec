"""The ``choreograph`` command: a song or a motion file -> robot targets, dance.npz."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from quaddance.cli._dance_spec import ModeOpt, MovesOpt, SeedOpt, StyleOpt, dance_spec
from quaddance.cli.options import BeatsOpt, RobotModelOpt, finite_in, print_notes


def choreograph_cmd(
    song: Annotated[
        Path | None,
        typer.Argument(help="Audio file: wav, flac, ogg or mp3 (optional with --motion)."),
    ] = None,
    out: Annotated[Path, typer.Option("-o", "--out", help="Where to write the dance.")] = Path(
        "dance.npz"
    ),
    motion: Annotated[
        Path | None,
        typer.Option(help="Human motion file (EDGE or AIST++ .pkl, .bvh) to dance instead."),
    ] = None,
    mode: ModeOpt = "feasible",
    h0: Annotated[
        float,
        typer.Option(help="paper mode: eq. 4's h0, m (paper: 2).", callback=finite_in(0.001, 10)),
    ] = 2.0,
    scale: Annotated[
        float,
        typer.Option(help="minmax mode: scale s (released code).", callback=finite_in(0.001, 10)),
    ] = 1.0,
    max_height: Annotated[
        float | None,
        typer.Option(
            help="feasible mode: highest front-foot target, m (default: the range the robot's "
            "shipped policy was trained on, as `dance` keeps to).",
            callback=finite_in(0.01, 1.0),
        ),
    ] = None,
    seed: SeedOpt = 0,
    style: StyleOpt = "mixed",
    moves: MovesOpt = None,
    beats: BeatsOpt = None,
    robot: RobotModelOpt = "go1",
    check: Annotated[
        bool,
        typer.Option(
            "--check", help="Only report what feasible targets clamp (paws, body); write nothing."
        ),
    ] = False,
) -> None:
    """Turn a song (or a human motion file) into foot-height and body targets for a robot
    (--robot), dance.npz."""
    from rich.console import Console

    from quaddance.pipeline import ChoreographJob, clamp_table, dance_table, run_choreograph
    from quaddance.play.dance import shipped_max_height_m
    from quaddance.robots import get_robot
    from quaddance.targets import TargetConfig

    if song is None and motion is None:
        raise typer.BadParameter("give a SONG, or --motion FILE (or both)")
    robot_cfg = get_robot(robot)
    if max_height is None:  # the dance `dance` would make with the shipped policy
        max_height = shipped_max_height_m(robot_cfg)
    targets = TargetConfig(h0_m=h0, scale=scale, max_height_m=max_height, robot=robot_cfg)
    spec = dance_spec(mode, style, seed, moves, targets, beats, {"--motion": motion})
    job = ChoreographJob(song=song, motion=motion, out=out, spec=spec, check=check)
    err = Console(stderr=True)
    with err.status("Analysing the music and choreographing..."):
        dance, analysis = run_choreograph(job)
    print_notes(err, dance.notes)
    Console().print(clamp_table(dance) if check else dance_table(dance, analysis, out))
