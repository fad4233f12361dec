"""The `quaddance` command. Command bodies import lazily so that `--help` stays fast."""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from pathlib import Path
from typing import Annotated, Any

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

# --- argument checks: a bad value is a usage error (exit 2) naming the option ----------------

SEED_MAX = 2**32 - 1
"""Largest seed accepted (numpy's and torch's generators take 0 ... 2**32 - 1 everywhere)."""
SeedRange = {"min": 0, "max": SEED_MAX}


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


# --- music -----------------------------------------------------------------------------------
# (commands: analyze, demo-song)


@app.command("analyze")
def analyze_cmd(
    song: SongArg,
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Where to write the analysis JSON.")
    ] = Path("analysis.json"),
) -> None:
    """Find the tempo, beats, downbeats, sections and envelopes of a song; write them as JSON."""
    from rich.console import Console

    from quaddance.fileio import check_output_file
    from quaddance.music.analysis import analyze_file

    check_output_file(out)  # before the work, not after it
    with Console(stderr=True).status(f"Analysing {song.name}..."):
        analysis = analyze_file(song)
    analysis.save_json(out)
    starts = ", ".join(f"{t:.1f}" for t in analysis.sections_s)
    print(
        f"{song.name}: {analysis.duration_s:.1f} s, tempo {analysis.tempo_bpm:.1f} BPM, "
        f"{analysis.beats_s.size} beats, {analysis.downbeats_s.size} bars, "
        f"{analysis.sections_s.size} sections (starting at {starts} s) -> {out}"
    )


@app.command("demo-song")
def demo_song_cmd(
    out: Annotated[Path, typer.Argument(help="Where to write the song (wav, flac or ogg).")] = Path(
        "demo_song.wav"
    ),
) -> None:
    """Write the built-in demo song: 30 s at 118 BPM, drums, bass and chords, made by code."""
    from quaddance.music.synth import write_demo_song

    if out.suffix.lower() not in (".wav", ".flac", ".ogg"):
        raise typer.BadParameter(f"OUT must end in .wav, .flac or .ogg, got {out.name!r}")
    truth = write_demo_song(out)
    print(
        f"demo song: {truth.duration_s:.0f} s, {truth.tempo_bpm:g} BPM, {truth.beats_s.size} beats,"
        f" section change at {truth.section_change_s[0]:.2f} s -> {out}"
    )


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
    moves: Annotated[
        Path | None,
        typer.Option(help="TOML file of extra body moves and styles (see choreo/moves_file.py)."),
    ] = None,
    check: Annotated[
        bool,
        typer.Option(
            "--check", help="Only report what feasible targets clamp (paws, body); write nothing."
        ),
    ] = False,
) -> None:
    """Turn a song (or a human motion file) into robot foot-height and body targets, dance.npz."""
    import numpy as np
    from rich.console import Console
    from rich.table import Table

    from quaddance.dancefile import save_dance
    from quaddance.errors import InputFileError
    from quaddance.fileio import check_output_file
    from quaddance.pipeline import make_dance
    from quaddance.targets import MODES, TargetConfig

    if song is None and motion is None:
        raise typer.BadParameter("give a SONG, or --motion FILE (or both)")
    if mode not in MODES:
        raise typer.BadParameter(f"--mode must be one of {', '.join(MODES)}, got {mode!r}")
    for path in (song, motion):
        if path is not None and not path.is_file():
            raise InputFileError(path, "no such file")
    move_set = None
    if moves is not None:
        from quaddance.choreo.moves_file import load_moves

        move_set = load_moves(moves)  # before the work: a bad file fails in a moment
    if not check:
        check_output_file(out)  # before the work, not after it
    cfg = TargetConfig(mode=mode, h0_m=h0, scale=scale)
    if max_height is not None:
        cfg = dataclasses.replace(cfg, max_height_m=max_height)
    console = Console(stderr=True)
    with console.status("Analysing the music and choreographing..."):
        dance, analysis = make_dance(
            song, motion, mode=mode, seed=seed, target_cfg=cfg, style=style, moves=move_set
        )
    if check:
        _print_clamp_report(dance)
        return
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
    body = dance.body_targets
    table.add_row(
        "trunk range",
        f"height {body[:, 0].min():+.3f}..{body[:, 0].max():+.3f} m, roll/pitch/yaw "
        + " / ".join(f"{np.rad2deg(np.ptp(body[:, c])):.0f}" for c in (1, 2, 3))
        + " deg",
    )
    Console().print(table)


def _print_clamp_report(dance: Any) -> None:
    """The table of ``choreograph --check``: what feasible targets clamped, and by how much."""
    import numpy as np
    from rich.console import Console
    from rich.table import Table

    from quaddance.targets import BODY_COLUMNS

    report = dance.clamp_report or {}
    paw = report.get("paw", {})
    table = Table(title=f"clamp check: {dance.source}")
    for name in ("what", "clamped", "max", "mean"):
        table.add_column(name)
    table.add_row(
        "paw lifts",
        f"{paw.get('human_lifts', 0)} human -> {paw.get('robot_lifts', 0)} robot "
        f"({paw.get('dropped_or_merged', 0)} dropped or merged)",
        f"{paw.get('clipped_to_max_height', 0)} clipped to {paw.get('max_height_m', 0):.2f} m",
        f"highest {paw.get('highest_target_m', 0):.3f} m",
    )
    body = report.get("body", {})
    n = max(int(body.get("samples", 0)), 1)
    for name in BODY_COLUMNS:
        col = body.get(name, {"clamped": 0, "max": 0.0, "mean": 0.0})
        unit, scale = ("m", 1.0) if name.endswith("_m") else ("deg", float(np.rad2deg(1.0)))
        table.add_row(
            f"body {name}",
            f"{col['clamped']} samples ({100 * col['clamped'] / n:.0f} %)",
            f"{col['max'] * scale:.3f} {unit}",
            f"{col['mean'] * scale:.4f} {unit}",
        )
    Console().print(table)


# Options that several commands share, defined once.
PolicyOpt = Annotated[
    Path | None, typer.Option(help="Policy .onnx (its .json beside it); default: shipped.")
]
RobotOpt = Annotated[
    str, typer.Option(help="sim (a simulated Go1 in another process) or go1 (a real one).")
]
RobotIpOpt = Annotated[str, typer.Option(help="go1: the robot's low-level IP.")]
PowerLevelOpt = Annotated[
    int, typer.Option(help="go1: SDK PowerProtect level, 1 (10 %) to 10.", min=1, max=10)
]


# --- training --------------------------------------------------------------------------------


@app.command("train")
def train_cmd(
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

    from quaddance.sim.config import DanceTaskCfg, ObsCfg, RewardCfg
    from quaddance.train import DEFAULT_CURRICULUM_M_STEPS, PRESETS, TrainCfg, train

    if engine not in ("cpu", "gpu"):
        raise typer.BadParameter(f"--engine must be cpu or gpu, got {engine!r}")
    if preset not in PRESETS:
        raise typer.BadParameter(f"--preset must be one of {', '.join(PRESETS)}, got {preset!r}")
    try:
        RewardCfg.named(reward)
    except ValueError as err:
        raise typer.BadParameter(str(err)) from err
    if curriculum is None and whole_body and init_from is None:
        curriculum = DEFAULT_CURRICULUM_M_STEPS
    ramp_steps = None
    if curriculum is not None and whole_body:
        start, end = curriculum
        if not (0 <= start <= end < 1e6) or not all(math.isfinite(x) for x in curriculum):
            raise typer.BadParameter(f"--curriculum needs 0 <= START <= END, got {start} {end}")
        ramp_steps = (round(start * 1e6), round(end * 1e6)) if end > 0 else None
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
        max_minutes=minutes,
        init_from=init_from,
        curriculum_env_steps=ramp_steps,
        task=DanceTaskCfg(
            front_feedforward=feedforward, whole_body=whole_body, obs=ObsCfg(heading=whole_body)
        ),
    )
    with console.status("Building the target bank (first run only) and the envs..."):
        from quaddance.fileio import ensure_dir
        from quaddance.train import build_bank

        ensure_dir(run_dir)
        bank = build_bank(cfg)
    trainer = train(cfg, log=console.print, progress=progress, bank=bank)
    console.print(
        f"done: {trainer.iteration} iterations, {trainer.env_steps:,} env steps, "
        f"{trainer.wall_s / 60:.1f} min; policy -> {run_dir / 'policy.onnx'}"
    )


# --- playback --------------------------------------------------------------------------------


@app.command("dance")
def dance_cmd(
    song: Annotated[
        Path | None, typer.Argument(help="Audio file: wav, flac, ogg or mp3 (or use --demo).")
    ] = None,
    demo: Annotated[bool, typer.Option(help="Dance to the built-in demo song.")] = False,
    motion: Annotated[
        Path | None, typer.Option(help="Human motion (EDGE/AIST++ .pkl, .bvh) instead of ours.")
    ] = None,
    policy: PolicyOpt = None,
    mode: Annotated[str, typer.Option(help="Targets: feasible, paper or minmax.")] = "feasible",
    seed: Annotated[int, typer.Option(help="Choreographer seed.", **SeedRange)] = 0,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("dance_out"),
    no_video: Annotated[bool, typer.Option("--no-video", help="Skip the video.")] = False,
    randomize: Annotated[
        bool, typer.Option(help="Randomise the robot's dynamics as in training.")
    ] = False,
    style: Annotated[str, typer.Option(help="Choreography style.")] = "mixed",
    moves: Annotated[
        Path | None,
        typer.Option(help="TOML file of extra body moves and styles (see choreo/moves_file.py)."),
    ] = None,
) -> None:
    """Make the Go1 dance to a song: dance.mp4 (with the music), feet.png, metrics.json,
    dance.npz and rollout.npz."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    from quaddance.play.dance import DanceJob, run_dance
    from quaddance.play.metrics import summary_table
    from quaddance.targets import MODES

    if mode not in MODES:
        raise typer.BadParameter(f"--mode must be one of {', '.join(MODES)}, got {mode!r}")
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
        mode=mode,
        seed=seed,
        video=not no_video,
        randomize=randomize,
        style=style,
        moves=moves,
        analysis_process=True,
    )
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
    console.print(f"took {result.timings_s['total_s']:.1f} s")
    _exit_without_teardown()


def _exit_without_teardown() -> None:
    """End a command whose outputs are all written and closed, skipping the interpreter's
    teardown: unloading torch alone takes 0.9 s, and the exit would wait for the helper
    process's own teardown too (`dance`: 2 s between its last line and the shell's prompt,
    measured). The helper has been told to stop and ends on its own."""
    import gc

    gc.collect()  # run multiprocessing's finalizers: the resource tracker must not warn
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


@app.command("deploy")
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
        typer.Option(help="Fault at dance time T, s (sim only): push@T, freeze@T, nan@T, lag@T."),
    ] = None,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("deploy_out"),
    robot_ip: RobotIpOpt = "192.168.123.10",
    power_level: PowerLevelOpt = 1,
    sim_latency_ms: Annotated[
        tuple[float, float],
        typer.Option(
            help="sim: sensor-to-motor delay range, ms (drawn per message).",
            callback=finite_in(0.0, 500.0),
        ),
    ] = (5.0, 20.0),
) -> None:
    """Run the dance on a robot: passive -> soft stand -> ready -> dance -> done, with a safety
    layer (damping on a fall, a stale or NaN state, Ctrl-C); writes deploy.json and log.npz."""
    from rich.console import Console

    from quaddance.deploy.job import DeployJob, parse_inject, run_deploy

    console = Console(stderr=True)
    job = DeployJob(
        out_dir=out,
        robot=robot,
        song=song,
        motion=motion,
        dance=dance,
        demo=demo,
        policy=policy,
        seconds=seconds,
        auto_start=auto_start,
        inject=parse_inject(inject),
        robot_ip=robot_ip,
        power_level=power_level,
        sim_latency_ms=sim_latency_ms,
    )
    summary, paths = run_deploy(job, status=lambda msg: console.log(msg))
    front = summary["front"] or {}
    mae = [front[f]["mae_m"] for f in ("fl", "fr") if f in front and front[f]["mae_m"] is not None]
    console.print(
        f"final state {summary['final_state']}, danced {summary['duration_s']:.1f} s, "
        f"falls {summary['falls']}, front MAE "
        + (f"{100 * sum(mae) / len(mae):.1f} cm" if mae else "n/a")
        + f", tick p99 {summary['tick_ms']['p99']} ms"
    )
    for name, path in paths.items():
        console.print(f"{name}: {path}")


@app.command("live")
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
    style: Annotated[str, typer.Option(help="Choreography style.")] = "mixed",
    seed: Annotated[int, typer.Option(help="Choreography seed.", **SeedRange)] = 0,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("live_out"),
    robot_ip: RobotIpOpt = "192.168.123.10",
    power_level: PowerLevelOpt = 1,
) -> None:
    """Dance to music as it plays: online beat tracking, a dance planned a bar ahead, the
    robot on the wall clock (same runner and safety layer as deploy). Writes live.json,
    rollout.npz, deploy.json and log.npz (and dance.mp4 with --video)."""
    from rich.console import Console

    from quaddance.choreo.choreographer import STYLES
    from quaddance.live.session import LiveJob, run_live

    if style not in STYLES:
        raise typer.BadParameter(f"--style must be one of {', '.join(sorted(STYLES))}")
    console = Console(stderr=True)
    job = LiveJob(
        out_dir=out,
        from_file=from_file,
        start_s=start,
        device=device,
        robot=robot,
        policy=policy,
        seconds=seconds,
        viewer=viewer,
        host=host,
        port=port,
        video=video,
        seed=seed,
        style=style,
        robot_ip=robot_ip,
        power_level=power_level,
    )
    summary, paths = run_live(job, status=lambda msg: console.log(msg))
    lock = summary["lock_s"]
    console.print(
        f"danced {summary['duration_s']:.1f} s, falls {summary['falls']}, "
        + (f"beat locked at {lock:.1f} s" if lock is not None else "no beat lock")
        + f", {len(summary['beats_s'])} beats, latency p50/p99 "
        f"{summary['latency_ms']['p50']} / {summary['latency_ms']['p99']} ms, "
        f"loop p99 {summary['loop_ms']['p99']} ms"
    )
    for name, path in paths.items():
        console.print(f"{name}: {path}")


@app.command("eval")
def eval_cmd(
    items: Annotated[
        list[Path] | None,
        typer.Argument(help="Songs, motion files or folders of them (default: --held-out)."),
    ] = None,
    report: Annotated[Path, typer.Option("--report", "-o", help="Markdown report.")] = Path(
        "report.md"
    ),
    policy: PolicyOpt = None,
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

    from quaddance.bench.heldout import HELD_OUT_SETS, write_held_out_set
    from quaddance.play.evaluate import EvalSettings, collect_items, evaluate, summarize
    from quaddance.play.rollout import POLICY_OUTPUTS

    if held_out_set not in HELD_OUT_SETS:
        raise typer.BadParameter(f"--set must be one of {', '.join(HELD_OUT_SETS)}")
    if policy_output not in POLICY_OUTPUTS:
        raise typer.BadParameter(f"--policy-output must be one of {', '.join(POLICY_OUTPUTS)}")
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
    s = summarize(rows)
    print(
        f"{s['items']} items, {s['falls']} falls; feasible MAE "
        f"{100 * (s['mae_feasible_m'] or 0):.1f} cm, corr {s['corr_feasible'] or 0:.2f}; rear lift "
        f"{100 * (s['rear_lift_mean_m'] or 0):.1f} cm mean -> {report} (+ .json, .png)"
    )


# --- benchmarks ------------------------------------------------------------------------------
# (bench subcommands: beats, choreograph, train, dance, reach)


@bench_app.command("live")
def bench_live_cmd(
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Where to write the JSON results.")
    ] = Path("benchmarks/results/live.json"),
    sets: Annotated[
        str,
        typer.Option(
            help="Sets, comma-separated: random, untuned, live, heldout (tuning too); the "
            "whole loop runs on the live-case sets among them (live, heldout) and, with "
            "tuning, on 8 tuning songs."
        ),
    ] = "random,untuned,live,heldout",
    random: Annotated[
        int, typer.Option(help="Songs in the random MIDI set.", min=0, max=1000)
    ] = 12,
    dance: Annotated[
        bool,
        typer.Option(
            "--dance/--tracker-only",
            help="Also run `live --from-file` in real time on the live-case songs (about "
            "8 min for live and heldout; 5 min for the tuning songs).",
        ),
    ] = True,
    shifts: Annotated[
        int,
        typer.Option(
            help="Also track every song with its audio moved by k/N of an onset frame (k < N)"
            " and average the goals over the N shifts: single runs flip songs, the means are"
            " steadier (to compare tracker changes).",
            min=1,
            max=16,
        ),
    ] = 1,
) -> None:
    """Online beat tracking vs the offline analyser (lock time, F-measure) on songs with exact
    beats not tuned on, heard from their start and joined mid-song (also: after a quiet room,
    with noise, and whether noise alone locks it); then the whole live loop on the simulated
    robot: falls, loop time, latency, the robot's motion accents on the true beats. Writes
    JSON."""
    import tempfile

    from rich.console import Console

    from quaddance.bench.live import bench_live_dance, bench_live_tracker, machine_info
    from quaddance.fileio import write_json

    console = Console(stderr=True)
    chosen = tuple(s.strip() for s in sets.split(",") if s.strip())
    with console.status("Tracking beats online...") as status:
        results = {
            "tracker": bench_live_tracker(
                chosen,
                n_random=random,
                progress=lambda n: status.update(f"Tracking {n}..."),
                shifts=shifts,
            )
        }
    for name, m in results["tracker"]["means"].items():
        console.print(
            f"{name}: {m['n_locked']}/{m['n_songs']} locked, median lock {m['lock_s_median']} s,"
            f" F online {m['f_online']:.3f} vs offline {m['f_offline']:.3f}; joined mid-song:"
            f" median lock {m['join_lock_s_median']} s, F online {m['join_f_online']:.3f} vs"
            f" offline {m['join_f_offline']:.3f}"
        )
    goals = results["tracker"]["goals"]
    console.print(
        f"locked within {goals['lock_within_s']:g} s: {goals['songs_locked_in_time']} from"
        f" the start, {goals['joining_mid_song']['songs_locked_in_time']} joined mid-song,"
        f" {goals['after_silence_locked_in_time']} after a quiet room,"
        f" {goals['with_noise_locked_in_time']} with noise; F online after a quiet room / with"
        " noise: "
        + ", ".join(
            f"{name} {m['silence_f_online']:.3f} / {m['noisy_f_online']:.3f}"
            for name, m in results["tracker"]["means"].items()
        )
    )
    if "shifted" in goals:
        s = goals["shifted"]
        j = s["joining_mid_song"]
        console.print(
            f"averaged over {s['shifts']} shifts within a frame: from the start"
            f" {s['songs_locked_in_time']:g} locked in time, {s['songs_within_f_gap']:g}"
            f" within the F gap, F online {s['f_online']:.3f}; joined mid-song"
            f" {j['songs_locked_in_time']:g}, {j['songs_within_f_gap']:g},"
            f" F {j['f_online']:.3f} (of {len(results['tracker']['songs'])} songs)"
        )
    noise = results["tracker"]["noise"]
    console.print(
        f"steady noise ({noise['clips']} clips of {noise['duration_s']:g} s): locked in "
        + ", ".join(f"{n} {where}" for where, n in noise["locked"].items())
    )
    if dance:
        with tempfile.TemporaryDirectory(prefix="quaddance-bench-live-") as tmp:
            results["dance"] = bench_live_dance(
                Path(tmp), progress=lambda n: console.log(f"live dance: {n}"), sets=chosen
            )
        for r in results["dance"]["songs"]:
            console.print(
                f"{r['name']}: lock {r['lock_s']} s, falls {r['falls']}, accents on "
                f"{100 * r['accent_coverage_after_lock']:.0f} % of beats (median "
                f"{r['accent_median_offset_ms']} ms), loop p99 {r['loop_ms']['p99']} ms"
            )
    results["machine"] = machine_info()
    write_json(out, results)
    console.print(f"results: {out}")


@bench_app.command("beats")
def bench_beats_cmd(
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Where to write the JSON results.")
    ] = Path("benchmarks/results/beats.json"),
    random: Annotated[
        int, typer.Option(help="Songs in the random MIDI set (not tuned on).", min=0, max=1000)
    ] = 12,
    sets: Annotated[
        str, typer.Option(help="Comma-separated sets to score: tuning, random, untuned.")
    ] = "tuning,random,untuned",
    madmom_python: Annotated[
        Path | None,
        typer.Option(
            help="A Python interpreter that can import madmom: also score madmom's DBN tracker "
            "(madmom is not a dependency; install it in a separate environment)."
        ),
    ] = None,
) -> None:
    """Beat F-measure of our analyser, librosa's default (and madmom's) on songs with exact beats.

    Reports the strict F (+-70 ms) and the F at each tracker's own metrical level (same,
    double or half tempo), per set: "tuning" (tuned on), "random" and "untuned" (never tuned
    on). Needs fluidsynth and a General MIDI soundfont (apt-get install fluidsynth
    fluid-soundfont-gm); renderings are cached under benchmarks/cache/.
    """
    from rich.console import Console
    from rich.table import Table

    from quaddance.bench.beats import run_beat_bench

    console = Console(stderr=True)
    chosen = tuple(s.strip() for s in sets.split(",") if s.strip())
    with console.status("Scoring beats...") as status:
        results = run_beat_bench(
            out,
            n_random=random,
            sets=chosen,
            madmom_python=madmom_python,
            progress=lambda name: status.update(f"Scoring {name}..."),
        )
    trackers = ["quaddance", "librosa_default"]
    if madmom_python is not None:
        trackers.append("madmom_dbn")
    table = Table(title="beat F-measure (+-70 ms): strict / at the tracker's metrical level")
    for col in ("song", "set", "BPM", *trackers):
        table.add_column(col)
    for row in results["songs"]:
        cells = [f"{row[f'f_{t}']:.3f} / {row[f'f_metrical_{t}']:.3f}" for t in trackers]
        table.add_row(row["name"], row["set"], f"{row['true_tempo_bpm']:g}", *cells)
    for set_name, mean in results["means"].items():
        cells = [
            f"{mean[f'f_{t}']:.3f} / {mean[f'f_metrical_{t}']:.3f}" if f"f_{t}" in mean else "-"
            for t in trackers
        ]
        table.add_row(f"mean ({mean['n_songs']} songs)", set_name, "", *cells)
    Console().print(table)
    print(f"-> {out}")


@bench_app.command("choreograph")
def bench_choreograph_cmd(
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Where to write the JSON results.")
    ] = Path("benchmarks/results/choreograph.json"),
    repeats: Annotated[
        int, typer.Option(help="Runs per timing; the median is kept.", min=1, max=1000)
    ] = 5,
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


@bench_app.command("train")
def bench_train_cmd(
    out: Annotated[Path, typer.Option("--out", "-o", help="JSON results.")] = Path(
        "benchmarks/results/train_cpu.json"
    ),
    engine: Annotated[str, typer.Option(help="cpu or gpu.")] = "cpu",
    num_envs: Annotated[
        list[int] | None,
        typer.Option(
            help="Env counts (default: cpu 64 256 1024, gpu 4096 16384).", min=1, max=2**20
        ),
    ] = None,
    preset: Annotated[
        str | None, typer.Option(help="Training preset (default: cpu / paper).")
    ] = None,
    iterations: Annotated[
        int, typer.Option(help="Timed PPO iterations per env count.", min=1, max=10_000)
    ] = 3,
    mjlab: Annotated[bool, typer.Option(help="Also time mjlab's Go1 velocity task.")] = True,
) -> None:
    """Env-only and end-to-end PPO env steps/s; writes a JSON file."""
    from quaddance.bench.train import run_train_bench

    counts = tuple(num_envs or ((64, 256, 1024) if engine == "cpu" else (4096, 16384)))
    run_train_bench(
        out,
        engine,
        counts,
        preset or ("cpu" if engine == "cpu" else "paper"),
        iterations=iterations,
        mjlab=mjlab,
    )
    print(f"-> {out}")


@bench_app.command("dance")
def bench_dance_cmd(
    out: Annotated[Path, typer.Option("--out", "-o", help="JSON results.")] = Path(
        "benchmarks/results/dance.json"
    ),
    repeats: Annotated[int, typer.Option(help="Timed runs per song (median and min).")] = 3,
    warmup: Annotated[bool, typer.Option(help="One untimed run first.")] = True,
    policy: Annotated[Path | None, typer.Option(help="Policy .onnx; default: shipped.")] = None,
) -> None:
    """Time the whole `dance` command (video on) on a 12 s and a 30 s song; writes JSON.

    Each run is a fresh process timed from outside; ratio = wall / song length (goal <= 1).
    CPU time of the process tree and the load average are recorded beside the wall time.
    """
    from rich.console import Console

    from quaddance.bench.dance import run_dance_bench

    console = Console(stderr=True)
    results = run_dance_bench(
        out, repeats=repeats, warmup=warmup, policy=policy, progress=console.log
    )
    for song in results["songs"]:
        print(
            f"{song['song_s']:g} s song: wall median {song['wall_median_s']:.1f} s "
            f"({song['ratio_median']:.2f}x), min {song['wall_min_s']:.1f} s "
            f"({song['ratio_min']:.2f}x); CPU {song['cpu_median_s']:.1f} s; "
            f"load {song['load_1min_median']:.1f}"
        )
    print(f"-> {out}")


@bench_app.command("envelope")
def bench_envelope_cmd(
    items: Annotated[
        list[Path] | None,
        typer.Argument(
            help="Songs/motions (default: 2 songs of the generator held-out set and 2 motions "
            "of the other set, written into --work)."
        ),
    ] = None,
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Where to write the JSON results.")
    ] = Path("benchmarks/results/envelope.json"),
    report: Annotated[Path, typer.Option(help="Markdown page of the results.")] = Path(
        "docs/results/envelope.md"
    ),
    policy: PolicyOpt = None,
    work: Annotated[Path, typer.Option(help="Folder for the default items.")] = Path(
        "runs/heldout"
    ),
) -> None:
    """Robustness envelope: falls and tracking at each end of the training randomisation
    ranges (friction 0.1/3, mass -1/+3 kg, strength 0.9/1.1, lag 30 ms, and the four hard
    ends at once), and pushes of increasing strength: the first push velocity that makes the
    robot fall (nominal robot and hard corner)."""
    from rich.console import Console

    from quaddance.bench.envelope import default_items, run_envelope, write_envelope
    from quaddance.play.evaluate import collect_items

    console = Console(stderr=True)
    todo = collect_items(items) if items else default_items(work)
    result = run_envelope(todo, policy, log=console.print)
    command = "quaddance bench envelope" + (f" --policy {policy}" if policy else "")
    write_envelope(result, out, report, command)
    for name, p in result["pushes"].items():
        first = p["first_fall_vel_m_s"]
        print(f"{name}: first fall at push {'none' if first is None else f'{first:.2f} m/s'}")
    print(f"-> {out}, {report}")


@bench_app.command("ff-ablation")
def bench_ff_ablation_cmd(
    run_dir: Annotated[
        Path, typer.Argument(help="Run folder of `quaddance train --no-feedforward`.")
    ],
    shipped_curve: Annotated[
        Path, typer.Option(help="Learning curve of the run with the feed-forward.")
    ] = Path("docs/results/learning_curve.csv.gz"),
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Where to write the JSON results.")
    ] = Path("benchmarks/results/ff_ablation.json"),
    docs: Annotated[
        Path, typer.Option(help="Folder for the curve (csv, png) and the comparison plot.")
    ] = Path("docs/results"),
    with_ff_run: Annotated[
        Path | None,
        typer.Option(
            help="Run folder of the same training with the feed-forward on (same code and "
            "settings): compared too, its curve copied to "
            "DOCS/learning_curve_with_feedforward.csv."
        ),
    ] = None,
) -> None:
    """Training without the front-lift feed-forward next to runs with it: front-foot error
    and rear lift at 0.25-2 M env steps against the error of standing still; copies the
    run's curve to DOCS/learning_curve_no_feedforward.csv (+ .png) and plots the runs in
    DOCS/learning_curve_ff_ablation.png."""
    from quaddance.bench.ablation import run_ablation

    result = run_ablation(run_dir, shipped_curve, out, docs, with_ff_run)
    still = result["standing_still_front_err_m"]
    print(f"standing still: front error {100 * still:.2f} cm")
    for name, run in result["runs"].items():
        known = [a for a in run["at"] if a["front_abs_err_m"] is not None]
        for a in known[-1:]:
            print(
                f"{name}: front error {100 * a['front_abs_err_m']:.2f} cm at "
                f"{a['env_steps'] / 1e6:.2f} M env steps"
            )
    print(f"-> {out}, {docs}")


@bench_app.command("long")
def bench_long_cmd(
    out: Annotated[Path, typer.Option("--out", "-o", help="JSON results.")] = Path(
        "benchmarks/results/long_song.json"
    ),
) -> None:
    """A 20-minute song through `dance --no-video` (time, CPU, peak memory) and a 2-hour
    file that must be refused early (a few minutes)."""
    from rich.console import Console

    from quaddance.bench.long import run_long_bench

    with Console(stderr=True).status("long inputs...") as status:
        results = run_long_bench(out, log=status.update)
    for name in ("dance_20min_no_video", "analyze_2h_silent"):
        r = results[name]
        print(
            f"{name}: exit {r['exit_code']}, {r['wall_s']:.1f} s wall, {r['cpu_s']:.1f} s CPU, "
            f"peak {r['peak_rss_mb']:.0f} MB (load {r['load_avg_1min_before']:.1f})"
        )
    print(f"-> {out}")


@bench_app.command("deploy")
def bench_deploy_cmd(
    out: Annotated[Path, typer.Option("--out", "-o", help="JSON results.")] = Path(
        "benchmarks/results/deploy.json"
    ),
    seconds: Annotated[
        float, typer.Option(help="Dance length, s.", callback=finite_in(1.0, 30.0))
    ] = 20.0,
) -> None:
    """Sim-to-sim: the demo song by `dance` and by `deploy --robot sim`; fault deadlines."""
    from rich.console import Console

    from quaddance.bench.deploy import run
    from quaddance.fileio import check_output_file, write_json

    check_output_file(out)
    console = Console(stderr=True)
    results = run(seconds, log=lambda msg: console.log(msg))
    write_json(out, results)
    for name, r in results["songs"].items():
        d, s = r["dance"], r["deploy_sim"]
        print(
            f"{name}: front MAE dance {100 * d['front_mae_mean_m']:.2f} cm, deploy sim "
            f"{100 * (s['front_mae_mean_m'] or float('nan')):.2f} cm; falls {d['falls']} / "
            f"{s['falls']}; tick ms {s['tick_ms']}"
        )
    print(
        "time to damp: "
        + ", ".join(f"{k} {v['time_to_damp_s']}" for k, v in results["faults"].items())
        + f" -> {out}"
    )


@bench_app.command("body-reach")
def bench_body_reach_cmd(
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Where to write the JSON results.")
    ] = Path("benchmarks/results/body_reach.json"),
    policy: Annotated[
        Path | None,
        typer.Option(help="A whole-body policy .onnx to balance; default: feed-forward alone."),
    ] = None,
) -> None:
    """The trunk poses (height, roll, pitch, yaw) a Go1 holds with four feet down and with a
    front paw up: a sweep per column and sign, the range held without a fall, a foot lifting
    or sliding, or the trunk missing the pose by more than 35 %. Writes JSON."""
    from rich.console import Console

    from quaddance.bench.body_reach import bench_body_reach
    from quaddance.bench.live import machine_info
    from quaddance.fileio import write_json
    from quaddance.play.policy import OnnxPolicy

    console = Console(stderr=True)
    loaded = None if policy is None else OnnxPolicy.load(policy)
    with console.status("Sweeping trunk poses..."):
        results = bench_body_reach(loaded)
    results["machine"] = machine_info()
    for which in ("four_feet", "paw_up"):
        ranges = ", ".join(f"{k} {lo:+g}..{hi:+g}" for k, (lo, hi) in results[which].items())
        console.print(f"{which}: {ranges}")
    write_json(out, results)
    console.print(f"results: {out}")


@bench_app.command("reach")
def bench_reach_cmd(
    out: Annotated[Path, typer.Option("--out", "-o", help="JSON results.")] = Path(
        "benchmarks/results/reach.json"
    ),
    feet: Annotated[
        list[str] | None, typer.Option("--foot", help="Front foot to lift, FL or FR (repeat).")
    ] = None,
    heights: Annotated[
        list[float] | None,
        typer.Option(
            "--height",
            help="Coarse sweep heights, m (repeat; default 0.05 ... 0.45).",
            callback=finite_in(0.0, 1.0),
        ),
    ] = None,
    tolerance: Annotated[
        float,
        typer.Option(
            help="Bisect the edge of the sweep down to this, m (as large as the sweep's step: "
            "no bisection).",
            callback=finite_in(1e-4, 1.0),
        ),
    ] = 0.005,
) -> None:
    """Highest front-foot height the Go1 holds standing on three legs, in our simulator."""
    from rich.console import Console

    from quaddance.fileio import write_json
    from quaddance.sim.reach import DEFAULT_HEIGHTS_M, LIFTABLE_FEET, reach_report

    chosen = tuple(feet or LIFTABLE_FEET)
    for foot in chosen:
        if foot not in LIFTABLE_FEET:
            raise typer.BadParameter(f"--foot must be FL or FR, got {foot!r}")
    console = Console(stderr=True)
    with console.status("Settling the robot on three legs...") as status:

        def show(foot: str, trial: dict) -> None:
            status.update(
                f"{foot}: {trial['target_m']:.3f} m -> held {trial['reached_m']:.3f} m "
                f"({trial['reason']})"
            )

        results = reach_report(
            chosen, tuple(heights or DEFAULT_HEIGHTS_M), tolerance, progress=show
        )
    write_json(out, results)
    for foot, r in results["feet"].items():
        print(
            f"{foot}: reach {r['reach_m']:.3f} m (held {r['held_m']:.3f} m; fails at "
            f"{r['first_failure_m'] or float('nan'):.3f} m); kinematic bound "
            f"{r['kinematic_bound_front_m']:.3f} m in front of the hip, "
            f"{r['kinematic_bound_m']:.3f} m anywhere; {r['n_trials']} trials, {r['wall_s']:.1f} s"
        )
    print(f"-> {out}")


#: Longest error line printed, characters (a message quoting a file must stay one short line).
MAX_ERROR_CHARS = 400
#: Exit status after Ctrl-C (SIGINT) or SIGTERM: 128 + the signal number, as a shell reports.
EXIT_SIGINT, EXIT_SIGTERM = 130, 143


def one_line_error(err: BaseException) -> str:
    """``quaddance: error: <message>`` on one line of at most `MAX_ERROR_CHARS`."""
    line = "quaddance: error: " + " ".join(str(err).split())
    return line if len(line) <= MAX_ERROR_CHARS else line[: MAX_ERROR_CHARS - 3] + "..."


def _stop_on_signals() -> dict[int, int]:
    """Turn SIGINT and SIGTERM into KeyboardInterrupt, so that every ``atomic_path`` removes
    its temporary file and no output is left half-written; returns {signal: exit status} of
    the first signal received (filled in by the handler). Later signals are ignored while
    the process cleans up, so a second Ctrl-C cannot cut the cleanup short."""
    import signal
    import threading

    received: dict[int, int] = {}

    def interrupt(signum: int, frame: object) -> None:
        if received:
            return
        received[signum] = EXIT_SIGTERM if signum == signal.SIGTERM else EXIT_SIGINT
        raise KeyboardInterrupt(f"signal {signum}")

    default_unraisable = sys.unraisablehook

    def unraisable(info: Any) -> None:
        # A signal that lands in a ctypes callback (numba's LLVM cache, while librosa loads)
        # raises there, where ctypes can only print a traceback and drop the exception. Send
        # the signal again, 50 ms later from another thread, once this hook has returned: the
        # handler then raises in a frame of the main thread that can take it.
        if isinstance(info.exc_value, KeyboardInterrupt) and received:
            signum = next(iter(received))
            received.clear()
            resend = threading.Timer(0.05, os.kill, args=(os.getpid(), signum))
            resend.daemon = True
            resend.start()
            return
        default_unraisable(info)

    sys.unraisablehook = unraisable
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, interrupt)
    return received


def main() -> None:
    """Console entry point: user errors become one line on stderr and exit status 2; Ctrl-C
    and SIGTERM one line and exit status 130 / 143 (outputs complete or absent)."""
    import signal

    # This process never renders (video frames are drawn in worker processes, which get
    # EGL: `play.video`). Without a MUJOCO_GL, MuJoCo's import loads GLFW, whose import runs
    # a Python subprocess; a Ctrl-C in the first second of a command then printed that
    # subprocess's traceback.
    os.environ.setdefault("MUJOCO_GL", "disable")
    received = _stop_on_signals()
    try:
        try:
            app()
        finally:
            # The work is over (done, failed or interrupted): a signal during the exit must
            # neither raise in the handlers below nor kill the process silently (at shutdown
            # Python restores the default action, which would end it with no message).
            for signum in (signal.SIGINT, signal.SIGTERM):
                signal.signal(signum, signal.SIG_IGN)
    except KeyboardInterrupt:
        _interrupted(received)
    except Exception as err:
        if received:  # the signal surfaced inside a library as another error (ctypes wraps
            _interrupted(received)  # it in an ArgumentError while converting an argument)
        if isinstance(err, QuaddanceError):
            print(one_line_error(err), file=sys.stderr)
            sys.exit(2)
        raise
    except SystemExit:
        # typer turns KeyboardInterrupt into a silent exit 130; say why we stopped.
        if received:
            _interrupted(received)
        raise


def _interrupted(received: dict[int, int]) -> None:
    # Training has written its checkpoint by now (train.py), so this is a clean stop.
    print("quaddance: interrupted", file=sys.stderr)
    sys.exit(next(iter(received.values()), EXIT_SIGINT))


if __name__ == "__main__":
    main()
