"""Fuzz campaign (issue 12) for the audio decoder, dance.npz, the policy JSON, the output paths,
Ctrl-C / SIGTERM and the command-line options; a JSON summary of outcomes per kind.

    .venv/bin/python scripts/fuzz_inputs_campaign.py [--scale 1.0] [-o OUT.json]

Readers run in child processes under a memory limit and a timeout (tests/fuzz_harness.py) and
each outcome is one of ok / refused / bad_message / traceback / crash / killed / hang. The
promise: only ok and refused. Output-path cases run the real command against FIFOs, sockets,
folders, links to /dev/null (never a real device) and must be refused with the node untouched.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests")]

import numpy as np  # noqa: E402
from fuzz_harness import REFUSED, run_cli, run_reader_batch, summarize  # noqa: E402
from input_fuzz_cases import (  # noqa: E402
    HOSTILE_INTS,
    WAV_FIELDS,
    _song,
    audio_seeds,
    mutate_audio,
    mutate_dance,
    mutate_policy,
    shipped_policy,
    wav_with_header,
)


def _write(folder: Path, cases: list[tuple[str, bytes | str]]) -> list[Path]:
    paths = []
    for i, (suffix, content) in enumerate(cases):
        paths.append(folder / f"c{i}{suffix}")
        if isinstance(content, str):
            paths[-1].write_text(content, encoding="utf-8", errors="surrogatepass")
        else:
            paths[-1].write_bytes(content)
    return paths


def _readers(folder: Path, n: int, log) -> dict:
    rng = np.random.default_rng(12)
    seeds = audio_seeds(rng)
    sweep = [
        (".wav", wav_with_header(_song(2.5, 8000, 1, rng), "PCM_16", {name: value}, size))
        for name in WAV_FIELDS
        for value in HOSTILE_INTS
        for size in (None, 0, 2**32 - 1)
    ]
    base = shipped_policy()
    groups = {
        "audio_header_sweep": ("input_fuzz_cases:load_audio_checked", sweep),
        "audio_mutated": (
            "input_fuzz_cases:load_audio_checked",
            [mutate_audio(seeds, rng) for _ in range(n)],
        ),
        "dance_npz_mutated": (
            "input_fuzz_cases:load_dance_checked",
            [(".npz", mutate_dance(rng)) for _ in range(n)],
        ),
        "policy_json_mutated": (
            "input_fuzz_cases:load_policy_json",
            [(".json", mutate_policy(base, rng)) for _ in range(n)],
        ),
    }
    results = {}
    for name, (reader, cases) in groups.items():
        sub = folder / name
        sub.mkdir()
        start = time.perf_counter()
        outcomes = run_reader_batch(reader, _write(sub, cases))
        bad = [o for o in outcomes if not o.clean]
        results[name] = {
            "cases": len(cases),
            "outcomes": summarize(outcomes),
            "wall_s": round(time.perf_counter() - start, 1),
            "findings": [f"{o.kind}: {o.detail[:300]}" for o in bad[:10]],
        }
        log(f"{name}: {results[name]['outcomes']}")
    return results


def _node(path: Path, kind: str) -> object:
    """Make a non-regular node at ``path``; returns what keeps it alive (a socket)."""
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "folder":
        path.mkdir()
    elif kind == "link_to_dev_null":
        path.symlink_to("/dev/null")
    elif kind == "broken_link":
        path.symlink_to(path.parent / "absent" / "x")
    elif kind == "socket":
        sock = socket.socket(socket.AF_UNIX)
        sock.bind(str(path))
        return sock
    elif kind == "file":
        path.write_text("keep me")
    return None


def _fingerprint(path: Path) -> tuple:
    st = path.lstat()
    return (stat.S_IFMT(st.st_mode), st.st_ino, st.st_size if stat.S_ISREG(st.st_mode) else 0)


def _outputs(folder: Path, song: Path, log) -> dict:
    """Every command against every kind of non-regular output node."""
    file_outputs = {
        "analyze": lambda out: ["analyze", song, "-o", out],
        "choreograph": lambda out: ["choreograph", song, "-o", out],
        "demo-song": lambda out: ["demo-song", out],
    }
    kinds = ("fifo", "folder", "link_to_dev_null", "broken_link", "socket")
    cases = []
    for cmd, args in file_outputs.items():
        suffix = ".wav" if cmd == "demo-song" else ".npz" if cmd == "choreograph" else ".json"
        for kind in kinds:
            cases.append((f"{cmd} -o <{kind}>", kind, f"out{suffix}", args))
        cases.append((f"{cmd} -o <file>/x", "file", f"out{suffix}/x{suffix}", args))
    for kind in ("file", "fifo", "link_to_dev_null"):
        cases.append(
            (
                f"dance --out <{kind}>",
                kind,
                "out",
                lambda out: ["dance", song, "--no-video", "--out", out],
            )
        )
    for inner in ("dance.npz", "metrics.json", "feet.png"):
        cases.append(
            (
                f"dance --out DIR with {inner} a FIFO",
                "fifo",
                f"dir/{inner}",
                lambda out: ["dance", song, "--no-video", "--out", Path(out).parent],
            )
        )
    kinds_count: Counter = Counter()
    findings = []
    for i, (label, kind, rel, args) in enumerate(cases):
        work = folder / f"o{i}"
        work.mkdir()
        target = work / rel
        node_path = target if kind != "file" or "/" not in rel else work / rel.split("/")[0]
        node_path.parent.mkdir(parents=True, exist_ok=True)
        keep = _node(node_path, kind)
        before = _fingerprint(node_path)
        try:
            outcome, _ = run_cli(args(str(target)), file=node_path.name, timeout_s=300)
        finally:
            if keep is not None:
                keep.close()
        untouched = _fingerprint(node_path) == before
        leftovers = [p.name for p in work.rglob("*") if ".tmp" in p.name]
        kind_seen = outcome.kind if untouched and not leftovers else "wrote_over_node"
        kinds_count[kind_seen] += 1
        if kind_seen != REFUSED:
            findings.append(f"{label}: {kind_seen}: {outcome.detail[:200]}")
        log(f"{label}: {kind_seen}")
    return {"cases": len(cases), "outcomes": dict(kinds_count), "findings": findings}


def _signals(folder: Path, song: Path, n: int, log) -> dict:
    """choreograph and dance --no-video interrupted at random moments by SIGINT / SIGTERM."""
    rng = random.Random(7)
    counts: Counter = Counter()
    findings = []
    for i in range(n):
        sig = rng.choice([signal.SIGINT, signal.SIGTERM])
        command = rng.choice(["choreograph", "dance"])
        out = folder / f"s{i}"
        out.mkdir()
        if command == "choreograph":
            args = ["choreograph", str(song), "-o", str(out / "dance.npz")]
        else:
            args = ["dance", str(song), "--no-video", "--out", str(out / "o")]
        delay_s = rng.uniform(0.5, 12.0)
        proc = subprocess.Popen(
            [sys.executable, "-m", "quaddance.cli", *args],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        time.sleep(delay_s)
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=300)
        expected = 143 if sig == signal.SIGTERM else 130
        lines = [x for x in stderr.splitlines() if "interrupted" in x or "rror" in x]
        tmp_left = [p.name for p in out.rglob("*") if ".tmp" in p.name]
        npz = next(out.rglob("dance.npz"), None)
        complete = True
        if npz is not None:
            from quaddance.dancefile import load_dance
            from quaddance.errors import InputFileError

            try:
                load_dance(npz)
            except InputFileError:
                complete = False
        if proc.returncode == 0:
            kind = "finished_before_signal"
        elif proc.returncode == expected and lines == ["quaddance: interrupted"]:
            kind = "interrupted_cleanly"
        else:
            kind = "bad_exit"
        if "Traceback" in stderr or tmp_left or not complete:
            kind = "partial_or_traceback"
        counts[kind] += 1
        if kind in ("bad_exit", "partial_or_traceback"):
            findings.append(
                f"{args[0]} sig {sig} at {delay_s:.1f} s: {proc.returncode} {stderr[-200:]}"
            )
        log(f"{command} {signal.Signals(sig).name} at {delay_s:.1f} s: {kind}")
    return {"cases": n, "outcomes": dict(counts), "findings": findings}


# Values out of range for every option below (a value that is valid for one of them would run
# that command: training, a benchmark).
_VALUES = ["nan", "inf", "-inf", "1e400", "-1", "-1e-320", "99999999999999999999", "abc", ""]
_OPTIONS = [
    (["choreograph", "s.wav"], ["--seed", "--h0", "--scale", "--max-height"]),
    (["dance", "s.wav"], ["--seed"]),
    (["eval", "s.wav"], ["--seed"]),
    (
        ["train"],
        [
            "--num-envs",
            "--iterations",
            "--seed",
            "--bank-size",
            "--max-height",
            "--checkpoint-every",
            "--minutes",
        ],
    ),
    (["bench", "choreograph"], ["--repeats"]),
    (["bench", "train"], ["--num-envs", "--iterations"]),
    (["bench", "reach"], ["--height", "--tolerance"]),
    (["bench", "beats"], ["--random"]),
]


def _arguments(log) -> dict:
    """Every numeric option with hostile values: a usage error (exit 2), never a traceback
    (in-process: parsing fails before any command body runs)."""
    from typer.testing import CliRunner

    from quaddance.cli import app

    counts: Counter = Counter()
    findings = []
    os.chdir(tempfile.mkdtemp())  # should a case run a command after all, its files land here
    for prefix, options in _OPTIONS:
        for option in options:
            for value in _VALUES:
                result = CliRunner().invoke(app, [*prefix, option, value])
                clean = result.exit_code == 2 and (
                    result.exception is None or isinstance(result.exception, SystemExit)
                )
                kind = "usage_error" if clean else f"exit_{result.exit_code}"
                counts[kind] += 1
                if not clean:
                    findings.append(
                        f"{' '.join(prefix)} {option} {value!r}: {result.output[-200:]}"
                    )
    log(f"arguments: {dict(counts)}")
    return {"cases": sum(counts.values()), "outcomes": dict(counts), "findings": findings}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scale", type=float, default=1.0, help="cases x this (1: 2000/reader)")
    parser.add_argument(
        "-o", "--out", type=Path, default=ROOT / "benchmarks/results/fuzz_inputs.json"
    )
    args = parser.parse_args()
    n = int(2000 * args.scale)
    log = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    start = time.perf_counter()
    results: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        from quaddance.music.synth import write_demo_song

        song = folder / "song.wav"
        write_demo_song(song)
        results["readers"] = _readers(folder, n, log)
        (folder / "outputs").mkdir()
        results["output_paths"] = _outputs(folder / "outputs", song, log)
        results["signals"] = _signals(folder, song, max(4, int(12 * args.scale)), log)
        results["arguments"] = _arguments(log)
    results["total_cases"] = sum(
        g["cases"]
        for g in [
            *results["readers"].values(),
            results["output_paths"],
            results["signals"],
            results["arguments"],
        ]
    )
    results["wall_s"] = round(time.perf_counter() - start, 1)
    from quaddance.fileio import write_json

    write_json(args.out, results)
    print(json.dumps({k: v for k, v in results.items() if k != "readers"}, indent=1)[:3000])
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()
