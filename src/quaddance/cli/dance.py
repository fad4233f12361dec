"""The ``dance`` command: a song -> a robot dancing in simulation (video, plots, metrics)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

from quaddance.cli._dance_spec import ModeOpt, MovesOpt, SeedOpt, StyleOpt, policy_dance_spec
from quaddance.cli._exit import exit_without_teardown
from quaddance.cli.options import (
    BeatsOpt,
    PolicyOpt,
    PolicyRobotOpt,
    note_earlier_outputs,
    print_notes,
)


def dance_cmd(
    song: Annotated[
        Path | None, typer.Argument(help="Audio file: wav, flac, ogg or mp3 (or use --demo).")
    ] = None,
    demo: Annotated[bool, typer.Option(help="Dance to the built-in demo song.")] = False,
    motion: Annotated[
        Path | None, typer.Option(help="Human motion (EDGE/AIST++ .pkl, .bvh) instead of ours.")
    ] = None,
    policy: PolicyOpt = None,
    robot: PolicyRobotOpt = None,
    mode: ModeOpt = "feasible",
    seed: SeedOpt = 0,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("dance_out"),
    no_video: Annotated[bool, typer.Option("--no-video", help="Skip the video.")] = False,
    randomize: Annotated[
        bool, typer.Option(help="Randomise the robot's dynamics as in training.")
    ] = False,
    style: StyleOpt = "mixed",
    moves: MovesOpt = None,
    beats: BeatsOpt = None,
) -> None:
    """Make a robot (the Go1 unless --robot or --policy says otherwise) dance to a song:
    dance.mp4 (with the music), feet.png, metrics.json, dance.npz and rollout.npz."""
    from rich.console import Console

    from quaddance.play.dance import OUTPUT_NAMES, DanceJob, run_dance
    from quaddance.play.metrics import summary_table

    spec, policy = policy_dance_spec(
        robot, policy, mode, style, seed, moves, beats, {"--motion": motion}
    )
    if demo:
        if song is not None:
            raise typer.BadParameter("give a SONG or --demo, not both")
        from quaddance.fileio import ensure_dir
        from quaddance.music.synth import write_demo_song

        song = ensure_dir(out) / "demo_song.wav"
        write_demo_song(song)
    if song is None and motion is None:
        raise typer.BadParameter("give a SONG, --demo, or --motion FILE")
    console = Console(stderr=True)
    job = DanceJob(
        out_dir=out,
        song=song,
        motion=motion,
        policy=policy,
        spec=spec,
        video=not no_video,
        randomize=randomize,
        analysis_process=True,
    )
    progress, sim_progress = _progress_bar(console)
    with progress:
        result = run_dance(
            job,
            status=lambda msg: console.log(msg),
            sim_progress=sim_progress,
            show_render_progress=True,
        )
    Console().print(summary_table(result.metrics))
    for name, path in result.paths.items():
        console.print(f"{name}: {path}")
    note_earlier_outputs(console, job.out_dir, OUTPUT_NAMES, result.paths.values())
    print_notes(console, result.dance.notes)
    console.print(f"took {result.timings_s['total_s']:.1f} s")
    exit_without_teardown()


def _progress_bar(console: Any) -> tuple[Any, Callable[[int, int], None]]:
    """A transient progress bar on ``console`` and the ``sim_progress(done, total)`` callback
    that adds the simulation's task to it on its first call."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    progress = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeRemainingColumn(),
        console=console,
        transient=True,
    )
    sim_task = None

    def sim_progress(done: int, total: int) -> None:
        nonlocal sim_task
        if sim_task is None:
            sim_task = progress.add_task("dancing (simulation)", total=total)
        if done % 25 == 0 or done == total:
            progress.update(sim_task, completed=done)

    return progress, sim_progress
