"""The `quaddance` command. Command bodies import lazily so that `--help` stays fast."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from quaddance.errors import QuaddanceError

app = typer.Typer(
    no_args_is_help=True,
    add_completion=False,
    help="Make a Unitree Go1 quadruped dance to any piece of music.",
)
bench_app = typer.Typer(
    no_args_is_help=True, help="Benchmarks; each writes a JSON file of results."
)
app.add_typer(bench_app, name="bench")

SongArg = Annotated[Path, typer.Argument(help="Audio file: wav, flac, ogg or mp3.")]


# --- music -----------------------------------------------------------------------------------
# (commands: analyze, demo-song)

# --- choreography ----------------------------------------------------------------------------
# (command: choreograph)


@app.command("choreograph")
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
    h0: Annotated[float, typer.Option(help="paper mode: eq. 4's h0, m (paper: 2).")] = 2.0,
    scale: Annotated[float, typer.Option(help="minmax mode: scale s (released code).")] = 1.0,
    max_height: Annotated[
        float, typer.Option(help="feasible mode: highest front-foot target, m.")
    ] = 0.20,
    seed: Annotated[int, typer.Option(help="Choreographer seed: another seed, another dance.")] = 0,
    style: Annotated[
        str, typer.Option(help="Choreographer style: mixed, calm, energetic or footwork.")
    ] = "mixed",
) -> None:
    """Turn a song (or a human motion file) into robot foot-height targets, dance.npz."""
    import numpy as np
    from rich.console import Console
    from rich.table import Table

    from quaddance.dancefile import save_dance
    from quaddance.errors import InputFileError
    from quaddance.pipeline import make_dance
    from quaddance.targets import MODES, TargetConfig

    if song is None and motion is None:
        raise typer.BadParameter("give a SONG, or --motion FILE (or both)")
    if mode not in MODES:
        raise typer.BadParameter(f"--mode must be one of {', '.join(MODES)}, got {mode!r}")
    for path in (song, motion):
        if path is not None and not path.is_file():
            raise InputFileError(path, "no such file")
    cfg = TargetConfig(mode=mode, h0_m=h0, scale=scale, max_height_m=max_height)
    console = Console(stderr=True)
    with console.status("Analysing the music and choreographing..."):
        dance, analysis = make_dance(
            song, motion, mode=mode, seed=seed, target_cfg=cfg, style=style
        )
    save_dance(out, dance)

    front = dance.targets_m[:, :2]
    up = front > 0
    n_lifts = [
        int(np.count_nonzero(np.diff(up[:, k].astype(np.int8)) == 1) + up[0, k]) for k in (0, 1)
    ]
    table = Table(title=f"dance -> {out}", show_header=False)
    table.add_row("source", dance.source)
    table.add_row("duration", f"{dance.duration_s:.1f} s at {dance.fps:g} Hz")
    if analysis is not None:
        table.add_row("tempo", f"{analysis.tempo_bpm:.1f} BPM, {dance.beats_s.size} beats")
    table.add_row("mode", dance.mode)
    table.add_row("lifts FL / FR", f"{n_lifts[0]} / {n_lifts[1]}")
    table.add_row("highest target", f"{front.max():.3f} m")
    table.add_row("a front foot up", f"{100 * up.any(axis=1).mean():.0f} % of the time")
    table.add_row("both front feet up", f"{100 * up.all(axis=1).mean():.0f} % of the time")
    Console().print(table)


# --- training --------------------------------------------------------------------------------


@app.command("train")
def train_cmd(
    engine: Annotated[
        str, typer.Option(help="Physics: cpu (native MuJoCo) or gpu (MuJoCo Warp).")
    ] = "cpu",
    num_envs: Annotated[
        int | None, typer.Option(help="Parallel envs (default: the preset's).")
    ] = None,
    iterations: Annotated[
        int, typer.Option(help="PPO iterations in total (with --resume: up to).")
    ] = 1000,
    run_dir: Annotated[
        Path, typer.Option(help="Checkpoints, logs, curve and the exported policy.")
    ] = Path("runs/dance"),
    resume: Annotated[bool, typer.Option(help="Continue from RUN_DIR/checkpoint.pt.")] = False,
    reward: Annotated[
        str, typer.Option(help="paper (eq. 2: c_f 30, lambda_f 10), l2, or table1-1 ... table1-5.")
    ] = "paper",
    preset: Annotated[
        str, typer.Option(help="cpu (small nets, fast on 2 cores) or paper (512-256-128, GPUs).")
    ] = "cpu",
    seed: Annotated[
        int, typer.Option(help="Seed of the target bank, the envs and the networks.")
    ] = 1,
    bank_size: Annotated[int, typer.Option(help="Target sequences in the bank.")] = 256,
    max_height: Annotated[
        float | None, typer.Option(help="Highest front-foot target in the bank, m.")
    ] = None,
    checkpoint_every: Annotated[float, typer.Option(help="Seconds between checkpoints.")] = 120.0,
) -> None:
    """Train the dance policy with PPO; exports RUN_DIR/policy.onnx and policy.json."""
    from rich.console import Console

    from quaddance.sim.config import RewardCfg
    from quaddance.train import PRESETS, TrainCfg, train

    if engine not in ("cpu", "gpu"):
        raise typer.BadParameter(f"--engine must be cpu or gpu, got {engine!r}")
    if preset not in PRESETS:
        raise typer.BadParameter(f"--preset must be one of {', '.join(PRESETS)}, got {preset!r}")
    try:
        RewardCfg.named(reward)
    except ValueError as err:
        raise typer.BadParameter(str(err)) from err
    console = Console(stderr=True)
    cfg = TrainCfg(
        run_dir=run_dir,
        engine=engine,
        preset=preset,
        num_envs=num_envs,
        iterations=iterations,
        reward=reward,
        seed=seed,
        resume=resume,
        bank_size=bank_size,
        max_height_m=max_height,
        checkpoint_every_s=checkpoint_every,
    )
    with console.status("Building the target bank (first run only) and the envs..."):
        from quaddance.train import build_bank

        run_dir.mkdir(parents=True, exist_ok=True)
        build_bank(cfg)
    trainer = train(cfg, log=console.print)
    console.print(
        f"done: {trainer.iteration} iterations, {trainer.env_steps:,} env steps, "
        f"{trainer.wall_s / 60:.1f} min; policy -> {run_dir / 'policy.onnx'}"
    )


# --- playback --------------------------------------------------------------------------------
# (commands: dance, eval)

# --- benchmarks ------------------------------------------------------------------------------
# (bench subcommands: beats, choreograph, train, dance)


@bench_app.command("choreograph")
def bench_choreograph_cmd(
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Where to write the JSON results.")
    ] = Path("benchmarks/results/choreograph.json"),
    repeats: Annotated[int, typer.Option(help="Runs per timing; the median is kept.")] = 5,
) -> None:
    """Seconds to choreograph 3 minutes of music from a beat grid, and to make its targets."""
    from rich.console import Console

    from quaddance.bench.choreograph import run_choreograph_bench

    with Console(stderr=True).status("Timing the choreographer and the targets..."):
        results = run_choreograph_bench(out, repeats=repeats)
    print(
        f"choreograph {results['duration_s']:.0f} s of music: "
        f"{results['choreograph_s_median']:.4f} s; "
        f"feasible targets: {results['targets_feasible_s_median']:.4f} s; "
        f"bank: {results['bank_s_per_sequence']:.4f} s per {results['bank_sequence_s']:.0f} s "
        f"sequence -> {out}"
    )


def main() -> None:
    """Console entry point: user errors become one line on stderr and exit status 2."""
    try:
        app()
    except QuaddanceError as err:
        print(f"quaddance: error: {err}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
