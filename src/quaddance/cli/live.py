"""The ``live`` command: dance to music as it plays (microphone or a file at real-time pace)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from quaddance.cli._dance_spec import ModeOpt, MovesOpt, SeedOpt, StyleOpt, policy_dance_spec
from quaddance.cli.options import (
    DdsDomainOpt,
    NetworkOpt,
    PolicyOpt,
    PowerLevelOpt,
    RobotIpOpt,
    RobotOpt,
    finite_in,
    note_earlier_outputs,
)


def live_cmd(
    from_file: Annotated[
        Path | None,
        typer.Option(
            "--from-file",
            help="Feed this song through the live path at real-time pace (default: microphone).",
        ),
    ] = None,
    start: Annotated[
        float,
        typer.Option(
            "--start",
            help="With --from-file: play from this far into the song, s, as music already "
            "playing (times in the outputs count from there).",
            callback=finite_in(0.0, 36000.0),
        ),
    ] = 0.0,
    device: Annotated[
        str | None, typer.Option(help="Microphone or line-in (sounddevice name or index).")
    ] = None,
    robot: RobotOpt = "sim",
    policy: PolicyOpt = None,
    seconds: Annotated[
        float | None,
        typer.Option(
            help="Dance this long, s (default: the file's length; 60 s from a microphone).",
            callback=finite_in(0.5, 3600.0),
        ),
    ] = None,
    viewer: Annotated[
        bool, typer.Option("--viewer", help="Serve a web page showing the robot, tempo, beats.")
    ] = False,
    host: Annotated[
        str, typer.Option(help="Viewer address; 0.0.0.0 lets other machines watch.")
    ] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="Viewer port.", min=1, max=65535)] = 8080,
    video: Annotated[
        bool, typer.Option("--video", help="With --from-file: write dance.mp4 afterwards.")
    ] = False,
    mode: ModeOpt = "feasible",
    style: StyleOpt = "mixed",
    seed: SeedOpt = 0,
    moves: MovesOpt = None,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("live_out"),
    robot_ip: RobotIpOpt = "192.168.123.10",
    power_level: PowerLevelOpt = 1,
    network: NetworkOpt = None,
    dds_domain: DdsDomainOpt = 0,
) -> None:
    """Dance to music as it plays: online beat tracking, a dance planned a bar ahead, the
    robot on the wall clock (same runner and safety layer as deploy). Writes live.json,
    rollout.npz, deploy.json and log.npz (and dance.mp4 with --video)."""
    from rich.console import Console

    from quaddance.deploy.job import BACKENDS, BackendOptions
    from quaddance.live.session import OUTPUT_NAMES, LiveJob, run_live, summary_line

    # ``--robot`` names the backend; the robot model is the backend's (sim: the policy's).
    spec, policy = policy_dance_spec(BACKENDS.get(robot), policy, mode, style, seed, moves)
    console = Console(stderr=True)
    job = LiveJob(
        out_dir=out,
        from_file=from_file,
        start_s=start,
        device=device,
        backend=BackendOptions(
            robot, robot_ip, power_level, network=network, dds_domain=dds_domain
        ),
        policy=policy,
        seconds=seconds,
        viewer=viewer,
        host=host,
        port=port,
        video=video,
        spec=spec,
    )
    summary, paths = run_live(job, status=lambda msg: console.log(msg))
    console.print(summary_line(summary))
    for name, path in paths.items():
        console.print(f"{name}: {path}")
    note_earlier_outputs(console, out, OUTPUT_NAMES, paths.values())
