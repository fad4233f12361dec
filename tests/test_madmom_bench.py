"""The beat benchmarks' madmom runner, with a stand-in madmom package (madmom itself lives in
its own environment, which CI does not build): the processors each tracker asks for, the
downbeats it keeps, the errors, and ``bench live --sets real``'s songs."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from benchmarks.beats import MADMOM_TRACKERS, madmom_beats_s, madmom_tracks
from benchmarks.live import LIVE_SETS, REAL_SETS, real_songs
from quaddance.errors import QuaddanceError

# The stand-in answers with times that say which processors, in which mode, made them.
_BEATS = """
import numpy as np
class RNNBeatProcessor:
    def __init__(self, online=False):
        self.online = online
    def __call__(self, path):
        return np.full(10, 0.5 if self.online else 0.25)
class DBNBeatTrackingProcessor:
    def __init__(self, fps, online=False):
        assert fps == 100
        self.online = online
    def __call__(self, act):
        return np.array([act[0], 1.0 + act[0]]) + (10.0 if self.online else 0.0)
"""
_DOWNBEATS = """
import numpy as np
class RNNDownBeatProcessor:
    def __call__(self, path):
        return np.zeros((10, 2))
class DBNDownBeatTrackingProcessor:
    def __init__(self, beats_per_bar, fps):
        assert list(beats_per_bar) == [3, 4] and fps == 100
    def __call__(self, act):
        return np.array([[0.5, 1], [1.0, 2], [1.5, 3], [2.0, 1], [2.5, 2]])
"""


@pytest.fixture
def fake_madmom(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    pkg = tmp_path / "site" / "madmom"
    (pkg / "features").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "features" / "__init__.py").write_text("")
    (pkg / "features" / "beats.py").write_text(_BEATS)
    (pkg / "features" / "downbeats.py").write_text(_DOWNBEATS)
    monkeypatch.setenv("PYTHONPATH", str(tmp_path / "site"))
    wav = tmp_path / "song.wav"
    wav.write_bytes(b"")
    return wav


def test_each_tracker_runs_its_processors_in_its_mode(fake_madmom: Path) -> None:
    tracks = madmom_tracks(sys.executable, [fake_madmom], MADMOM_TRACKERS)
    row = tracks[str(fake_madmom)]
    np.testing.assert_allclose(row["dbn"], [0.25, 1.25])  # offline RNN, offline DBN
    np.testing.assert_allclose(row["online"], [10.5, 11.5])  # forward RNN, online DBN
    np.testing.assert_allclose(row["downbeats"], [0.5, 2.0])  # the beats numbered 1
    only_dbn = madmom_beats_s(sys.executable, [fake_madmom])
    np.testing.assert_allclose(only_dbn[str(fake_madmom)], [0.25, 1.25])


def test_unknown_tracker_and_broken_interpreter_are_one_line_errors(
    fake_madmom: Path, tmp_path: Path
) -> None:
    with pytest.raises(QuaddanceError, match="unknown madmom tracker"):
        madmom_tracks(sys.executable, [fake_madmom], ("dbn", "crf"))
    with pytest.raises(QuaddanceError, match="cannot run madmom's interpreter"):
        madmom_tracks(tmp_path / "no-python", [fake_madmom])
    broken = tmp_path / "python"
    broken.write_text("#!/bin/sh\necho 'No module named madmom' >&2\nexit 1\n")
    broken.chmod(0o755)
    with pytest.raises(QuaddanceError, match="No module named madmom"):
        madmom_tracks(broken, [fake_madmom])


def test_bench_beats_real_with_a_missing_interpreter_stops_at_once(tmp_path: Path) -> None:
    from benchmarks.cli import app

    result = CliRunner().invoke(
        app,
        ["beats", "--sets", "real", "--out", str(tmp_path / "b.json"),
         "--madmom-python", str(tmp_path / "no-python")],
    )  # fmt: skip
    assert result.exit_code != 0
    assert "cannot run madmom's interpreter" in str(result.exception)
    assert not (tmp_path / "b_real.json").exists()


def test_real_sets_are_the_real_music_splits(monkeypatch: pytest.MonkeyPatch) -> None:
    import benchmarks.real_music as real_music
    from benchmarks.real_music import load_songs

    assert set(REAL_SETS) <= set(LIVE_SETS)
    assert {split for _, split in REAL_SETS.values()} == set(real_music.SPLITS)
    assert {real_set for real_set, _ in REAL_SETS.values()} == set(real_music.BENCH_SET_ROOTS)
    assert set(real_music.BENCH_SET_ROOTS.values()) == {
        real_music.ROOT, real_music.LMMS_ROOT, real_music.FOF_ROOT
    }  # fmt: skip
    # Fitting and tuning grids read only the sets with a held-out part: real-fof's licence.
    assert set(real_music.REAL_SET_ROOTS.values()) == {real_music.ROOT, real_music.LMMS_ROOT}
    # The audio is not decoded here: only which songs each set holds, and their beats.
    monkeypatch.setattr(real_music, "load_audio_at", lambda song, sr: np.zeros(sr))
    songs = real_songs(("real", "random"), 11025)
    heldout = load_songs(splits=("heldout",))
    assert [s.name for s in songs] == [s.name for s in heldout]
    assert {s.set for s in songs} == {"real"}
    np.testing.assert_array_equal(songs[0].beats_s, heldout[0].beats_s)
    np.testing.assert_array_equal(songs[0].downbeats_s, heldout[0].downbeats_s)
    assert [s.name for s in real_songs(("real-tuning",), 11025)] == [
        s.name for s in load_songs(splits=("tuning",))
    ]


def test_live_bench_real_lmms_sets_read_the_lmms_part(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    import benchmarks.real_music as real_music
    from quaddance.errors import QuaddanceError

    asked: list[tuple[Path, tuple[str, ...]]] = []

    def songs_of(root: Path, splits: tuple[str, ...]) -> list:
        real_music.load_manifest(root)  # as load_songs does first
        asked.append((root, splits))
        return []

    monkeypatch.setattr(real_music, "load_songs", songs_of)
    monkeypatch.setitem(real_music.BENCH_SET_ROOTS, "real", tmp_path / "real_music")
    monkeypatch.setitem(real_music.BENCH_SET_ROOTS, "real-lmms", tmp_path / "real_music_lmms")
    # Not built: one error that says what is missing, not a traceback.
    with pytest.raises(QuaddanceError, match="no real-music manifest"):
        real_songs(("real-lmms",), 11025)
    for folder in ("real_music", "real_music_lmms"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "manifest.json").write_text("{}")
    assert real_songs(("real-lmms-tuning", "real"), 11025) == []
    assert asked == [
        (tmp_path / "real_music_lmms", ("tuning",)),
        (tmp_path / "real_music", ("heldout",)),
    ]


def test_bench_beats_real_picks_madmom_by_its_options(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import benchmarks.beats as beats
    import benchmarks.real_music as real_music
    from benchmarks.cli import app

    asked: list[str | None] = []

    def fake_bench(out, root=real_music.ROOT, madmom_python=None, progress=None):
        assert root == real_music.ROOT
        asked.append(madmom_python)
        return {"songs": [], "means": {}, "command": "c", "set": "s", "metric": "m"}

    monkeypatch.setattr(real_music, "run_real_bench", fake_bench)
    installed = tmp_path / "venv"
    (installed / "bin").mkdir(parents=True)
    (installed / "bin" / "python").write_text("")
    out = ["--out", str(tmp_path / "b.json")]
    monkeypatch.setattr(beats, "MADMOM_VENV", tmp_path / "not-built")
    runs = (
        [],  # not installed: left out
        ["--madmom-python", "/opt/mm/python"],
        ["--madmom-python", "/opt/mm/python", "--no-madmom"],
    )
    for extra in runs:
        result = CliRunner().invoke(app, ["beats", "--sets", "real", *out, *extra])
        assert result.exit_code == 0, result.output
    monkeypatch.setattr(beats, "MADMOM_VENV", installed)
    for extra in ([], ["--no-madmom"]):
        result = CliRunner().invoke(app, ["beats", "--sets", "real", *out, *extra])
        assert result.exit_code == 0, result.output
    assert asked == [None, "/opt/mm/python", None, str(installed / "bin" / "python"), None]
    report = tmp_path / "beats_real.md"
    result = CliRunner().invoke(app, ["beats", "--sets", "real", *out, "--report", str(report)])
    assert result.exit_code == 0, result.output
    assert report.read_text().startswith("# Beats on real music")


def test_bench_beats_real_lmms_scores_the_lmms_set_once_built(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import benchmarks.real_music as real_music
    from benchmarks.cli import app
    from quaddance.errors import QuaddanceError

    scored: list[tuple[Path, Path]] = []

    def fake_bench(out, root=real_music.ROOT, madmom_python=None, progress=None):
        real_music.load_manifest(root)  # as run_real_bench's load_songs does first
        scored.append((Path(out), Path(root)))
        return {"songs": [], "means": {}, "command": "c", "set": "s", "metric": "m"}

    monkeypatch.setattr(real_music, "run_real_bench", fake_bench)
    lmms = tmp_path / "real_music_lmms"
    lmms.mkdir()
    monkeypatch.setattr(real_music, "LMMS_ROOT", lmms)
    monkeypatch.setitem(real_music.BENCH_SET_ROOTS, "real-lmms", lmms)
    args = ["beats", "--sets", "real-lmms", "--out", str(tmp_path / "b.json"), "--no-madmom"]
    # Not built: one error that says how to build it.
    result = CliRunner().invoke(app, args)
    assert isinstance(result.exception, QuaddanceError)
    assert "apt-get install lmms" in str(result.exception)
    assert "build --root" in str(result.exception) and not scored
    (lmms / real_music.MANIFEST_NAME).write_text("{}")
    both = [*args[:2], "real,real-lmms", *args[3:], "--report", str(tmp_path / "r.md")]
    result = CliRunner().invoke(app, both)
    assert result.exit_code == 0, result.output
    assert scored == [
        (tmp_path / "b_real.json", real_music.ROOT),
        (tmp_path / "b_real_lmms.json", lmms),
    ]
    # Each set its own report.
    assert (tmp_path / "r.md").is_file() and (tmp_path / "r_lmms.md").is_file()
    # A third set's report is named after it, beside the others.
    fof = tmp_path / "real_music_fof"
    fof.mkdir()
    (fof / real_music.MANIFEST_NAME).write_text("{}")
    monkeypatch.setitem(real_music.BENCH_SET_ROOTS, "real-fof", fof)
    three = [*args[:2], "real,real-fof", *args[3:], "--report", str(tmp_path / "r3.md")]
    result = CliRunner().invoke(app, three)
    assert result.exit_code == 0, result.output
    assert scored[-1] == (tmp_path / "b_real_fof.json", fof)
    assert (tmp_path / "r3.md").is_file() and (tmp_path / "r3_fof.md").is_file()
    # Without the first set, the first one chosen takes the name given; none overwrites another.
    two = [*args[:2], "real-lmms,real-fof", *args[3:], "--report", str(tmp_path / "r2.md")]
    result = CliRunner().invoke(app, two)
    assert result.exit_code == 0, result.output
    assert (tmp_path / "r2.md").is_file() and (tmp_path / "r2_fof.md").is_file()


def test_the_real_music_report_gives_each_tracker_per_part(tmp_path: Path) -> None:
    from benchmarks.real_music import report_md

    mean = {
        "n_songs": 2, "minutes": 5.0, "f_offline": 0.71, "f_metrical_offline": 0.81,
        "f_downbeat_offline": 0.4, "tempo_ok_offline": 2, "f_madmom_dbn": 0.77,
        "f_metrical_madmom_dbn": 0.83, "f_downbeat_madmom": 0.55, "tempo_ok_madmom_dbn": 1,
        "n_locked": 2, "locked_within_6s": 1, "lock_s_median": 5.5,
    }  # fmt: skip
    song = {"name": "a", "split": "heldout", "kind": "recording", "true_tempo_bpm": 120.0,
            "f_offline": 0.7, "f_metrical_offline": 0.8, "lock_s": 4.2}  # fmt: skip
    results = {
        "command": "quaddance bench beats --sets real", "set": "S", "metric": "M",
        "machine": {"cpu": "x86_64", "cpu_count": 2}, "madmom_python": "/mm/python",
        "means": {"heldout": mean, "tuning": {**mean, "n_songs": 1}}, "songs": [song],
    }  # fmt: skip
    text = report_md(results)
    assert text.index("## heldout") < text.index("## tuning")  # held-out first
    assert "| quaddance offline (`analyze`) | 0.71 | 0.81 | 0.40 | 2 of 2 |" in text
    assert "| madmom offline (RNN + DBN) | 0.77 | 0.83 | 0.55 | 1 of 2 |" in text
    assert "librosa" not in text.split("## Songs")[0]  # not run: no row
    assert "BeatNet" not in text.split("## Songs")[0]
    assert "| a | heldout | recording | 120 | 0.70 / 0.80 | - | - | - | - | - | 4.2 |" in text
    assert "x86_64, 2 CPU cores" in text and "CC BY-NC-SA" in text


def _part_mean(n: int) -> dict:
    """A report part of ``n`` songs with no tracker scores."""
    return {"n_songs": n, "minutes": 1.0, "n_locked": 0, "locked_within_6s": 0,
            "lock_s_median": None}  # fmt: skip


def test_the_real_music_report_shows_a_kind_only_where_a_part_has_several() -> None:
    from benchmarks.real_music import report_md

    results = {
        "command": "c", "set": "S", "metric": "M", "sources": "benchmarks/x/sources.toml",
        "means": {"heldout": _part_mean(3), "heldout_recording": _part_mean(1),
                  "heldout_lmms_render": _part_mean(2), "heldout_midi_render": _part_mean(0),
                  "tuning": _part_mean(2), "tuning_lmms_render": _part_mean(2)},
        "songs": [],
    }  # fmt: skip
    text = report_md(results)
    headings = [line for line in text.splitlines() if line.startswith("## ")]
    assert headings == [
        "## heldout (3 songs, 1.0 min)",
        "## heldout, recording (1 songs, 1.0 min)",
        "## heldout, LMMS renders (2 songs, 1.0 min)",
        "## tuning (2 songs, 1.0 min)",
        "## Songs",
    ]
    assert "(`benchmarks/x/sources.toml`)" in text


def test_the_real_music_report_of_a_set_with_no_held_out_part_says_so() -> None:
    from benchmarks.real_music import report_md

    results = {
        "command": "c", "set": "S", "metric": "M", "sources": "benchmarks/y/sources.toml",
        "means": {"heldout": _part_mean(0), "heldout_recording": _part_mean(0),
                  "tuning": _part_mean(3), "tuning_recording": _part_mean(3)},
        "songs": [],
    }  # fmt: skip
    text = report_md(results)
    headings = [line for line in text.splitlines() if line.startswith("## ")]
    assert headings == ["## tuning (3 songs, 1.0 min)", "## Songs"]
    assert "none is held out" in text and "The held-out part was fixed" not in text
