"""The ``bench`` commands; each writes a JSON file of results.

``quaddance bench NAME`` runs them from a source checkout (`quaddance.cli.bench` loads this
app); each body runs its benchmark from this package and prints a summary.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from quaddance.cli.options import PolicyOpt, PolicyRobotOpt, RobotModelOpt, finite_in

app = typer.Typer(no_args_is_help=True, help="Benchmarks; each writes a JSON file of results.")

MadmomPython = Annotated[
    Path | None,
    typer.Option(
        help="A Python interpreter that can import madmom: also score madmom's trackers (bench "
        "live: its online tracker on the real-music sets). madmom is not a dependency; the "
        "default is the environment scripts/install_madmom.sh builds (.madmom/venv), when "
        "it is there."
    ),
]
NoMadmom = Annotated[
    bool, typer.Option("--no-madmom", help="Leave madmom out even where it is installed.")
]


@app.command("live")
def bench_live_cmd(
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Where to write the JSON results.")
    ] = Path("benchmarks/results/live.json"),
    sets: Annotated[
        str,
        typer.Option(
            help="Sets, comma-separated: random, untuned, live, heldout (tuning too); real, "
            "real-tuning (benchmarks/real_music's parts), real-lmms, real-lmms-tuning (its "
            "LMMS part, once built), real-fof-tuning (Frets on Fire's own songs, once built); "
            "the whole loop runs on the live-case sets among them "
            "(live, heldout) and, with tuning, on 8 tuning songs."
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
    madmom_python: MadmomPython = None,
    no_madmom: NoMadmom = False,
) -> None:
    """Online beat tracking vs the offline analyser (lock time, F-measure) on songs with exact
    beats not tuned on, heard from their start and joined mid-song (also: after a quiet room,
    with noise, and whether noise alone locks it); then the whole live loop on the simulated
    robot: falls, loop time, latency, the robot's motion accents on the true beats. Writes
    JSON."""
    import tempfile

    from rich.console import Console

    from benchmarks.live import bench_live_dance, bench_live_tracker, machine_info
    from quaddance.fileio import write_json

    console = Console(stderr=True)
    chosen = tuple(s.strip() for s in sets.split(",") if s.strip())
    madmom_python = _madmom_python(madmom_python, no_madmom, console)
    with console.status("Tracking beats online...") as status:
        results = {
            "tracker": bench_live_tracker(
                chosen,
                n_random=random,
                progress=lambda n: status.update(f"Tracking {n}..."),
                shifts=shifts,
                madmom_python=madmom_python,
            )
        }
    for name, m in results["tracker"]["means"].items():
        console.print(
            f"{name}: {m['n_locked']}/{m['n_songs']} locked, median lock {m['lock_s_median']} s,"
            f" F online {m['f_online']:.3f} vs offline {m['f_offline']:.3f}; joined mid-song:"
            f" median lock {m['join_lock_s_median']} s, F online {m['join_f_online']:.3f} vs"
            f" offline {m['join_f_offline']:.3f}"
            + (
                f"; madmom online {m['f_madmom_online']:.3f} (same span as ours)"
                if "f_madmom_online" in m
                else ""
            )
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


def _madmom_python(given: Path | None, no_madmom: bool, console: Any) -> Path | None:
    """The madmom interpreter a bench uses: ``given``, else the installed one, else None."""
    from benchmarks.beats import default_madmom_python

    if no_madmom:
        return None
    python = given if given is not None else default_madmom_python()
    if python is None:
        console.print("madmom left out: run scripts/install_madmom.sh to compare with it")
    return python


@app.command("beats")
def bench_beats_cmd(
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Where to write the JSON results.")
    ] = Path("benchmarks/results/beats.json"),
    random: Annotated[
        int, typer.Option(help="Songs in the random MIDI set (not tuned on).", min=0, max=1000)
    ] = 12,
    sets: Annotated[
        str,
        typer.Option(
            help="Comma-separated sets to score: tuning, random, untuned (MIDI songs written "
            "here), real (music made by people elsewhere, benchmarks/real_music: its results "
            "go to OUT with _real added to the name), real-lmms (LMMS's demo songs, "
            "benchmarks/real_music_lmms, once built: results to OUT with _real_lmms added), "
            "real-fof (Frets on Fire's own songs, benchmarks/real_music_fof, once built: "
            "results to OUT with _real_fof added)."
        ),
    ] = "tuning,random,untuned",
    madmom_python: MadmomPython = None,
    no_madmom: NoMadmom = False,
    report: Annotated[
        Path | None,
        typer.Option(
            help="With a real-music set: also write its markdown report here (several: the "
            "first of real, real-lmms, real-fof here, each other's beside it as NAME_lmms.md, "
            "NAME_fof.md)."
        ),
    ] = None,
) -> None:
    """Beat F-measure of our analyser, librosa's default (and madmom's) on songs with exact beats.

    Reports the strict F (+-70 ms) and the F at each tracker's own metrical level (same,
    double or half tempo), per set: "tuning" (tuned on), "random" and "untuned" (never tuned
    on). Needs fluidsynth and a General MIDI soundfont (apt-get install fluidsynth
    fluid-soundfont-gm); renderings are cached under benchmarks/cache/. "real" scores the
    real-music set (benchmarks/real_music: band recordings and MIDI songs made elsewhere,
    tuning and held-out parts) offline, online (after the lock), with librosa and with
    BeatNet's published networks (CC BY 4.0) decoded by a bar-pointer HMM. "real-lmms" scores
    the same way the demo songs of LMMS, rendered by LMMS (build them first: apt-get install
    lmms gcc; python -m benchmarks.real_music build --root benchmarks/real_music_lmms), and
    "real-fof" Frets on Fire's own band recordings, all tuning (python -m
    benchmarks.real_music build --root benchmarks/real_music_fof; their licence keeps them off
    the repository).
    """
    from rich.console import Console
    from rich.table import Table

    from benchmarks.beats import run_beat_bench

    console = Console(stderr=True)
    madmom_python = _madmom_python(madmom_python, no_madmom, console)
    chosen = tuple(s.strip() for s in sets.split(",") if s.strip())
    from benchmarks.real_music import BENCH_SET_ROOTS

    real_sets = [name for name in BENCH_SET_ROOTS if name in chosen]
    for k, name in enumerate(real_sets):
        suffix = "_" + name.replace("-", "_")  # beats_real.json, beats_real_lmms.json
        real_out = out.with_name(f"{out.stem}{suffix}{out.suffix}")
        # One report per set: the first set's at REPORT, each other's beside it (r_lmms.md).
        to = (
            report
            if report is None or k == 0
            else report.with_name(f"{report.stem}{suffix.removeprefix('_real')}{report.suffix}")
        )
        _bench_real_beats(real_out, BENCH_SET_ROOTS[name], madmom_python, console, to)
    chosen = tuple(s for s in chosen if s not in BENCH_SET_ROOTS)
    if not chosen:
        return
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


def _bench_real_beats(
    real_out: Path, root: Path, madmom_python: Path | None, console: Any, report: Path | None
) -> None:
    """``bench beats --sets real`` (or ``real-lmms``): the real-music set under ``root``,
    offline, online, librosa and BeatNet (and madmom); the markdown report to ``report``."""
    from rich.console import Console
    from rich.table import Table

    from benchmarks.real_music import report_md, run_real_bench
    from quaddance.fileio import atomic_path

    with console.status("Scoring beats on real music...") as status:
        results = run_real_bench(
            real_out,
            root,
            madmom_python=None if madmom_python is None else str(madmom_python),
            progress=lambda name: status.update(f"Scoring {name}..."),
        )
    trackers = ["offline", "online", "librosa", "beatnet"]
    if madmom_python is not None:
        trackers += ["madmom_dbn", "madmom_online"]
    table = Table(title="real music, beat F (+-70 ms): strict / at the tracker's metrical level")
    for col in ("song", "split", "kind", "BPM", *trackers, "lock s"):
        table.add_column(col)
    for row in results["songs"]:
        cells = [f"{row[f'f_{t}']:.3f} / {row[f'f_metrical_{t}']:.3f}" for t in trackers]
        bpm = row["true_tempo_bpm"]
        bpm_text = f"{bpm:g}" if isinstance(bpm, float) else f"{bpm[0]:g}-{bpm[1]:g}"
        table.add_row(row["name"], row["split"], row["kind"], bpm_text, *cells, str(row["lock_s"]))
    for part, mean in results["means"].items():
        cells = [
            f"{mean[f'f_{t}']:.3f} / {mean[f'f_metrical_{t}']:.3f}" if f"f_{t}" in mean else "-"
            for t in trackers
        ]
        table.add_row(f"mean ({mean['n_songs']} songs)", part, "", "", *cells, "")
    Console().print(table)
    print(f"-> {real_out}")
    if report is not None:
        with atomic_path(report) as tmp:
            tmp.write_text(report_md(results))
        print(f"-> {report}")


@app.command("choreograph")
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

    from benchmarks.choreograph import run_choreograph_bench

    with Console(stderr=True).status("Timing the choreographer and the targets..."):
        results = run_choreograph_bench(out, repeats=repeats)
    print(
        f"choreograph {results['duration_s']:.0f} s of music: "
        f"{results['choreograph_s_median']:.4f} s; "
        f"feasible targets: {results['targets_feasible_s_median']:.4f} s; "
        f"bank: {results['bank_s_per_sequence']:.4f} s per {results['bank_sequence_s']:.0f} s "
        f"sequence -> {out}"
    )


@app.command("train")
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
    from benchmarks.train import run_train_bench

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


@app.command("dance")
def bench_dance_cmd(
    out: Annotated[Path, typer.Option("--out", "-o", help="JSON results.")] = Path(
        "benchmarks/results/dance.json"
    ),
    repeats: Annotated[int, typer.Option(help="Timed runs per song (median and min).")] = 3,
    warmup: Annotated[bool, typer.Option(help="One untimed run first.")] = True,
    policy: Annotated[Path | None, typer.Option(help="Policy .onnx; default: shipped.")] = None,
    no_video: Annotated[
        bool,
        typer.Option("--no-video", help="Time `dance --no-video`: the simulation's speed."),
    ] = False,
) -> None:
    """Time the whole `dance` command on a 12 s and a 30 s song; writes JSON.

    Each run is a fresh process timed from outside; ratio = wall / song length (goal <= 1
    with video). CPU time of the process tree, the load average and metrics.json's
    `realtime_factor_sim` are recorded beside the wall time.
    """
    from rich.console import Console

    from benchmarks.dance import run_dance_bench

    console = Console(stderr=True)
    results = run_dance_bench(
        out,
        repeats=repeats,
        warmup=warmup,
        policy=policy,
        progress=console.log,
        video=not no_video,
    )
    for song in results["songs"]:
        print(
            f"{song['song_s']:g} s song: wall median {song['wall_median_s']:.1f} s "
            f"({song['ratio_median']:.2f}x), min {song['wall_min_s']:.1f} s "
            f"({song['ratio_min']:.2f}x); CPU {song['cpu_median_s']:.1f} s; "
            f"load {song['load_1min_median']:.1f}; "
            f"sim {song['realtime_factor_sim_median']:.1f}x real time"
        )
    print(f"-> {out}")


@app.command("envelope")
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
    robot: PolicyRobotOpt = None,
    work: Annotated[Path, typer.Option(help="Folder for the default items.")] = Path(
        "runs/heldout"
    ),
) -> None:
    """Robustness envelope: falls and tracking at each end of the training randomisation
    ranges (friction 0.1/3, mass -1/+3 kg, strength 0.9/1.1, lag 30 ms, and the four hard
    ends at once), and pushes of increasing strength: the first push velocity that makes the
    robot fall (nominal robot and hard corner)."""
    from rich.console import Console

    from benchmarks.envelope import default_items, run_envelope, write_envelope
    from quaddance.play.evaluate import collect_items
    from quaddance.play.policy import choose_policy

    console = Console(stderr=True)
    _, policy_path = choose_policy(robot, policy)
    todo = collect_items(items) if items else default_items(work)
    result = run_envelope(todo, policy_path, log=console.print)
    command = "quaddance bench envelope" + (f" --robot {robot}" if robot else "")
    command += f" --policy {policy}" if policy else ""
    write_envelope(result, out, report, command)
    for name, p in result["pushes"].items():
        first = p["first_fall_vel_m_s"]
        print(f"{name}: first fall at push {'none' if first is None else f'{first:.2f} m/s'}")
    print(f"-> {out}, {report}")


@app.command("ff-ablation")
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
    from benchmarks.ablation import run_ablation

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


@app.command("long")
def bench_long_cmd(
    out: Annotated[Path, typer.Option("--out", "-o", help="JSON results.")] = Path(
        "benchmarks/results/long_song.json"
    ),
    repeats: Annotated[int, typer.Option(min=1, help="Runs of the 20-minute song.")] = 3,
) -> None:
    """A 20-minute song through `dance --no-video`, `--repeats` times (median time, CPU, peak
    memory), and a 2-hour file that must be refused early (about 4 minutes in all)."""
    from rich.console import Console

    from benchmarks.long import TARGET_PEAK_MB, TARGET_WALL_S, run_long_bench

    with Console(stderr=True).status("long inputs...") as status:
        results = run_long_bench(out, log=status.update, repeats=repeats)
    dance = results["dance_20min_no_video"]
    for k, r in enumerate(dance["runs"], 1):
        print(
            f"20-min dance, run {k}: exit {r['exit_code']}, {r['wall_s']:.1f} s wall, "
            f"{r['cpu_s']:.1f} s CPU, peak {r['peak_rss_mb']:.0f} MB "
            f"(load {r['load_avg_1min_before']:.1f})"
        )
    if "wall_median_s" in dance:
        print(
            f"20-min dance: median {dance['wall_median_s']:.1f} s (goal {TARGET_WALL_S:g}), "
            f"peak {dance['peak_rss_max_mb']:.0f} MB (goal {TARGET_PEAK_MB:g}): "
            f"{'met' if dance['met'] else 'NOT met'}"
        )
    r = results["analyze_2h_silent"]
    print(
        f"2-hour file: exit {r['exit_code']}, {r['wall_s']:.1f} s wall, "
        f"peak {r['peak_rss_mb']:.0f} MB"
    )
    print(f"-> {out}")


@app.command("deploy")
def bench_deploy_cmd(
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="JSON results [default: benchmarks/results/deploy.json, deploy_BACKEND.json "
            "for another backend].",
        ),
    ] = None,
    seconds: Annotated[
        float, typer.Option(help="Dance length, s.", callback=finite_in(1.0, 30.0))
    ] = 20.0,
    robot: Annotated[
        str,
        typer.Option(
            "--robot", help="Backend: sim, go1-sim or go2-sim (the shipped policy of its robot)."
        ),
    ] = "sim",
) -> None:
    """Sim-to-sim: songs by `dance` and by `deploy --robot BACKEND`; fault deadlines."""
    from rich.console import Console

    from benchmarks.deploy import run
    from quaddance.deploy.job import SIMULATED
    from quaddance.errors import QuaddanceError
    from quaddance.fileio import check_output_file, write_json

    if robot not in SIMULATED:
        raise QuaddanceError(f"--robot must be one of {', '.join(SIMULATED)}, got {robot!r}")
    name = "deploy.json" if robot == "sim" else f"deploy_{robot}.json"
    out = out or Path("benchmarks/results") / name
    check_output_file(out)
    console = Console(stderr=True)
    results = run(seconds, log=lambda msg: console.log(msg), backend=robot)
    write_json(out, results)
    for name, r in results["songs"].items():
        d, s = r["dance"], r["deploy_sim"]
        print(
            f"{name}: front MAE dance {100 * d['front_mae_mean_m']:.2f} cm, deploy sim "
            f"{100 * (s['front_mae_mean_m'] or float('nan')):.2f} cm; falls {d['falls']} / "
            f"{s['falls']}; tick ms {s['tick_ms']}"
            + ("" if s["final_state"] == "done" else f"; ENDED IN {s['final_state']}: {s['why']}")
        )
    print(
        "time to damp: "
        + ", ".join(f"{k} {v['time_to_damp_s']}" for k, v in results["faults"].items())
        + f" -> {out}"
    )


def _robot_results(robot: str, name: str) -> Path:
    """Where a robot's benchmark file goes: the Go1's in benchmarks/results, another robot's
    in a folder of its own (benchmarks/results/go2/...)."""
    from quaddance.robots import GO1, get_robot

    cfg = get_robot(robot)
    folder = Path("benchmarks/results")
    return folder / name if cfg.name == GO1.name else folder / cfg.short_name / name


@app.command("body-reach")
def bench_body_reach_cmd(
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="JSON results (default: benchmarks/results/body_reach.json, a Go2's under "
            "benchmarks/results/go2/).",
        ),
    ] = None,
    policy: Annotated[
        Path | None,
        typer.Option(help="A whole-body policy .onnx to balance; default: feed-forward alone."),
    ] = None,
    robot: RobotModelOpt = "go1",
) -> None:
    """The trunk poses (height, roll, pitch, yaw) a robot holds with four feet down and with
    a front paw up: a sweep per column and sign, the range held without a fall, a foot
    lifting or sliding, or the trunk missing the pose by more than 35 %. Writes JSON. With
    --policy the robot is the policy's."""
    from rich.console import Console

    from benchmarks.body_reach import bench_body_reach
    from benchmarks.live import machine_info
    from quaddance.fileio import write_json
    from quaddance.play.policy import OnnxPolicy
    from quaddance.robots import get_robot

    console = Console(stderr=True)
    loaded = None if policy is None else OnnxPolicy.load(policy)
    with console.status("Sweeping trunk poses..."):
        results = bench_body_reach(loaded, get_robot(robot))
    out = out or _robot_results(results["robot"], "body_reach.json")
    results["machine"] = machine_info()
    for which in ("four_feet", "paw_up"):
        ranges = ", ".join(f"{k} {lo:+g}..{hi:+g}" for k, (lo, hi) in results[which].items())
        console.print(f"{which}: {ranges}")
    write_json(out, results)
    console.print(f"results: {out}")


@app.command("reach")
def bench_reach_cmd(
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="JSON results (default: benchmarks/results/reach.json, a Go2's under "
            "benchmarks/results/go2/).",
        ),
    ] = None,
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
    robot: RobotModelOpt = "go1",
) -> None:
    """Highest front-foot height a robot holds standing on three legs, in our simulator."""
    from rich.console import Console

    from benchmarks.reach import DEFAULT_HEIGHTS_M, LIFTABLE_FEET, reach_report
    from quaddance.fileio import write_json
    from quaddance.robots import get_robot

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
            chosen,
            tuple(heights or DEFAULT_HEIGHTS_M),
            tolerance,
            progress=show,
            robot=get_robot(robot),
        )
    out = out or _robot_results(results["robot"], "reach.json")
    write_json(out, results)
    for foot, r in results["feet"].items():
        failed = r["first_failure_m"]
        fails = "no height tried failed" if failed is None else f"fails at {failed:.3f} m"
        print(
            f"{foot}: reach {r['reach_m']:.3f} m (held {r['held_m']:.3f} m; {fails}); "
            f"kinematic bound {r['kinematic_bound_front_m']:.3f} m in front of the hip, "
            f"{r['kinematic_bound_m']:.3f} m anywhere; {r['n_trials']} trials, {r['wall_s']:.1f} s"
        )
    print(f"-> {out}")
