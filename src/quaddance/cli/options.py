"""Options and checks that several commands share: a bad value is a usage error (exit 2)
naming the option; and the note on outputs an earlier run left."""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Annotated, Any

import typer

SongArg = Annotated[Path, typer.Argument(help="Audio file: wav, flac, ogg or mp3.")]

SEED_MAX = 2**32 - 1
"""Largest seed accepted (numpy's and torch's generators take 0 ... 2**32 - 1 everywhere)."""
SeedRange = {"min": 0, "max": SEED_MAX}

PolicyOpt = Annotated[
    Path | None, typer.Option(help="Policy .onnx (its .json beside it); default: shipped.")
]
RobotOpt = Annotated[
    str,
    typer.Option(
        help="Backend: sim (the policy's robot simulated in another process, quaddance's own "
        "protocol), go1-sim / go2-sim (a simulated Go1 / Go2 behind the robot's own protocol, "
        "driven through the vendor's SDK), go1 / go2 (a real robot)."
    ),
]
NetworkOpt = Annotated[
    str | None,
    typer.Option(help="go2: the network interface wired to the robot (e.g. eth0)."),
]
DdsDomainOpt = Annotated[
    int, typer.Option(help="go2: the DDS domain id (the robot's: 0).", min=0, max=232)
]
RobotModelOpt = Annotated[
    str, typer.Option("--robot", help="Robot model: go1 or go2 (its limits and policy).")
]
PolicyRobotOpt = Annotated[
    str | None,
    typer.Option(
        "--robot",
        help="Robot model: go1 or go2 (its model, limits and shipped policy); default: "
        "--policy's robot, else go1.",
    ),
]
BeatsOpt = Annotated[
    Path | None,
    typer.Option(
        help="The song's beats from another tool, in place of the tracker's: a text file, one "
        "time (s) a line (a first column of a label export; a second column counting each "
        "bar's beats, as madmom's DBNDownBeatTracker writes, gives the downbeats), or JSON "
        "with beats_s (and downbeats_s).",
    ),
]
RobotIpOpt = Annotated[str, typer.Option(help="go1: the robot's low-level IP.")]
PowerLevelOpt = Annotated[
    int, typer.Option(help="go1: SDK PowerProtect level, 1 (10 %) to 10.", min=1, max=10)
]


def finite_in(lo: float, hi: float):
    """Option callback: the value (or each value of a list) is finite and in [lo, hi].

    click's FloatRange lets NaN through (every comparison with NaN is false), hence this.
    """

    def check(value):
        for v in value if isinstance(value, list | tuple) else [value]:
            if v is not None and not (math.isfinite(v) and lo <= v <= hi):
                raise typer.BadParameter(f"{v} is not a finite number in [{lo:g}, {hi:g}]")
        return value

    return check


def print_notes(console: Any, notes: Iterable[str]) -> None:
    """One ``note:`` line each, unwrapped and as written (paths are not markup)."""
    for note in notes:
        console.print(f"note: {note}", soft_wrap=True, markup=False, highlight=False)


def note_earlier_outputs(
    console: Any, out_dir: Path, names: Iterable[str], written: Iterable[Path]
) -> None:
    """One ``note:`` line per file of ``names`` in ``out_dir`` that this run did not write
    (`quaddance.fileio.earlier_outputs`)."""
    from quaddance.fileio import earlier_outputs

    print_notes(
        console,
        (
            f"{path} is from an earlier run (this one did not write it)"
            for path in earlier_outputs(out_dir, names, written)
        ),
    )
