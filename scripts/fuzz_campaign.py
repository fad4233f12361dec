"""Fuzz campaign for the motion readers, bigger than the test suite's; writes a JSON summary.

    .venv/bin/python scripts/fuzz_campaign.py --cases 20000 [--seed 1] [--cli 20]

Case kinds (shares of ``--cases``): mutated EDGE/AIST++/hostile pickles, crafted hostile
pickles with random parameters (nesting depth, dtype code and flags, array shapes, integer
sizes), mutated BVH text and bytes, random bytes; a fixed set of large inputs (20 MB lines,
millions of blank lines, 500-joint skeletons, 3 M-opcode pickles, oversized files); plus
whole Hypothesis runs (BVH and pickle
properties, new examples each run) and ``--cli`` cases through the real ``quaddance
choreograph --motion``. Every case runs in a child process under a 2 GiB address-space limit
and a timeout (`tests/fuzz_harness.py`). Outcomes per kind go to
``benchmarks/results/fuzz_motion.json``; any case that was not ok / refused is copied to
``benchmarks/results/fuzz_motion_findings/``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import motion_fuzz_cases as cases  # noqa: E402 - lives in tests/, shared with the suite
from fuzz_harness import (  # noqa: E402
    DEFAULT_MEMORY_BYTES,
    run_call,
    run_cli,
    run_reader_batch,
)

LOAD_MOTION = "quaddance.choreo.motion:load_motion"
OUT_JSON = ROOT / "benchmarks" / "results" / "fuzz_motion.json"
FINDINGS = ROOT / "benchmarks" / "results" / "fuzz_motion_findings"
# Shares of --cases per kind.
SHARES = {
    "pickle_mutation": 0.45,
    "pickle_crafted": 0.15,
    "bvh_text_mutation": 0.2,
    "bvh_byte_mutation": 0.1,
    "random_bytes": 0.1,
}
_DTYPE_CODES = ["O8", "O4", "c16", "c8", "U2", "S4", "V8", "M8", "m8", "f16", "f8", "i8", "b1", "?"]


def crafted(rng: np.random.Generator, sentinel: str) -> bytes:
    """A hostile pickle from one of the crafted families, with random parameters."""
    family = int(rng.integers(0, 4))
    if family == 0:
        kind = ["list", "tuple", "dict", "tuple_key", "frozenset", "memo_chain"][
            int(rng.integers(0, 6))
        ]
        depth = int(rng.choice([50, 63, 64, 65, 66, 100, 1000, 10_000, 100_000, 400_000]))
        return cases.deep_pickle(kind, depth if kind != "memo_chain" else min(depth, 100_000))
    if family == 1:
        code = _DTYPE_CODES[int(rng.integers(0, len(_DTYPE_CODES)))]
        pointers = tuple(int(v) for v in rng.integers(0, 2**63, size=int(rng.integers(1, 6))))
        return cases.object_array_pickle(code, int(rng.integers(0, 256)), pointers)
    if family == 2:
        shape = tuple(
            int(v) for v in rng.choice([0, 1, 3, 24, 72, 10**6, 2**31, -1], size=rng.integers(0, 4))
        )
        count = int(np.prod(shape)) if shape and min(shape) >= 0 else 1
        raw = bytes(8 * count) if 0 <= count <= 10_000 else bytes(int(rng.integers(0, 64)))
        key = b"\x80\x04}X\t\x00\x00\x00full_pose"
        return key + cases._array_state(shape, raw) + b"s."
    hostile = cases.hostile_pickles(sentinel)
    names = sorted(hostile)
    return hostile[names[int(rng.integers(0, len(names)))]]


def build_cases(n: int, seed: int, workdir: Path, sentinel: str) -> dict[str, list[Path]]:
    """Write ``n`` case files into ``workdir``; return their paths by kind."""
    rng = np.random.default_rng(seed)
    seeds = cases.valid_motion_pickles(rng)
    hostile = [raw for raw in cases.hostile_pickles(sentinel).values() if len(raw) < 10_000]
    corpus = seeds + hostile
    bvh_texts = cases.valid_bvh_texts(rng)
    bvh_bytes = [t.encode() for t in bvh_texts]
    paths: dict[str, list[Path]] = {kind: [] for kind in SHARES}
    paths["large_inputs"] = []
    for name, data in cases.large_cases(rng).items():
        paths["large_inputs"].append(workdir / f"large_{name}")
        paths["large_inputs"][-1].write_bytes(data)
    for suffix in (".pkl", ".bvh"):  # over the size limit, written sparse (no disk used)
        path = workdir / f"large_oversize{suffix}"
        with path.open("wb") as f:
            f.truncate(300 << 20)
        paths["large_inputs"].append(path)
    for kind, share in SHARES.items():
        for i in range(round(n * share)):
            if kind == "pickle_mutation":
                data, suffix = mutate_many(corpus[i % len(corpus)], rng, corpus), ".pkl"
            elif kind == "pickle_crafted":
                data, suffix = crafted(rng, sentinel), ".pkl"
            elif kind == "bvh_text_mutation":
                text = cases.mutate_text(bvh_texts[i % len(bvh_texts)], rng)
                data, suffix = text.encode("utf-8", "surrogatepass"), ".bvh"
            elif kind == "bvh_byte_mutation":
                data = cases.mutate_bytes(bvh_bytes[i % len(bvh_bytes)], rng, bvh_bytes)
                suffix = ".bvh"
            else:
                head = [b"", b"\x80\x02", b"\x80\x05", b"HIERARCHY\n"][i % 4]
                data = head + rng.bytes(int(rng.integers(0, 2000)))
                suffix = (".pkl", ".bvh", ".dat")[i % 3]
            path = workdir / f"{kind}_{i}{suffix}"
            path.write_bytes(data)
            paths[kind].append(path)
    return paths


def mutate_many(data: bytes, rng: np.random.Generator, corpus: list[bytes]) -> bytes:
    """1-3 rounds of `mutate_bytes`: deeper damage than one round."""
    for _ in range(int(rng.integers(1, 4))):
        data = cases.mutate_bytes(data, rng, corpus)
    return data


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=20_000, help="file cases in all")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--cli", type=int, default=20, help="cases also run through the CLI")
    parser.add_argument(
        "--hypothesis", type=int, default=2000, help="examples per Hypothesis property"
    )
    parser.add_argument("--out", type=Path, default=OUT_JSON)
    args = parser.parse_args()

    start = time.monotonic()
    summary: dict[str, object] = {
        "command": " ".join(["scripts/fuzz_campaign.py", *sys.argv[1:]]),
        "seed": args.seed,
        "memory_limit_bytes": DEFAULT_MEMORY_BYTES,
        "reader": LOAD_MOTION,
    }
    by_kind: dict[str, dict[str, int]] = {}
    findings: list[dict[str, str]] = []
    with tempfile.TemporaryDirectory(prefix="fuzz_motion_") as tmp:
        workdir = Path(tmp)
        sentinel = workdir / "SENTINEL"
        paths = build_cases(args.cases, args.seed, workdir, str(sentinel))
        for kind, kind_paths in paths.items():
            t0 = time.monotonic()
            outcomes = run_reader_batch(
                LOAD_MOTION, kind_paths, sentinel=sentinel, warnings_as_errors=True
            )
            by_kind[kind] = dict(Counter(o.kind for o in outcomes))
            print(f"{kind}: {by_kind[kind]} ({time.monotonic() - t0:.0f} s)", flush=True)
            for outcome in outcomes:
                if not outcome.clean:
                    FINDINGS.mkdir(parents=True, exist_ok=True)
                    saved = FINDINGS / kind_paths[outcome.index].name
                    shutil.copyfile(kind_paths[outcome.index], saved)
                    findings.append(
                        {
                            "kind": kind,
                            "outcome": outcome.kind,
                            "file": str(saved.relative_to(ROOT)),
                            "detail": outcome.detail[:500],
                        }
                    )
        rng = np.random.default_rng(args.seed + 1)
        all_paths = [p for kind_paths in paths.values() for p in kind_paths]
        cli_counts: Counter[str] = Counter()
        for index in rng.choice(len(all_paths), size=min(args.cli, len(all_paths)), replace=False):
            path = all_paths[int(index)]
            outcome, _ = run_cli(
                ["choreograph", "--motion", path, "-o", workdir / "dance.npz"], file=path
            )
            cli_counts[outcome.kind] += 1
            if not outcome.clean:
                findings.append(
                    {
                        "kind": "cli",
                        "outcome": outcome.kind,
                        "file": path.name,
                        "detail": outcome.detail[:500],
                    }
                )
        by_kind["cli_choreograph"] = dict(cli_counts)
        print(f"cli_choreograph: {dict(cli_counts)}", flush=True)
        for prop in ("hypothesis_bvh", "hypothesis_pickles"):
            t0 = time.monotonic()
            outcome = run_call(
                f"test_fuzz_motion:{prop}", str(workdir), args.hypothesis, False, timeout_s=3600
            )
            by_kind[f"{prop} ({args.hypothesis} examples, one run)"] = {outcome.kind: 1}
            print(f"{prop}: {outcome.kind} ({time.monotonic() - t0:.0f} s)", flush=True)
            if not outcome.clean:
                findings.append(
                    {
                        "kind": prop,
                        "outcome": outcome.kind,
                        "file": "",
                        "detail": outcome.detail[:1500],
                    }
                )
        summary["sentinel_created"] = sentinel.exists()
    summary["file_cases"] = sum(len(p) for p in paths.values())
    summary["by_kind"] = by_kind
    totals: Counter[str] = Counter()
    for kind, counts in by_kind.items():
        if not kind.startswith("hypothesis"):
            totals.update(counts)
    summary["totals"] = dict(totals)
    summary["findings"] = findings
    summary["wall_s"] = round(time.monotonic() - start, 1)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(summary, indent=2) + "\n")
    print(f"-> {args.out} ({len(findings)} findings, {summary['wall_s']} s)")


if __name__ == "__main__":
    main()
