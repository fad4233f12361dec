"""The beat trackers' goals on the held-out real music, pooled over the real-music sets.

Reads the results of ``quaddance bench beats --sets real`` and ``--sets real-lmms``, takes the
held-out songs of both, and reports each tracker's mean beat F (+-70 ms, strict and at its
metrical level), ours against madmom's song by song (the mean difference with a 95 % bootstrap
interval over the songs, and how many songs each side wins), and each goal of the tracker with
the figure that meets or misses it. Nothing is run again: it only reads the results files.

    python -m benchmarks.beats_goals [--results FILE ...] [--out FILE] [--report FILE]
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.real_music import DOWNBEAT_KEYS, REPORT_TRACKERS, run_as_script, song_means
from quaddance.layout import DANCE_TEMPO_BPM

MODULE = "benchmarks.beats_goals"
RESULTS = (
    Path("benchmarks/results/beats_real.json"),
    Path("benchmarks/results/beats_real_lmms.json"),
)
OUT = Path("benchmarks/results/beats_goals.json")
REPORT = Path("docs/results/beats_goals.md")

BOOTSTRAP_DRAWS = 10_000
"""Resamples of the songs behind each interval (seeded: the report is the same every run)."""
TIE_F = 0.01
"""Songs whose F differs by less than this count as neither side's win."""

#: Ours against madmom, song by song: (ours, madmom's).
PAIRS = (("offline", "madmom_dbn"), ("online", "madmom_online"))


@dataclass(frozen=True)
class Goal:
    name: str
    value: float
    target: str
    met: bool


def heldout_rows(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The held-out songs' rows of each results file, each tagged with its file's set."""
    return [
        {**row, "set": str(r.get("command", f"set {i + 1}")).rsplit(" ", 1)[-1]}
        for i, r in enumerate(results)
        for row in r["songs"]
        if row["split"] == "heldout"
    ]


def bootstrap_interval(diffs: np.ndarray, draws: int = BOOTSTRAP_DRAWS) -> tuple[float, float]:
    """95 % percentile interval of the mean of ``diffs`` over ``draws`` resamples of its
    entries (with replacement; seeded)."""
    rng = np.random.default_rng(0)
    means = rng.choice(diffs, size=(draws, len(diffs)), replace=True).mean(axis=1)
    low, high = np.percentile(means, [2.5, 97.5])
    return float(low), float(high)


def paired(rows: list[dict[str, Any]], ours: str, theirs: str, metric: str) -> dict[str, Any]:
    """Ours minus theirs on ``metric`` (``f`` or ``f_metrical``), song by song."""
    d = np.array([r[f"{metric}_{ours}"] - r[f"{metric}_{theirs}"] for r in rows])
    low, high = bootstrap_interval(d)
    return {
        "mean_diff": round(float(d.mean()), 4),
        "interval_95": [round(low, 4), round(high, 4)],
        "ours_higher": int((d >= TIE_F).sum()),
        "theirs_higher": int((d <= -TIE_F).sum()),
        "ties": int((np.abs(d) < TIE_F).sum()),
        # The mean difference if ours rose to theirs on every song where theirs is higher: how
        # far ours leads by taking the higher of the two on each song.
        "with_theirs_where_higher": round(float(np.maximum(d, 0.0).mean()), 4),
    }


def goals(rows: list[dict[str, Any]], pooled: dict[str, Any]) -> list[Goal]:
    """The tracker's goals on the held-out songs (``pooled``: their `song_means`), each with
    the figure that decides it."""
    n = len(rows)
    off, on = pooled["f_metrical_offline"], pooled["f_metrical_online"]
    mm_off, mm_on = pooled["f_metrical_madmom_dbn"], pooled["f_metrical_madmom_online"]
    locked = pooled["locked_within_6s"]
    # Each results file was made on its own machine: the CPU share is judged per set.
    cpu = {
        name: float(np.mean([r["online_cpu_per_audio_s"] for r in rows if r["set"] == name]))
        for name in sorted({r["set"] for r in rows})
    }
    cpu_text = ", ".join(f"{name} {share:.3f}" for name, share in cpu.items())
    out = [
        Goal("offline F at its metrical level", off, f">= madmom DBN + 0.03 = {mm_off + 0.03:.3f}",
             off >= mm_off + 0.03),
        Goal("online F at its metrical level, after the lock", on,
             f">= madmom online {mm_on:.3f} and >= 0.80", on >= mm_on and on >= 0.80),
        Goal("songs locked within 6 s", locked / n, f">= 90 % ({locked} of {n})",
             locked >= 0.9 * n),
        Goal("online tracker CPU, share of one core (mean per set, the larger)",
             max(cpu.values()), f"<= 0.10 ({cpu_text})", max(cpu.values()) <= 0.10),
    ]  # fmt: skip
    for key in ("offline", "online"):
        ok = pooled[f"tempo_ok_{key}"]
        out.append(Goal(f"{key} tempo within 4 % (or x2, x1/2)", ok / n, f"all ({ok} of {n})",
                        ok == n))  # fmt: skip
        low, high = DANCE_TEMPO_BPM
        inside = sum(low <= r[f"tempo_bpm_{key}"] <= high for r in rows)
        out.append(Goal(f"{key} tempo level inside {low:g}-{high:g} BPM", inside / n,
                        f"all ({inside} of {n})", inside == n))  # fmt: skip
        rising = sum(bool(r[f"{key}_beats_increasing"]) for r in rows)
        out.append(Goal(f"{key} beats strictly increasing", rising / n,
                        f"all ({rising} of {n})", rising == n))  # fmt: skip
    return out


def score(results: list[dict[str, Any]]) -> dict[str, Any]:
    rows = heldout_rows(results)
    if not rows:
        raise ValueError("the results hold no held-out song")
    pooled = song_means(rows)
    # Per tracker that every song has scores of: F strict, at its level, and downbeat F.
    means = {
        key: {m: pooled[k] for m, k in (("f", f"f_{key}"), ("f_metrical", f"f_metrical_{key}"),
                                        ("f_downbeat", DOWNBEAT_KEYS.get(key))) if k in pooled}
        for key, _ in REPORT_TRACKERS
        if f"f_{key}" in pooled
    }  # fmt: skip
    missing = [k for k in ("offline", "online", "madmom_dbn", "madmom_online") if k not in means]
    if missing:
        raise ValueError(f"the results lack {', '.join(missing)} (was madmom installed?)")
    return {
        "benchmark": "beats_goals",
        "sets": sorted({r["set"] for r in rows}),
        "n_songs": pooled["n_songs"],
        "minutes": pooled["minutes"],
        "means": means,
        "paired": {
            f"{ours} - {theirs}": {m: paired(rows, ours, theirs, m) for m in ("f_metrical", "f")}
            for ours, theirs in PAIRS
        },
        "goals": [g.__dict__ for g in goals(rows, pooled)],
        "songs": [r["name"] for r in rows],
    }


def report_md(scored: dict[str, Any], sources: list[str]) -> str:
    means, n = scored["means"], scored["n_songs"]
    lines = [
        "# Beat tracker goals on the held-out real music",
        "",
        f"Made by `python -m {MODULE}` from {', '.join(f'`{s}`' for s in sources)} (made by "
        f"`quaddance bench beats --sets {' / '.join(scored['sets'])}`): the held-out songs of "
        f"both sets, {n} songs, {scored['minutes']} min. Beat F-measure, +-70 ms; online "
        "figures count the beats after the tracker's first lock, madmom's online tracker "
        "scored over the same span. madmom's models are CC BY-NC-SA: compared against, never "
        "shipped.",
        "",
        "| tracker | F strict | F at its metrical level | downbeat F |",
        "|---|---|---|---|",
    ]
    for key, name in REPORT_TRACKERS:
        if key in means:
            m = means[key]
            down = f"{m['f_downbeat']:.3f}" if "f_downbeat" in m else "-"
            lines.append(f"| {name} | {m['f']:.3f} | {m['f_metrical']:.3f} | {down} |")
    lines += [
        "",
        "Ours minus madmom, song by song: the mean difference, its 95 % bootstrap interval over "
        f"the songs ({BOOTSTRAP_DRAWS} resamples), the songs each side wins by {TIE_F} or "
        "more, and the mean difference if ours had madmom's score on every song where madmom's "
        "is higher (the lead of the higher of the two on each song):",
        "",
        "| pair | metric | mean difference | 95 % interval | ours higher | madmom higher | ties "
        "| mean difference with madmom's score where it is higher |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for pair, by_metric in scored["paired"].items():
        for metric, p in by_metric.items():
            low, high = p["interval_95"]
            lines.append(
                f"| {pair} | {metric} | {p['mean_diff']:+.3f} | {low:+.3f} to {high:+.3f} | "
                f"{p['ours_higher']} | {p['theirs_higher']} | {p['ties']} | "
                f"{p['with_theirs_where_higher']:+.3f} |"
            )
    lines += ["", "| goal | figure | target | met |", "|---|---|---|---|"]
    for g in scored["goals"]:
        lines.append(
            f"| {g['name']} | {g['value']:.3f} | {g['target']} | {'yes' if g['met'] else 'no'} |"
        )
    lines += [
        "",
        "How soon a beat is reported (within 25 ms) is measured by `quaddance bench live` "
        "(`max_report_delay_ms` in `benchmarks/results/live_real*.json`). The CPU share is wall "
        "time inside the tracker per second of audio, on the machine each results file names.",
        "",
        "Songs: " + ", ".join(scored["songs"]) + ".",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    from quaddance.errors import QuaddanceError
    from quaddance.fileio import atomic_path, write_json

    parser = argparse.ArgumentParser(prog=f"python -m {MODULE}", description=__doc__.split("\n")[0])
    parser.add_argument(
        "--results", type=Path, nargs="+", default=list(RESULTS),
        help="bench beats results files (default: both real-music sets')",
    )  # fmt: skip
    parser.add_argument("--out", type=Path, default=OUT, help="where to write the JSON")
    parser.add_argument("--report", type=Path, default=REPORT, help="where to write markdown")
    args = parser.parse_args(argv)
    results = []
    for path in args.results:
        try:
            results.append(json.loads(path.read_text()))
        except (OSError, json.JSONDecodeError) as e:
            raise QuaddanceError(f"{path}: not a bench beats results file ({e})") from e
    try:
        scored = score(results)
    except KeyError as e:
        raise QuaddanceError(f"{', '.join(map(str, args.results))}: a song lacks {e}") from e
    except ValueError as e:
        raise QuaddanceError(f"{', '.join(map(str, args.results))}: {e}") from e
    scored["command"] = f"python -m {MODULE} --results " + " ".join(map(str, args.results))
    write_json(args.out, scored)
    with atomic_path(args.report) as tmp:
        tmp.write_text(report_md(scored, [str(p) for p in args.results]))
    for g in scored["goals"]:
        print(f"{'met ' if g['met'] else 'MISS'} {g['name']}: {g['value']:.3f} ({g['target']})")
    print(f"-> {args.out}, {args.report}")


if __name__ == "__main__":
    run_as_script(main)
