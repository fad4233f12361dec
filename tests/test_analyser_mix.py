"""``python -m benchmarks.analyser_mix``: the grid of the analyser's activation mixes, scored on
tuning songs only."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from tuning_sets import code_made_sets

import benchmarks.analyser_mix as am
from benchmarks.real_music import RealSong


@pytest.fixture
def two_sets(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, np.ndarray]:
    """Two song sets of code-made songs in place of the real-music sets; a held-out song in
    each that must never be read."""
    made = code_made_sets(tmp_path, 10.0)

    def load_audio_at(song: RealSong, sr: int) -> np.ndarray:
        assert song.split == "tuning", f"read held-out song {song.name}"
        return made.audio[song.name]

    monkeypatch.setattr(am, "REAL_SET_ROOTS", made.roots)
    monkeypatch.setattr(am, "load_songs", made.load_songs)
    monkeypatch.setattr(am, "load_audio_at", load_audio_at)
    monkeypatch.setattr(am, "MIXES", (am.Mix(0.5, 0.5), am.Mix(0.25, 0.75, (0.9, 1.0))))
    return made.audio


def test_the_grid_scores_each_mix_on_the_tuning_songs_only(two_sets, tmp_path: Path) -> None:
    out = tmp_path / "mix.json"
    am.main(["--out", str(out)])
    result = json.loads(out.read_text())
    assert result["songs"] == {
        "tuning": ["tuning/a_tuning"],
        "tuning-lmms": ["tuning-lmms/b_tuning"],
    }
    names = ["own 0.5, beatnet 0.5 x 1", "own 0.25, beatnet 0.75 x 0.9/1"]
    assert list(result["by_mix"]) == names
    for name in names:
        songs = result["per_song"][name]
        # A code-made song's beats are found at either mix; "all" is the mean over the songs.
        assert all(s["f_metrical"] > 0.8 for s in songs.values())
        mean = np.mean([s["f_metrical"] for s in songs.values()])
        assert result["by_mix"][name]["all"]["f_metrical"] == pytest.approx(mean, abs=1e-4)
        assert result["by_mix"][name]["tuning"] == songs["tuning/a_tuning"]


def test_mix_scores_only_the_mixes_named(two_sets, tmp_path: Path) -> None:
    out = tmp_path / "mix.json"
    name = "own 0.5, beatnet 0.5 x 1"
    am.main(["--mix", name, "--out", str(out)])
    result = json.loads(out.read_text())
    assert list(result["by_mix"]) == list(result["per_song"]) == [name]
    assert set(result["per_song"][name]) == {"tuning/a_tuning", "tuning-lmms/b_tuning"}


def test_a_mix_is_the_analysers_config() -> None:
    cfg = am.Mix(0.25, 0.75, am.FIVE).config()
    assert (cfg.activation_weight, cfg.beatnet_weight, cfg.beatnet_stretches) == (
        0.25,
        0.75,
        am.FIVE,
    )


def test_a_set_not_built_stops_the_grid_before_any_song_is_scored(
    two_sets, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from benchmarks import real_music

    read: list[str] = []
    listed = am.load_songs

    def load_songs(root: Path, splits: tuple[str, ...]) -> list[RealSong]:
        if root.name == "missing":
            return real_music.load_songs(root, splits)  # the benchmark's own check
        return listed(root, splits)

    monkeypatch.setattr(am, "load_songs", load_songs)
    monkeypatch.setattr(am, "load_audio_at", lambda song, sr: read.append(song.name))
    with pytest.raises(real_music.SetFileMissingError, match="missing"):
        am.main(["--also", str(tmp_path / "missing"), "--out", str(tmp_path / "mix.json")])
    assert read == []
    assert not (tmp_path / "mix.json").exists()


def test_a_mix_at_another_level_hears_the_song_that_much_quieter(monkeypatch) -> None:
    heard: list[float] = []

    def analyze(y: np.ndarray, sr: int, cfg: object) -> object:
        heard.append(float(np.max(np.abs(y))))
        raise RuntimeError("heard")

    monkeypatch.setattr(am.analysis, "analyze", analyze)
    y = np.array([0.0, 0.8, -0.4], dtype=np.float32)
    for mix in (am.Mix(0.25, 0.75), am.Mix(0.25, 0.75, gain_db=-6.0)):
        with pytest.raises(RuntimeError, match="heard"):
            am.score(None, y, mix)  # type: ignore[arg-type]
    assert heard == pytest.approx([0.8, 0.8 * 10 ** (-6 / 20)], rel=1e-6)
    assert am.Mix(0.25, 0.75, am.FIVE, gain_db=-6.0).name.endswith(", at -6 dB")
