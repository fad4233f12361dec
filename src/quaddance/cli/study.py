"""The ``study`` command: the paper's section 4.3 study, every variant trained, evaluated and
tabulated (`quaddance.study`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from quaddance.cli.options import finite_in


def study_cmd(
    budget: Annotated[
        int,
        typer.Option(
            help="Env steps per run (default: sized for about 2 hours on 2 CPU cores).",
            min=1,
            max=10**11,
        ),
    ] = 1_250_000,  # quaddance.study.DEFAULT_BUDGET (imported lazily: torch)
    seeds: Annotated[int, typer.Option(help="Seeds per variant (1, 2, ...).", min=1, max=100)] = 2,
    only: Annotated[
        list[str] | None,
        typer.Option(help="Run only these variants (repeat, or NAME,NAME); see --list."),
    ] = None,
    list_: Annotated[
        bool, typer.Option("--list", help="Print the variants and what each changes, and stop.")
    ] = False,
    out: Annotated[
        Path,
        typer.Option(help="Finished runs; the report goes beside it (OUT.md, OUT.json)."),
    ] = Path("docs/results/study"),
    work_dir: Annotated[
        Path, typer.Option(help="Training work: checkpoints, banks, logs (resumable).")
    ] = Path("runs/study"),
    engine: Annotated[
        str, typer.Option(help="Physics: cpu (native MuJoCo) or gpu (MuJoCo Warp).")
    ] = "cpu",
    num_envs: Annotated[int, typer.Option(help="Parallel envs.", min=1, max=2**20)] = 256,
    bank_size: Annotated[
        int, typer.Option(help="Target sequences in each run's bank.", min=1, max=100_000)
    ] = 256,
    eval_items: Annotated[
        int, typer.Option(help="Held-out items each run dances (1-4).", min=1, max=4)
    ] = 4,
    eval_seconds: Annotated[
        float,
        typer.Option(help="Length of each held-out item, s.", callback=finite_in(2.0, 600.0)),
    ] = 20.0,
) -> None:
    """Train every variant of the paper's study (reward form, Table 1, c_r, h0, feed-forward,
    the paper's setup) at one budget, evaluate each on held-out songs, write OUT.md with the
    table and the paper's claims; a rerun skips finished runs."""
    from quaddance.study import StudyCfg, list_variants, run_study

    if list_:
        print(list_variants())
        return
    names = tuple(name for value in only or () for name in value.split(",") if name)
    cfg = StudyCfg(
        out=out,
        work=work_dir,
        budget_env_steps=budget,
        seeds=seeds,
        only=names,
        engine=engine,
        num_envs=num_envs,
        bank_size=bank_size,
        eval_items=eval_items,
        eval_duration_s=eval_seconds,
    )
    run_study(cfg)
