"""``--beats FILE``: each format reads to its beats, each bad file is one line naming it and
the problem (exit 2), and a dance made with it lifts its paws on the file's beats, not on
the tracker's."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_robot_choice import _one_line_error, _quaddance

from quaddance.choreo.accents import accent_offsets_s, motion_accents_s
from quaddance.choreo.grid import synthetic_grid
from quaddance.dancefile import load_dance
from quaddance.music.beat_file import BeatList, read_beats
from quaddance.pipeline import DanceSpec, compose

BEATS_S = (0.5, 1.0, 1.5, 2.0, 2.5)


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("plain.txt", "0.5\n1.0\n1.5\n2.0\n2.5\n"),
        ("comments.txt", "# beats of a song\n\n0.5\n1.0  # one\n\n1.5\n2.0\n2.5"),
        ("sonic_visualiser.csv", "0.500000000,1\n1.000000000,2\n1.5,3\n2.0,4\n2.5,5\n"),
        ("audacity.txt", "0.5\t0.5\tb\n\\\t100.0\t2000.0\n1.0\t1.0\tb\n1.5\t1.5\n2\t2\n2.5\n"),
        ("beats.json", json.dumps({"beats_s": list(BEATS_S)})),
        ("beats", '  {"beats_s": [0.5, 1, 1.5, 2, 2.5], "source": "by hand"}'),
    ],
)
def test_each_format_reads_to_its_beats(tmp_path, name, text):
    beats = read_beats(_write(tmp_path, name, text))
    assert beats.beats_s == BEATS_S and beats.downbeats_s is None and beats.name == name


@pytest.mark.parametrize(
    ("name", "text", "downbeats_s"),
    [
        # madmom's DBNDownBeatTracker: time, tab, beat of the bar; the first bar part-way.
        ("madmom.beats", "0.5\t3\n1.0\t4\n1.5\t1\n2.0\t2\n2.5\t3\n", (1.5,)),
        ("ballroom.beats", "0.5 1\n1.0 2\n1.5 3\n2.0 1\n2.5 2\n", (0.5, 2.0)),  # 3/4
        ("harmonix.txt", "0.5\t1\t1\n1.0\t2\t1\n1.5\t3\t1\n2.0\t4\t1\n2.5\t1\t2\n", (0.5, 2.5)),
    ],
)
def test_a_second_column_that_counts_the_bar_s_beats_gives_the_downbeats(
    tmp_path, name, text, downbeats_s
):
    beats = read_beats(_write(tmp_path, name, text))
    assert beats.beats_s == BEATS_S and beats.downbeats_s == downbeats_s


@pytest.mark.parametrize(
    "column",
    [
        ["1", "2", "4", "1", "2"],  # skips a beat: not a count
        ["2", "3", "4", "5", "6"],  # no 1
        ["1", "2", "3", "4", "5"],  # never a new bar: a label's numbering (Sonic Visualiser's)
        ["1", "2", "3", "4", ""],  # a line without it
        ["1", "1.5", "1", "2", "3"],  # not whole numbers
        ["11", "12", "13", "1", "2"],  # past MAX_BAR_BEATS
        ["1", "2", "\u00b2", "1", "2"],  # a superscript two: a digit, not a number
    ],
)
def test_any_other_second_column_gives_no_downbeats(tmp_path, column):
    text = "\n".join(f"{t} {c}".strip() for t, c in zip(BEATS_S, column, strict=True))
    assert read_beats(_write(tmp_path, "b.txt", text)).downbeats_s is None


def test_json_downbeats_are_kept(tmp_path):
    path = _write(tmp_path, "b.json", json.dumps({"beats_s": BEATS_S, "downbeats_s": [1.0]}))
    assert read_beats(path).downbeats_s == (1.0,)


BAD = [
    ("empty.txt", "", "empty file"),
    ("blank.txt", "\n  \n# nothing\n", "no beat times"),
    ("word.txt", "0.5\n1.0\nbeat\n", "line 3: 'beat' is not a number"),
    ("nan.txt", "0.5\n1.0\nnan\n2.0\n", "beat 3 (nan) is not a finite number"),
    ("negative.txt", "-0.5\n0.5\n1.0\n1.5\n", "beat 1 (-0.500 s) is negative"),
    ("backwards.txt", "0.5\n1.0\n0.9\n1.5\n2.0\n", "beat 3 (0.900 s) is not after beat 2"),
    ("repeated.txt", "0.5\n1.0\n1.0\n1.5\n2.0\n", "strictly increasing"),
    ("three.txt", "0.5\n1.0\n1.5\n", "3 beats; at least 4 are needed"),
    ("close.txt", "0.5\n1.0\n1.1\n1.5\n2.0\n", "are 0.100 s apart; beats must be at least 0.2"),
    ("broken.json", '{"beats_s": [0.5, 1.0,', "not readable JSON"),
    ("list.json", "[0.5, 1.0, 1.5, 2.0]", 'an object with "beats_s"'),
    ("text.json", '{"beats_s": [0.5, "1.0", 1.5, 2.0]}', "beats_s[1] ('1.0') is not a number"),
    ("down.json", '{"beats_s": [0.5, 1, 1.5, 2], "downbeats_s": [1.2]}', "downbeat 1.200 s"),
    ("latin1.txt", b"0.5\n\xe9\n", "not a text file"),
    ("comma.txt", "0,5\n1,5\n2,5\n3,5\n", "line '0,5' reads as 0 s: write times with a decimal"),
]


@pytest.mark.parametrize(("name", "content", "problem"), BAD, ids=[b[0] for b in BAD])
def test_each_bad_beat_file_is_one_line(monkeypatch, capsys, tmp_path, song_3s, name, content,
                                        problem):  # fmt: skip
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    code, err = _quaddance(monkeypatch, capsys, "choreograph", song_3s, "--beats", path,
                           "-o", tmp_path / "d.npz")  # fmt: skip
    _one_line_error(code, err, f"quaddance: error: {path}: ", problem)


@pytest.mark.parametrize(("command", "flags"), [("choreograph", ()), ("dance", ("--no-video",))])
def test_beats_past_the_song_s_end_are_one_line(monkeypatch, capsys, tmp_path, song_3s,
                                                command, flags):  # fmt: skip
    """Found once the song is analysed (in ``dance``, by its helper process)."""
    path = _write(tmp_path, "long.txt", "\n".join(str(0.5 * k) for k in range(1, 9)))
    code, err = _quaddance(monkeypatch, capsys, command, song_3s, "--beats", path, *flags,
                           "--out", tmp_path / "out")  # fmt: skip
    errors = [line for line in err if line.startswith("quaddance: error:")]  # dance logs too
    assert code == 2 and len(errors) == 1, err
    assert errors[0].endswith(f"{path}: beat 4.000 s is past the song's end (3.000 s)")


@pytest.mark.parametrize(
    "args",
    [
        ("choreograph", "--motion", "walk.bvh"),
        ("dance", "--motion", "walk.bvh", "--no-video"),
        ("deploy", "--motion", "walk.bvh"),
        ("deploy", "--dance", "dance.npz"),
    ],
)
def test_beats_with_a_motion_or_a_dance_is_a_usage_error(monkeypatch, capsys, tmp_path, args):
    beats = _write(tmp_path, "beats.txt", "\n".join(map(str, BEATS_S)))
    code, err = _quaddance(monkeypatch, capsys, *args, "--beats", beats, "--out", tmp_path / "o")
    assert code == 2, err
    assert f"--beats gives a SONG's beats: not with {args[1]}" in " ".join(err), err


def test_the_grid_takes_the_file_s_beats_and_keeps_the_music_s_loudness():
    grid = synthetic_grid(120.0, 6.0, np.random.default_rng(0))
    beats = np.arange(0.3, 5.9, 0.6)
    mine = grid.with_beats(beats)
    np.testing.assert_array_equal(mine.beats_s, beats)
    np.testing.assert_array_equal(mine.downbeats_s, beats[::4])
    assert mine.tempo_bpm == pytest.approx(100.0)
    np.testing.assert_array_equal(mine.energy, grid.energy)
    np.testing.assert_array_equal(mine.sections_s, grid.sections_s)
    np.testing.assert_array_equal(grid.with_beats(beats, [0.9]).downbeats_s, [0.9])
    dance = compose(DanceSpec(beats=BeatList(Path("b.txt"), tuple(beats))), grid, music_name="s")
    np.testing.assert_array_equal(dance.beats_s, beats)
    assert dance.source.endswith("on s, beats of b.txt")


@pytest.fixture(scope="module")
def shifted(tmp_path_factory) -> tuple[Path, Path, np.ndarray]:
    """A 6 s song made by code and a beat file of its beats moved by half a beat: (song,
    file, the file's beats)."""
    import soundfile as sf

    from quaddance.music.synth import render_song

    folder = tmp_path_factory.mktemp("shifted")
    y, truth = render_song(120.0, 6.0, seed=4)
    sf.write(folder / "song.wav", y, 22050)
    beats_s = truth.beats_s + 0.25
    beats_s = beats_s[beats_s < truth.duration_s]
    path = folder / "beats.txt"
    path.write_text("".join(f"{t:.4f}\tbeat\n" for t in beats_s))
    return folder / "song.wav", path, beats_s


def _lift_offsets_s(dance, beats_s: np.ndarray) -> np.ndarray:
    """Distance from each front-paw lift's peak to the nearest of ``beats_s``, s."""
    accents = motion_accents_s(dance.time_s, dance.targets_m)
    assert accents.size >= 2
    return accent_offsets_s(beats_s, accents)  # each accent's distance to the nearest beat


def test_a_dance_with_beats_lifts_on_the_file_s_beats(monkeypatch, capsys, tmp_path, shifted):
    song, path, beats_s = shifted
    out = tmp_path / "out"
    # The command ends its process without teardown; here it must return to the tests.
    monkeypatch.setattr("quaddance.cli.dance.exit_without_teardown", lambda: None)
    code, _ = _quaddance(monkeypatch, capsys, "dance", song, "--beats", path, "--no-video",
                         "--out", out)  # fmt: skip
    assert code == 0
    dance = load_dance(out / "dance.npz")
    np.testing.assert_allclose(dance.beats_s, beats_s)
    np.testing.assert_allclose(dance.downbeats_s, beats_s[::4])
    assert dance.source.endswith("on song.wav, beats of beats.txt")
    assert json.loads((out / "metrics.json").read_text())["source"] == dance.source
    # The lifts peak on the file's beats, half a beat from the song's own.
    assert _lift_offsets_s(dance, beats_s).max() < 0.05
    assert _lift_offsets_s(dance, beats_s - 0.25).min() > 0.15


def test_choreograph_and_deploy_dance_to_the_file_s_beats(monkeypatch, capsys, tmp_path, shifted):
    song, path, beats_s = shifted
    code, _ = _quaddance(monkeypatch, capsys, "choreograph", song, "--beats", path,
                         "-o", tmp_path / "d.npz")  # fmt: skip
    assert code == 0
    dance = load_dance(tmp_path / "d.npz")
    np.testing.assert_allclose(dance.beats_s, beats_s)
    assert _lift_offsets_s(dance, beats_s).max() < 0.05

    from quaddance.deploy import job as deploy_job

    made = []
    make_dance = deploy_job.make_dance

    def keep(*args, **kwargs):
        made.append(make_dance(*args, **kwargs)[0])
        raise SystemExit(0)

    monkeypatch.setattr(deploy_job, "make_dance", keep)
    code, _ = _quaddance(monkeypatch, capsys, "deploy", song, "--beats", path, "--out",
                         tmp_path / "deploy")  # fmt: skip
    assert code == 0
    np.testing.assert_allclose(made[0].beats_s, beats_s)
    assert made[0].source.endswith("beats of beats.txt")


def _beats(times) -> BeatList:
    return BeatList(Path("b.txt"), tuple(float(t) for t in times))


def test_beats_that_span_the_song_in_the_dance_range_have_no_notes():
    assert _beats(np.arange(0.4, 29.9, 0.5)).notes(30.0) == []
    assert _beats(np.arange(14.0, 44.0, 1.0)).notes(58.0) == []  # 14 s before, 15 s after


@pytest.mark.parametrize(
    ("times", "duration_s", "words"),
    [
        (np.arange(0.0, 30.0, 0.25), 30.0, "its beats run at 240 BPM, outside the dance range "
         "60-180 BPM; they are danced as they are (give every second beat"),
        (np.arange(0.0, 30.0, 5.0), 30.0, "its beats run at 12 BPM, outside the dance range "
         "60-180 BPM; they are danced as they are (give a beat between each two"),
        (np.arange(0.5, 4.6, 0.5), 120.0, "the last beat is at 4.5 s of the 120.0 s song; the "
         "robot stands still for the last 115.5 s"),
        (np.arange(20.0, 60.0, 0.5), 60.0, "the first beat is at 20.0 s; the robot stands still "
         "until then"),
    ],
)  # fmt: skip
def test_beats_off_the_dance_range_or_leaving_the_song_bare_get_a_note(times, duration_s, words):
    notes = _beats(times).notes(duration_s)
    assert len(notes) == 1 and notes[0].startswith(f"b.txt: {words}"), notes


def test_choreograph_and_dance_say_where_the_beats_leave_the_robot_standing(
    monkeypatch, capsys, tmp_path, demo_song
):
    song, _ = demo_song
    path = _write(tmp_path, "intro.txt", "\n".join(str(0.5 * k) for k in range(1, 10)))
    note = "note: intro.txt: the last beat is at 4.5 s of the 30.0 s song; the robot stands "
    code, err = _quaddance(monkeypatch, capsys, "choreograph", song, "--beats", path,
                           "-o", tmp_path / "d.npz")  # fmt: skip
    assert code == 0 and any(line.startswith(note) for line in err), err
    monkeypatch.setattr("quaddance.cli.dance.exit_without_teardown", lambda: None)
    code, err = _quaddance(monkeypatch, capsys, "dance", song, "--beats", path, "--no-video",
                           "--out", tmp_path / "out")  # fmt: skip
    assert code == 0 and any(line.startswith(note) for line in err), err
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["notes"][0].startswith(note.removeprefix("note: "))
