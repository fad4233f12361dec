"""The ``train`` command: PPO on the dance task; exports the policy."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from quaddance.cli.options import RobotModelOpt, SeedRange, finite_in


def train_cmd(
    robot: RobotModelOpt = "go1",
    engine: Annotated[
        str, typer.Option(help="Physics: cpu (native MuJoCo) or gpu (MuJoCo Warp).")
    ] = "cpu",
    num_envs: Annotated[
        int | None, typer.Option(help="Parallel envs (default: the preset's).", min=1, max=2**20)
    ] = None,
    iterations: Annotated[
        int,
        typer.Option(help="PPO iterations in total (with --resume: up to).", min=1, max=10**8),
    ] = 1000,
    run_dir: Annotated[
        Path, typer.Option(help="Checkpoints, logs, curve and the exported policy.")
    ] = Path("runs/dance"),
    resume: Annotated[bool, typer.Option(help="Continue from RUN_DIR/checkpoint.pt.")] = False,
    reward: Annotated[
        str, typer.Option(help="paper (eq. 2: c_f 30, lambda_f 10), l2, or table1-1 ... table1-5.")
    ] = "paper",
    c_r: Annotated[
        float,
        typer.Option(
            "--c-r",
            help="Eq. 3's rear-leg weight c_r (the paper settled on -30).",
            callback=finite_in(-1e4, 0.0),
        ),
    ] = -30.0,
    without: Annotated[
        list[str] | None,
        typer.Option(
            "--without",
            help="Leave a reward term out (repeatable); 'ours' leaves out every term that is "
            "not the paper's (rear_lift_l1, foot_slide, base_drift, yaw_rate).",
            metavar="TERM",
        ),
    ] = None,
    mode: Annotated[
        str,
        typer.Option(
            help="Targets of the training bank: feasible, or paper (eq. 4: h0 * h / max(h))."
        ),
    ] = "feasible",
    h0: Annotated[
        float | None,
        typer.Option(
            "--h0",
            help="Eq. 4's h0, m, with --mode paper (default 2, the paper's; 0.5 kept its "
            "paws down).",
            callback=finite_in(0.01, 10.0),
        ),
    ] = None,
    preset: Annotated[
        str, typer.Option(help="cpu (small nets, fast on 2 cores) or paper (512-256-128, GPUs).")
    ] = "cpu",
    seed: Annotated[
        int, typer.Option(help="Seed of the target bank, the envs and the networks.", **SeedRange)
    ] = 1,
    bank_size: Annotated[
        int, typer.Option(help="Target sequences in the bank.", min=1, max=100_000)
    ] = 256,
    max_height: Annotated[
        float | None,
        typer.Option(
            help="Highest front-foot target in the bank, m.", callback=finite_in(0.01, 1.0)
        ),
    ] = None,
    checkpoint_every: Annotated[
        float,
        typer.Option(help="Seconds between checkpoints.", callback=finite_in(1.0, 86_400.0)),
    ] = 120.0,
    minutes: Annotated[
        float | None,
        typer.Option(
            help="Stop (checkpoint and export) after this many minutes.",
            callback=finite_in(0.0, 525_600.0),
        ),
    ] = None,
    progress: Annotated[bool, typer.Option(help="Show a progress bar.")] = True,
    feedforward: Annotated[
        bool,
        typer.Option(
            "--feedforward/--no-feedforward",
            help="Front-lift feed-forward (sim/feedforward.py); off: the policy alone lifts "
            "the feet (the ablation where PPO stands still).",
        ),
    ] = True,
    whole_body: Annotated[
        bool,
        typer.Option(
            "--whole-body/--paws-only",
            help="Whole-body dance: the bank has body targets (trunk height, roll, pitch, "
            "yaw), the actor sees them and its heading error (IMU yaw since the start minus "
            "the target yaw), rewards track them, a body feed-forward moves the legs.",
        ),
    ] = False,
    init_from: Annotated[
        Path | None,
        typer.Option(
            help="Start from another run's checkpoint.pt: shared inputs keep their weights, new "
            "ones (e.g. --whole-body's body targets) start at zero weight."
        ),
    ] = None,
    curriculum: Annotated[
        tuple[float, float] | None,
        typer.Option(
            help="Whole-body curriculum, millions of env steps: the paws-only task until START "
            "(no trunk motion, no trunk-tracking or foot-slide reward), the whole-body task "
            "from END. Default: 3 13 from scratch, none with --init-from; "
            "0 0: full size throughout.",
            metavar="START END",
        ),
    ] = None,
) -> None:
    """Train the dance policy with PPO; exports RUN_DIR/policy.onnx and policy.json."""
    from rich.console import Console

    from quaddance.robots import get_robot
    from quaddance.sim import tasks
    from quaddance.train import PRESETS, TRAIN_MODES, TrainCfg, train

    if engine not in ("cpu", "gpu"):
        raise typer.BadParameter(f"--engine must be cpu or gpu, got {engine!r}")
    if preset not in PRESETS:
        raise typer.BadParameter(f"--preset must be one of {', '.join(PRESETS)}, got {preset!r}")
    if reward not in tasks.REWARD_SETS:
        sets = ", ".join(tasks.REWARD_SETS)
        raise typer.BadParameter(f"--reward must be one of {sets}, got {reward!r}")
    if mode not in TRAIN_MODES:
        raise typer.BadParameter(f"--mode must be one of {', '.join(TRAIN_MODES)}, got {mode!r}")
    if h0 is not None and mode != "paper":
        raise typer.BadParameter("--h0 scales eq. 4's targets: give it with --mode paper")
    named = [tasks.OUR_TERMS if name == "ours" else (name,) for name in without or ()]
    dropped = tuple(dict.fromkeys(name for names in named for name in names))
    known = tasks.dance_rewards(whole_body=whole_body)
    for name in dropped:
        if name not in known:
            terms = ", ".join(known)
            raise typer.BadParameter(f"--without: no reward term {name!r} (ours, {terms})")
    options: dict = {
        "reward_set": reward,
        "c_r": c_r,
        "without": dropped,
        "num_envs": num_envs or PRESETS[preset].num_envs,
        "front_feedforward": feedforward,
        "robot": get_robot(robot),
    }
    if whole_body and curriculum is not None:
        start, end = curriculum
        if not (0 <= start <= end < 1e6) or not all(math.isfinite(x) for x in curriculum):
            raise typer.BadParameter(f"--curriculum needs 0 <= START <= END, got {start} {end}")
        options["curriculum_env_steps"] = (round(start * 1e6), round(end * 1e6)) if end else None
    elif whole_body and init_from is not None:
        options["curriculum_env_steps"] = None  # a trained policy takes the full task at once
    variant = tasks.TASKS["whole-body" if whole_body else "paws-only"]
    console = Console(stderr=True)
    if engine == "gpu":
        import torch

        if not torch.cuda.is_available():
            console.print(
                "warning: no CUDA device: --engine gpu runs MuJoCo Warp on the CPU, far slower "
                "than --engine cpu"
            )
    cfg = TrainCfg(
        run_dir=run_dir,
        engine=engine,
        preset=preset,
        iterations=iterations,
        seed=seed,
        resume=resume,
        bank_size=bank_size,
        max_height_m=max_height,
        target_mode=mode,
        h0_m=TrainCfg.h0_m if h0 is None else h0,
        checkpoint_every_s=checkpoint_every,
        max_minutes=minutes,
        init_from=init_from,
        task=variant(**options),
    )
    with console.status("Building the target bank (first run only) and the envs..."):
        from quaddance.fileio import ensure_dir
        from quaddance.train import build_bank, run_start

        start = run_start(cfg)  # a bad checkpoint or run folder fails before the bank is built
        ensure_dir(run_dir)
        bank = build_bank(cfg)
    trainer = train(cfg, log=console.print, progress=progress, bank=bank, start=start)
    console.print(
        f"done: {trainer.iteration} iterations, {trainer.env_steps:,} env steps, "
        f"{trainer.wall_s / 60:.1f} min; policy -> {run_dir / 'policy.onnx'}"
    )
