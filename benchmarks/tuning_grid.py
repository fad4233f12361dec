"""A grid of a beat tracker's settings, scored song by song on the tuning songs of the
real-music sets and of every set given with ``--also``, never on held-out ones: what
``benchmarks.analyser_mix`` (the offline analyser) and ``benchmarks.online_mix`` (the online
tracker) share."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from benchmarks.real_music import RealSong, script_command, set_script_parser
from quaddance.fileio import write_json

Row = dict[str, Any]


def beatnet_name(weight: float, stretches: tuple[float, ...]) -> str:
    """How the grids name BeatNet's share and the speeds the song is heard at:
    ``beatnet 0.75 x 0.9/1``."""
    return f"beatnet {weight:g} x " + "/".join(f"{s:g}" for s in stretches)


def run(
    sets: dict[str, Path],
    mix_names: list[str],
    score_song: Callable[[RealSong], dict[str, Row]],
    means: Callable[[list[Row]], dict[str, float]],
    load_songs: Callable[[Path, tuple[str, ...]], list[RealSong]],
) -> dict[str, Any]:
    """Each mix's scores per song (``score_song``: mix name -> row, for one song) and their
    ``means`` per set and over all songs; tuning songs only."""
    per_song: dict[str, dict[str, Row]] = {m: {} for m in mix_names}
    # Every set is read first, so that a set not built stops the run before any scoring.
    by_set = {label: load_songs(root, ("tuning",)) for label, root in sets.items()}
    members = {label: [f"{label}/{s.name}" for s in songs] for label, songs in by_set.items()}
    for label, songs in by_set.items():
        for song in songs:
            for mix, row in score_song(song).items():
                per_song[mix][f"{label}/{song.name}"] = row
            print(f"{label}/{song.name} done", flush=True)
    summary = {}
    for mix in mix_names:
        songs = per_song[mix]
        parts = {label: means([songs[n] for n in names]) for label, names in members.items()}
        summary[mix] = {**parts, "all": means(list(songs.values()))}
    return {"songs": members, "by_mix": summary, "per_song": per_song}


def main(
    argv: list[str] | None,
    *,
    module: str,
    doc: str,
    results: str,
    metric: str,
    roots: dict[str, Path],
    mix_names: Sequence[str],
    grid: Callable[[dict[str, Path], list[str]], dict[str, Any]],
) -> None:
    """Parse ``--also``, ``--mix`` and ``--out``, score the ``grid`` (the mixes named, in the
    order of ``mix_names``; all of them without ``--mix``) over the tuning songs of the two
    real-music sets (``roots``: `real_music.REAL_SET_ROOTS`) and of each ``--also`` set, write
    the JSON (atomically) and print each mix's F at the metrical level per set."""
    parser = set_script_parser(module, doc, results)
    parser.add_argument(
        "--mix",
        action="append",
        metavar="NAME",
        help="score only this mix, named as in the JSON's by_mix (repeatable; default: all)",
    )
    args = parser.parse_args(argv)
    unknown = [name for name in args.mix or () if name not in mix_names]
    if unknown:
        parser.error(f"no mix named {unknown[0]!r}; the mixes: " + ", ".join(mix_names))
    chosen = [name for name in mix_names if name in (args.mix or mix_names)]
    sets = {"tuning": roots["real"], "tuning-lmms": roots["real-lmms"]}
    sets.update({root.name: root for root in args.also})
    result = grid(sets, chosen)
    command = script_command(module, args.also, [f for n in args.mix or () for f in ("--mix", n)])
    write_json(
        args.out,
        {
            "benchmark": module.rsplit(".", 1)[-1],
            "command": command,
            "metric": metric,
            **result,
        },
    )
    for name, parts in result["by_mix"].items():
        print(name, {label: p["f_metrical"] for label, p in parts.items()})
    print(f"wrote {args.out}")
