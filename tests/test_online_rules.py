"""``python -m benchmarks.online_rules``: each special rule of the online tracker switched off
in turn and scored song by song."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from tuning_sets import code_made_sets

import benchmarks.online_rules as rules
from quaddance.music import online_beats
from quaddance.music.online_beats import SR_HZ


def test_each_rule_is_switched_off_only_inside_its_block() -> None:
    shipped = {c: getattr(online_beats, c) for off in rules.RULES_OFF.values() for c in off}
    for name, off in rules.RULES_OFF.items():
        with rules.rule_off(name):
            for constant, value in off.items():
                assert getattr(online_beats, constant) == value != shipped[constant]
            # the other rules' constants are as shipped
            others = {c for n, o in rules.RULES_OFF.items() if n != name for c in o} - set(off)
            assert all(getattr(online_beats, c) == shipped[c] for c in others)
        assert {c: getattr(online_beats, c) for c in shipped} == shipped
    with pytest.raises(RuntimeError), rules.rule_off("backbeat test"):
        raise RuntimeError  # restored on an error too
    restored = online_beats.MAX_DOUBLED_BPM
    assert restored == shipped["MAX_DOUBLED_BPM"]


def test_switching_a_rule_off_changes_what_the_tracker_does() -> None:
    """A song that changes tempo at 14 s: the new tempo is reported within 3 s as shipped (the
    fast re-estimate from the last 3 s), later with that rule off."""
    from quaddance.music.live import track_samples
    from quaddance.music.synth import render_song

    change_s, new_bpm = 14.0, 132.0
    y, _ = render_song(100.0, 30.0, seed=3, sr=SR_HZ, tempo_change=(change_s, new_bpm))

    def switch_s() -> float:
        track = track_samples(y, SR_HZ)
        at = (track.block_end_s > change_s) & (np.abs(track.tempo_bpm / new_bpm - 1.0) < 0.04)
        return float(track.block_end_s[at][0]) - change_s

    with rules.rule_off(rules.SHIPPED):
        shipped = switch_s()
    with rules.rule_off("fast tempo re-estimate"):
        off = switch_s()
    assert shipped <= 3.0 < off


def test_every_split_is_summarised_per_rule(tmp_path: Path, monkeypatch) -> None:
    made = code_made_sets(tmp_path, 10.0)
    a, b = made.sets

    def score(song, y):
        # As if the backbeat test were worth 0.5 on held-out songs and nothing else mattered.
        down = song.split == "heldout" and online_beats.MAX_DOUBLED_BPM == 0.0
        return {"f_metrical": 0.4 if down else 0.9, "lock_s": 3.0}

    monkeypatch.setattr(rules, "score", score)
    monkeypatch.setattr(rules, "decode", lambda song: made.audio[song.name])
    monkeypatch.setattr(rules, "load_songs", made.load_songs)
    monkeypatch.setattr(rules, "REAL_SET_ROOTS", {"real": a})
    out = tmp_path / "rules.json"
    rules.main(["--also", str(b), "--rule", "backbeat test", "--rule", "swing test",
                "--out", str(out)])  # fmt: skip
    result = json.loads(out.read_text())
    assert result["command"] == (
        f"python -m benchmarks.online_rules --also {b} --rule 'backbeat test' "
        f"--rule 'swing test' --out {out}"
    )
    held = result["summary"]["heldout"]
    assert held["n_songs"] == 2
    assert held["as shipped"]["f_metrical"] == 0.9 and held["swing test"]["f_metrical"] == 0.9
    assert held["backbeat test"] == {"f_metrical": 0.4, "locked_within_6s": 2,
                                     "songs_up": 0, "songs_down": 2}  # fmt: skip
    assert result["summary"]["tuning"]["backbeat test"]["songs_down"] == 0
    assert set(result["rules_off"]) == {"backbeat test", "swing test"}


def test_jobs_track_the_songs_in_processes_with_the_same_results(tmp_path, monkeypatch) -> None:
    made = code_made_sets(tmp_path, 10.0)
    a, _ = made.sets

    def score(song, y):
        # Depends on the song and on which rule is off in the process that scores it.
        return {"f_metrical": float(len(y) % 7) + online_beats.FAST_MISSES % 5, "lock_s": 1.0}

    monkeypatch.setattr(rules, "score", score)
    monkeypatch.setattr(rules, "decode", lambda song: made.audio[song.name][: 100 + len(song.name)])
    monkeypatch.setattr(rules, "load_songs", made.load_songs)
    one = rules.run({"real": a}, ["fast tempo re-estimate"], jobs=1)
    two = rules.run({"real": a}, ["fast tempo re-estimate"], jobs=2)
    assert one == two and len(one["songs"]) == 2
    for row in two["songs"].values():  # the rule was off in the worker for its own way only
        shipped, off = row["as shipped"]["f_metrical"], row["fast tempo re-estimate"]["f_metrical"]
        assert shipped - off == online_beats.FAST_MISSES % 5
