"""The ``deploy`` command: a dance on a robot (simulated or real) with the safety layer."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from quaddance.cli._dance_spec import ModeOpt, MovesOpt, SeedOpt, StyleOpt, policy_dance_spec
from quaddance.cli.options import (
    BeatsOpt,
    DdsDomainOpt,
    NetworkOpt,
    PolicyOpt,
    PowerLevelOpt,
    RobotIpOpt,
    RobotOpt,
    finite_in,
    note_earlier_outputs,
)


def deploy_cmd(
    song: Annotated[
        Path | None, typer.Argument(help="Audio file (or --demo, --dance, --motion).")
    ] = None,
    demo: Annotated[bool, typer.Option(help="Dance to the built-in demo song.")] = False,
    dance: Annotated[
        Path | None, typer.Option("--dance", help="A dance.npz (quaddance choreograph).")
    ] = None,
    motion: Annotated[
        Path | None, typer.Option(help="Human motion (EDGE/AIST++ .pkl, .bvh) to dance.")
    ] = None,
    mode: ModeOpt = "feasible",
    style: StyleOpt = "mixed",
    seed: SeedOpt = 0,
    moves: MovesOpt = None,
    beats: BeatsOpt = None,
    robot: RobotOpt = "sim",
    policy: PolicyOpt = None,
    seconds: Annotated[
        float | None,
        typer.Option(help="Dance at most this long, s.", callback=finite_in(0.02, 3600.0)),
    ] = None,
    auto_start: Annotated[
        bool, typer.Option("--auto-start", help="Dance once standing, without waiting for Enter.")
    ] = False,
    inject: Annotated[
        list[str] | None,
        typer.Option(
            help="Fault at dance time T, s (simulated robots only): push@T, freeze@T, nan@T, lag@T."
        ),
    ] = None,
    dry_run: Annotated[
        bool,
        typer.Option(
            "--dry-run",
            help="Read, log and check the robot's state (joint ranges, IMU upright, battery) "
            "for 3 s without sending any command; no dance.",
        ),
    ] = False,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("deploy_out"),
    robot_ip: RobotIpOpt = "192.168.123.10",
    power_level: PowerLevelOpt = 1,
    network: NetworkOpt = None,
    dds_domain: DdsDomainOpt = 0,
    sim_latency_ms: Annotated[
        tuple[float, float],
        typer.Option(
            help="Simulated robots: sensor-to-motor delay range, ms (drawn per message).",
            callback=finite_in(0.0, 500.0),
        ),
    ] = (5.0, 20.0),
) -> None:
    """Run the dance on a robot: passive -> soft stand -> ready -> dance -> done, with a safety
    layer (damping on a fall, a stale or NaN state, Ctrl-C); writes deploy.json and log.npz."""
    from rich.console import Console

    from quaddance.deploy.job import (
        BACKENDS,
        OUTPUT_NAMES,
        BackendOptions,
        DeployJob,
        parse_inject,
        run_deploy,
        summary_line,
    )

    # ``--robot`` names the backend; the robot model is the backend's (sim: the policy's).
    timed = {"--motion": motion, "--dance": dance}
    model = BACKENDS.get(robot)
    spec, policy = policy_dance_spec(model, policy, mode, style, seed, moves, beats, timed)
    console = Console(stderr=True)
    job = DeployJob(
        out_dir=out,
        song=song,
        motion=motion,
        dance=dance,
        demo=demo,
        spec=spec,
        policy=policy,
        seconds=seconds,
        auto_start=auto_start,
        inject=parse_inject(inject),
        backend=BackendOptions(
            robot, robot_ip, power_level, sim_latency_ms, network=network, dds_domain=dds_domain
        ),
        dry_run=dry_run,
    )
    summary, paths = run_deploy(job, status=lambda msg: console.log(msg))
    console.print(summary_line(summary))
    for name, path in paths.items():
        console.print(f"{name}: {path}")
    note_earlier_outputs(console, out, OUTPUT_NAMES, paths.values())
    if summary.get("dry_run") and not summary["ok"]:
        raise typer.Exit(1)
