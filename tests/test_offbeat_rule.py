"""``python -m benchmarks.offbeat_rule``: the off-beat harmony test measured song by song, with
and without it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from tuning_sets import code_made_sets

import benchmarks.offbeat_rule as rule
from benchmarks.real_music import RealSong
from quaddance.music import analysis


@pytest.fixture
def made(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    sets = code_made_sets(tmp_path, 10.0)
    monkeypatch.setattr(rule, "load_audio_at", lambda song, sr: sets.audio[song.name])
    return sets


def test_a_song_the_test_leaves_alone_is_analysed_once(made, monkeypatch) -> None:
    calls: list[float] = []
    real = analysis.analyze

    def counted(y, sr, cfg=None):
        calls.append((cfg or analysis.AnalysisConfig()).offbeat_harmony_ratio)
        return real(y, sr, cfg)

    monkeypatch.setattr(analysis, "analyze", counted)
    song = made.sets[next(iter(made.sets))][0]
    row = rule.score_song(song)
    assert row["fired"] is False and row["with"] == row["without"]
    assert row["with"]["f_metrical"] > 0.9  # a code-made song at 100 BPM: on its beats
    assert calls == [analysis.AnalysisConfig().offbeat_harmony_ratio]


def test_where_the_test_fires_the_song_is_analysed_again_without_it(made, monkeypatch) -> None:
    real = analysis.analyze

    def shifted_unless_off(y, sr, cfg=None):
        a = real(y, sr, cfg)
        off = cfg is not None and math.isinf(cfg.offbeat_harmony_ratio)
        if not off:  # as if the test had moved the beats by half a beat
            half = 0.5 * np.median(np.diff(a.beats_s))
            a.beats_s, a.downbeats_s = a.beats_s + half, a.downbeats_s + half
        a.extra["offbeat_shift"] = not off
        return a

    monkeypatch.setattr(analysis, "analyze", shifted_unless_off)
    song = made.sets[next(iter(made.sets))][0]
    row = rule.score_song(song)
    assert row["fired"] is True
    assert row["with"]["f_metrical"] < 0.1 < 0.9 < row["without"]["f_metrical"]


def test_every_split_is_summarised_and_the_command_given_once(made, monkeypatch, tmp_path):
    def score(song: RealSong) -> dict:
        fired = song.split == "heldout"
        return {"fired": fired, "with": {"f_metrical": 1.0, "downbeat_f": 0.5},
                "without": {"f_metrical": 0.0 if fired else 1.0, "downbeat_f": 0.5}}  # fmt: skip

    monkeypatch.setattr(rule, "score_song", score)
    monkeypatch.setattr(rule, "load_songs", made.load_songs)
    a, b = made.sets
    monkeypatch.setattr(rule, "REAL_SET_ROOTS", {"real": a})
    out = tmp_path / "rule.json"
    rule.main(["--also", str(b), "--out", str(out)])
    result = json.loads(out.read_text())
    assert result["command"] == f"python -m benchmarks.offbeat_rule --also {b} --out {out}"
    held = result["summary"]["heldout"]
    assert held["n_songs"] == 2 and held["n_fired"] == 2
    assert held["f_metrical_with"] == 1.0 and held["f_metrical_without"] == 0.0
    tuning = result["summary"]["tuning"]
    assert tuning["n_fired"] == 0 and tuning["f_metrical_with"] == tuning["f_metrical_without"]
    assert all(k.startswith("heldout/") for k in result["fired"])
