"""The ``choreograph`` command: a song or a motion file -> robot targets, dance.npz."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from quaddance.cli._options import MovesOpt, SeedRange, finite_in


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
    mode: Annotated[
        str,
        typer.Option(
            help="Targets: feasible (reachable, returns to 0), paper (eq. 4) or minmax "
            "(released code)."
        ),
    ] = "feasible",
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
            help="feasible mode: highest front-foot target, m (default 0.30, measured).",
            callback=finite_in(0.01, 1.0),
        ),
    ] = None,
    seed: Annotated[
        int, typer.Option(help="Choreographer seed: another seed, another dance.", **SeedRange)
    ] = 0,
    style: Annotated[
        str, typer.Option(help="Choreographer style: mixed, calm, energetic or footwork.")
    ] = "mixed",
    moves: MovesOpt = None,
    check: Annotated[
        bool,
        typer.Option(
            "--check", help="Only report what feasible targets clamp (paws, body); write nothing."
        ),
    ] = False,
) -> None:
    """Turn a song (or a human motion file) into robot foot-height and body targets, dance.npz."""
    from rich.console import Console

    from quaddance.choreo.moves_file import load_moves
    from quaddance.layout import MODES
    from quaddance.pipeline import (
        ChoreographJob,
        DanceSpec,
        clamp_table,
        dance_table,
        run_choreograph,
    )
    from quaddance.targets import TargetConfig

    if song is None and motion is None:
        raise typer.BadParameter("give a SONG, or --motion FILE (or both)")
    if mode not in MODES:
        raise typer.BadParameter(f"--mode must be one of {', '.join(MODES)}, got {mode!r}")
    job = ChoreographJob(
        song=song,
        motion=motion,
        out=out,
        spec=DanceSpec(
            style=style,
            seed=seed,
            moves=None if moves is None else load_moves(moves),
            targets=TargetConfig(mode=mode, h0_m=h0, scale=scale)
            if max_height is None
            else TargetConfig(mode=mode, h0_m=h0, scale=scale, max_height_m=max_height),
        ),
        check=check,
    )
    with Console(stderr=True).status("Analysing the music and choreographing..."):
        dance, analysis = run_choreograph(job)
    Console().print(clamp_table(dance) if check else dance_table(dance, analysis, out))
