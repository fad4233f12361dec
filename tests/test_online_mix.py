"""``python -m benchmarks.online_mix``: the grid of the online tracker's uses of BeatNet, scored
on tuning songs only."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from tuning_sets import code_made_sets

import benchmarks.online_mix as om
from benchmarks.real_music import RealSong
from quaddance.music import online_beats

UNREADABLE = RealSong("x", "x", "A", "tuning", "recording", Path("x.wav"), np.zeros(0),
                      np.zeros(0), (120.0, 120.0), "4/4", "MIT", 1.0)  # fmt: skip
"""A tuning song whose file the tests' stand-in tracker refuses to read."""


@pytest.fixture
def two_sets(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, tuple]]:
    """Two song sets of code-made songs in place of the real-music sets, each with a held-out
    song that must never be read; returns what the tracker read: (song, its mix)."""
    made = code_made_sets(tmp_path, 12.0, write_wav=True)
    read: list[tuple[str, tuple]] = []
    track_file = om.live.track_file

    def tracked(path: Path):  # what the tracker reads, and with which mix
        assert "heldout" not in Path(path).name, f"read held-out song {path}"
        mix = (online_beats.BEATNET_WEIGHT, online_beats.BEATNET_STRETCHES)
        read.append((Path(path).stem, mix))
        return track_file(path)

    monkeypatch.setattr(om, "REAL_SET_ROOTS", made.roots)
    monkeypatch.setattr(om, "load_songs", made.load_songs)
    monkeypatch.setattr(om.live, "track_file", tracked)
    monkeypatch.setattr(om, "MIXES", (om.Mix(0.5), om.Mix(0.75, (0.9, 1.0))))
    return read


def test_the_grid_scores_each_mix_on_the_tuning_songs_only(two_sets, tmp_path: Path) -> None:
    out = tmp_path / "mix.json"
    om.main(["--out", str(out)])
    result = json.loads(out.read_text())
    assert result["songs"] == {
        "tuning": ["tuning/a_tuning"],
        "tuning-lmms": ["tuning-lmms/b_tuning"],
    }
    # Each song was tracked once per mix, the tracker reading that mix; then the defaults.
    assert two_sets == [
        ("a_tuning", (0.5, (1.0,))), ("a_tuning", (0.75, (0.9, 1.0))),
        ("b_tuning", (0.5, (1.0,))), ("b_tuning", (0.75, (0.9, 1.0))),
    ]  # fmt: skip
    assert (online_beats.BEATNET_WEIGHT, online_beats.BEATNET_STRETCHES) == (0.5, (1.0,))
    names = ["beatnet 0.5 x 1", "beatnet 0.75 x 0.9/1"]
    assert list(result["by_mix"]) == names
    for name in names:
        songs = result["per_song"][name]
        # A code-made song's beats are found at either mix, soon after its start.
        assert all(s["f_metrical"] > 0.8 and s["lock_s"] < 6.0 for s in songs.values())
        mean = np.mean([s["f_metrical"] for s in songs.values()])
        assert result["by_mix"][name]["all"]["f_metrical"] == pytest.approx(mean, abs=1e-4)
        assert result["by_mix"][name]["all"]["lock_within_6_s"] == 1.0
        assert result["by_mix"][name]["tuning"]["f"] == songs["tuning/a_tuning"]["f"]


def test_a_mix_is_restored_when_its_song_fails(monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(path: Path):
        assert online_beats.BEATNET_STRETCHES == om.FIVE
        raise RuntimeError("unreadable")

    monkeypatch.setattr(om.live, "track_file", broken)
    with pytest.raises(RuntimeError, match="unreadable"):
        om.score(UNREADABLE, om.Mix(0.75, om.FIVE))
    assert (online_beats.BEATNET_WEIGHT, online_beats.BEATNET_STRETCHES) == (0.5, (1.0,))


def test_mix_scores_only_the_mixes_named(two_sets, tmp_path: Path) -> None:
    out = tmp_path / "mix.json"
    om.main(["--mix", "beatnet 0.75 x 0.9/1", "--out", str(out)])
    result = json.loads(out.read_text())
    assert two_sets == [("a_tuning", (0.75, (0.9, 1.0))), ("b_tuning", (0.75, (0.9, 1.0)))]
    assert list(result["by_mix"]) == list(result["per_song"]) == ["beatnet 0.75 x 0.9/1"]
    assert result["command"] == "python -m benchmarks.online_mix --mix 'beatnet 0.75 x 0.9/1'"


def test_an_unknown_mix_is_one_line_naming_the_mixes(
    two_sets, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as stop:
        om.main(["--mix", "beatnet 0.6 x 1", "--out", str(tmp_path / "mix.json")])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "no mix named 'beatnet 0.6 x 1'" in err
    assert "beatnet 0.5 x 1, beatnet 0.75 x 0.9/1" in err
    assert two_sets == []
    assert not (tmp_path / "mix.json").exists()


def test_a_mix_sets_the_held_grid_s_following_its_jump_and_beatnet_s_vote(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    seen: list[tuple[float, float, float]] = []

    def broken(path: Path):
        ob = online_beats
        seen.append((ob.HOLD_FOLLOW, ob.OFFBEAT_VOTE_RATIO, ob.PHASE_JUMP_BEATS))
        raise RuntimeError("unreadable")

    monkeypatch.setattr(om.live, "track_file", broken)
    mixes = (
        om.Mix(0.5, hold_follow=0.5),
        om.Mix(0.5, hold_follow=0.0),
        om.Mix(0.5, offbeat_vote=2.0),
        om.Mix(0.5, offbeat_vote=3.0),
        om.Mix(0.5, phase_jump=0.25),
    )
    for mix in mixes:
        with pytest.raises(RuntimeError, match="unreadable"):
            om.score(UNREADABLE, mix)
    assert seen == [
        (0.5, np.inf, 0.15), (0.0, np.inf, 0.15), (1.0, 2.0, 0.15), (1.0, 3.0, 0.15),
        (1.0, np.inf, 0.25),
    ]  # fmt: skip
    assert online_beats.HOLD_FOLLOW == 1.0
    assert np.isinf(online_beats.OFFBEAT_VOTE_RATIO)
    assert online_beats.PHASE_JUMP_BEATS == 0.15
    # The grid names a mix by what differs from the tracker's defaults.
    assert om.Mix(0.5).name == "beatnet 0.5 x 1"
    assert [m.name for m in mixes] == [
        "beatnet 0.5 x 1, follow 0.5",
        "beatnet 0.5 x 1, follow 0",
        "beatnet 0.5 x 1, vote 2",
        "beatnet 0.5 x 1, vote 3",
        "beatnet 0.5 x 1, jump 0.25",
    ]
    assert {m.name for m in mixes} <= {m.name for m in om.MIXES}
