"""The analyser's learned beat activation (`music.beat_activation`): what it was fitted on,
what it hears, its fit (`benchmarks.train_beat_activation`) and its file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.real_music import REAL_SET_ROOTS, read_sources
from benchmarks.train_beat_activation import FPS, SR_HZ, fit, frame_labels
from quaddance.errors import InputFileError
from quaddance.music import analysis, beat_activation
from quaddance.music.beat_activation import BeatActivationModel, load_model, n_features
from quaddance.music.synth import render_song


def _beat_and_offbeat_frames(frames: np.ndarray, n_frames: int) -> tuple[np.ndarray, ...]:
    on = np.round(frames).astype(int)
    off = np.round(0.5 * (frames[1:] + frames[:-1])).astype(int)
    return on[(on >= 0) & (on < n_frames)], off[(off >= 0) & (off < n_frames)]


def _peak_near(x: np.ndarray, frames: np.ndarray, radius: int) -> np.ndarray:
    return np.array([x[max(0, f - radius) : f + radius + 1].max() for f in frames])


def test_the_shipped_model_was_fitted_on_tuning_songs_only() -> None:
    model = load_model()
    splits = {s.name: s.split for root in REAL_SET_ROOTS.values() for s in read_sources(root)[0]}
    tuning = {name for name, split in splits.items() if split == "tuning"}
    assert set(model.trained_on) == tuning  # every tuning song, and no held-out one
    assert model.context == beat_activation.CONTEXT
    assert model.weights.shape == (n_features(model.context),)


@pytest.mark.parametrize(("tempo_bpm", "swing"), [(96.0, 0.0), (128.0, 0.0), (110.0, 0.3)])
def test_the_activation_hears_the_beats_more_than_the_offbeats(tempo_bpm, swing) -> None:
    y, truth = render_song(tempo_bpm, 20.0, seed=7, swing=swing)
    rows = analysis.activation_rows(y, SR_HZ)
    act = load_model().activation(rows)
    assert act.shape == (rows.shape[1],) and np.all((act >= 0.0) & (act <= 1.0))
    on, off = _beat_and_offbeat_frames(truth.beats_s * FPS, len(act))
    assert np.median(_peak_near(act, on, 1)) > 1.5 * np.median(_peak_near(act, off, 1))


def test_a_fit_learns_where_the_beats_are_and_round_trips(tmp_path: Path) -> None:
    songs = [render_song(tempo, 15.0, seed=seed) for tempo, seed in ((100.0, 1), (140.0, 2))]
    rows = [analysis.activation_rows(y, SR_HZ) for y, _ in songs]
    labels = [
        frame_labels(t.beats_s, FPS, r.shape[1]) for (_, t), r in zip(songs, rows, strict=True)
    ]
    for lab, (_, truth) in zip(labels, songs, strict=True):
        on, off = _beat_and_offbeat_frames(truth.beats_s * FPS, len(lab))
        assert lab[on].all() and not lab[off].any() and lab.sum() <= 3 * len(truth.beats_s)
    model = fit(rows, labels, ["a", "b"])
    y, truth = render_song(120.0, 15.0, seed=3)  # a song it was not fitted on
    act = model.activation(analysis.activation_rows(y, SR_HZ))
    on, off = _beat_and_offbeat_frames(truth.beats_s * FPS, len(act))
    assert np.median(_peak_near(act, on, 1)) > 1.5 * np.median(_peak_near(act, off, 1))
    path = tmp_path / "model.json"
    model.save(path)
    back = BeatActivationModel.load(path)
    assert back.trained_on == ("a", "b") and back.context == model.context
    np.testing.assert_allclose(back.weights, model.weights, atol=1e-6)
    # The analyser reads a model file named in its settings.
    cfg = analysis.AnalysisConfig(activation_model=path)
    assert analysis.analyze(y, SR_HZ, cfg).beats_s.size > 20


def _good_model_dict() -> dict:
    context = (3, 3)
    return BeatActivationModel(
        np.zeros(n_features(context)), 0.0, context, ("a",), 1.0
    ).to_json_dict()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda d: "not json {", "is not a JSON file"),
        (lambda d: {**d, "format": "other"}, "is not a beat activation model"),
        (lambda d: {**d, "n_bands": 4}, "bands"),
        (lambda d: {**d, "weights": d["weights"][:-1]}, "weights must be"),
        (lambda d: {**d, "context_frames": [6, 1]}, "weights must be"),
        (lambda d: {**d, "context_frames": [-1, 0]}, "context_frames must be"),
        (lambda d: {**d, "weights": ["x"] * len(d["weights"])}, "malformed"),
        (lambda d: {k: v for k, v in d.items() if k != "bias"}, "malformed"),
    ],
)
def test_a_bad_model_file_is_refused_with_its_name(tmp_path: Path, change, message) -> None:
    path = tmp_path / "model.json"
    changed = change(_good_model_dict())
    path.write_text(changed if isinstance(changed, str) else json.dumps(changed))
    with pytest.raises(InputFileError, match=message) as err:
        BeatActivationModel.load(path)
    assert str(path) in str(err.value)


def test_a_missing_model_file_stops_the_analysis_with_its_name(tmp_path: Path) -> None:
    y, _ = render_song(120.0, 5.0, seed=1)
    cfg = analysis.AnalysisConfig(activation_model=tmp_path / "absent.json")
    with pytest.raises(InputFileError, match=r"absent\.json"):
        analysis.analyze(y, SR_HZ, cfg)
    beat_activation.load_model.cache_clear()


def test_the_fit_and_cross_validation_commands_write_their_files(tmp_path, monkeypatch) -> None:
    import benchmarks.train_beat_activation as tba
    from benchmarks.real_music import RealSong

    songs, audio = [], {}
    for k, (tempo, artist) in enumerate(((100.0, "A"), (128.0, "B"), (116.0, "B (band)"))):
        y, truth = render_song(tempo, 12.0, seed=k)
        name = f"song{k}"
        audio[name] = y
        songs.append(
            RealSong(name, name, artist, "tuning", "recording", tmp_path / f"{name}.ogg",
                     truth.beats_s, truth.downbeats_s, (tempo, tempo), "4/4", "MIT", 12.0)
        )  # fmt: skip
    monkeypatch.setattr(tba, "tuning_songs", lambda: songs)
    monkeypatch.setattr(tba, "load_audio_at", lambda song, sr: audio[song.name])
    model_path, cv_path = tmp_path / "model.json", tmp_path / "cv.json"
    tba.main(["--out", str(model_path)])
    assert BeatActivationModel.load(model_path).trained_on == ("song0", "song1", "song2")
    tba.main(["--cross-validate", "--weights", "0", "0.5", "--cv-out", str(cv_path)])
    cv = json.loads(cv_path.read_text())
    assert cv["songs"] == ["song0", "song1", "song2"]
    assert set(cv["by_activation_weight"]) == {"0", "0.5"}
    for scores in cv["by_activation_weight"].values():
        assert 0.5 < scores["f_metrical"] <= 1.0 and 0.0 <= scores["f"] <= 1.0
