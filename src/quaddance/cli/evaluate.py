"""The ``eval`` command: a policy over many songs and motions -> a report (md, json, png)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from quaddance.cli.options import SEED_MAX, PolicyOpt, PolicyRobotOpt


def eval_cmd(
    items: Annotated[
        list[Path] | None,
        typer.Argument(help="Songs, motion files or folders of them (default: --held-out)."),
    ] = None,
    report: Annotated[Path, typer.Option("--report", "-o", help="Markdown report.")] = Path(
        "report.md"
    ),
    policy: PolicyOpt = None,
    robot: PolicyRobotOpt = None,
    held_out: Annotated[
        Path | None,
        typer.Option(help="Write held-out set --set into this folder and evaluate it."),
    ] = None,
    held_out_set: Annotated[
        str,
        typer.Option(
            "--set",
            help="Held-out set for --held-out: generator (8 code-made songs through the "
            "built-in choreographer + 2 SMPL stepping motions: the training generator) or "
            "other (8 motions made another way: holds, 200 BPM alternation, near-maximum "
            "knee lifts, jumps, 60-180 BPM, BVH files of 5 other skeletons, EDGE/AIST++).",
        ),
    ] = "generator",
    seed: Annotated[
        int,
        typer.Option(
            help="Choreographer seed; item i's randomised dynamics use 1000*SEED+i.",
            min=0,
            max=SEED_MAX // 1000 - 1000,
        ),
    ] = 0,
    randomize: Annotated[
        bool,
        typer.Option(
            help="Randomise the robot's dynamics as in training (friction, mass, strength, "
            "joint offsets, lag, pushes), a different draw per item."
        ),
    ] = False,
    policy_output: Annotated[
        str,
        typer.Option(
            help="policy, or zero: replace the policy's output by zeros, leaving the front-lift "
            "feed-forward alone (the baseline the policy adds to)."
        ),
    ] = "policy",
    title: Annotated[str | None, typer.Option(help="Heading of the report.")] = None,
) -> None:
    """Run a policy over many songs/motions (no video): REPORT (markdown table + mean),
    REPORT's .json (every item's metrics.json + the mean) and .png (plot)."""
    from rich.console import Console
    from rich.progress import Progress

    from quaddance.play.evaluate import EvalSettings, collect_items, evaluate, summary_line
    from quaddance.play.heldout import HELD_OUT_SETS, write_held_out_set
    from quaddance.play.policy import choose_policy
    from quaddance.play.rollout import POLICY_OUTPUTS

    if held_out_set not in HELD_OUT_SETS:
        raise typer.BadParameter(f"--set must be one of {', '.join(HELD_OUT_SETS)}")
    if policy_output not in POLICY_OUTPUTS:
        raise typer.BadParameter(f"--policy-output must be one of {', '.join(POLICY_OUTPUTS)}")
    _, policy = choose_policy(robot, policy)
    paths = list(items or [])
    if held_out is not None:
        paths += write_held_out_set(held_out, held_out_set)
    if not paths:
        raise typer.BadParameter("give songs/motions/folders, or --held-out DIR")
    todo = collect_items(paths)
    settings = EvalSettings(seed=seed, randomize=randomize, policy_output=policy_output)
    with Progress(console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task("evaluating", total=len(todo))

        def step(i: int, n: int, name: str) -> None:
            bar.update(task, completed=i, description=f"evaluating {name}")

        rows = evaluate(todo, policy, report, settings, progress=step, title=title)
    print(f"{summary_line(rows)} -> {report} (+ .json, .png)")
