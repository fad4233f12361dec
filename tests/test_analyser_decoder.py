"""``python -m benchmarks.analyser_decoder``: the offline analyser with its DP and with the field's
beat-pointer HMM in the DP's place."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from tuning_sets import code_made_sets

import benchmarks.analyser_decoder as dec
from benchmarks.real_music import RealSong
from quaddance.music import analysis


def _pulse_envelope(bpm: float, duration_s: float, start_s: float) -> np.ndarray:
    """An onset envelope with a unit pulse at each beat and a little noise elsewhere."""
    rng = np.random.default_rng(0)
    env = 0.05 * rng.random(int(duration_s * dec.FPS))
    for t in np.arange(start_s, duration_s - 0.1, 60.0 / bpm):
        env[round(t * dec.FPS)] = 1.0
    return env


@pytest.mark.parametrize("steps_per_frame", [1, 2])
def test_the_hmm_finds_the_beats_of_a_pulse_train(steps_per_frame: int) -> None:
    env = _pulse_envelope(128.0, 20.0, 0.31)
    frames = dec.hmm_track_beats(env, np.full(len(env), 1.0), 3000.0, steps_per_frame)
    assert np.all(np.diff(frames) > 0)
    truth = np.flatnonzero(env == 1.0)
    # Every pulse after the first two is a beat, and no beat falls between pulses.
    hit = np.isin(truth[2:], frames)
    assert hit.all(), truth[2:][~hit]
    assert len(frames) <= len(truth)
    assert dec.hmm_track_beats(np.zeros(0), np.zeros(0), 3000.0).size == 0


def test_the_decoder_is_swapped_only_while_the_context_is_open() -> None:
    shipped = analysis._track_beats
    with dec.decoder("hmm"):
        assert analysis._track_beats is dec.hmm_track_beats
    assert analysis._track_beats is shipped
    with pytest.raises(RuntimeError), dec.decoder("hmm"):
        raise RuntimeError
    assert analysis._track_beats is shipped
    with dec.decoder("dp"):
        assert analysis._track_beats is shipped
    with pytest.raises(ValueError, match="unknown decoder 'viterbi'"), dec.decoder("viterbi"):
        pass


def test_a_song_is_analysed_with_each_decoder(tmp_path: Path, monkeypatch) -> None:
    made = code_made_sets(tmp_path, 10.0)
    monkeypatch.setattr(dec, "load_audio_at", lambda song, sr: made.audio[song.name])
    used: list[object] = []
    real = analysis.analyze

    def spied(y, sr, cfg=None):
        used.append(analysis._track_beats)
        return real(y, sr, cfg)

    monkeypatch.setattr(analysis, "analyze", spied)
    song = made.sets[next(iter(made.sets))][0]
    row = dec.score_song(song)
    assert used == [analysis._track_beats, dec.hmm_track_beats]
    for way in dec.WAYS:  # a code-made song at 100 BPM: both decoders are on its beats
        assert row[way]["f_metrical"] > 0.9, way


def test_every_split_is_summarised_with_the_songs_each_way(tmp_path, monkeypatch) -> None:
    made = code_made_sets(tmp_path, 10.0)

    def score(song: RealSong) -> dict:
        hmm = 0.5 if song.split == "heldout" else 1.0
        return {"dp": {"f_metrical": 1.0, "f": 1.0, "downbeat_f": 0.5},
                "hmm": {"f_metrical": hmm, "f": hmm, "downbeat_f": 0.5}}  # fmt: skip

    monkeypatch.setattr(dec, "score_song", score)
    monkeypatch.setattr(dec, "load_songs", made.load_songs)
    a, b = made.sets
    monkeypatch.setattr(dec, "REAL_SET_ROOTS", {"real": a})
    out = tmp_path / "decoder.json"
    dec.main(["--also", str(b), "--out", str(out)])
    result = json.loads(out.read_text())
    assert result["command"] == f"python -m benchmarks.analyser_decoder --also {b} --out {out}"
    held, tuning = result["summary"]["heldout"], result["summary"]["tuning"]
    assert held["n_songs"] == 2 and held["hmm_lower"] == 2 and held["hmm_higher"] == 0
    assert held["f_metrical_dp"] == 1.0 and held["f_metrical_hmm"] == 0.5
    assert tuning["hmm_lower"] == 0 and tuning["f_metrical_hmm"] == 1.0
    names = {"real": a, b.name: b}
    assert set(result["songs"]) == {
        f"{s.split}/{name}/{s.name}" for name, root in names.items() for s in made.sets[root]
    }
    with pytest.raises(SystemExit):
        dec.main(["--jobs", "0", "--out", str(out)])


def test_jobs_analyse_the_songs_in_processes_with_the_same_results(tmp_path, monkeypatch) -> None:
    made = code_made_sets(tmp_path, 8.0)
    a, _ = made.sets
    monkeypatch.setattr(dec, "load_audio_at", lambda song, sr: made.audio[song.name])
    monkeypatch.setattr(dec, "load_songs", made.load_songs)
    one = dec.run({"real": a}, jobs=1)
    two = dec.run({"real": a}, jobs=2)
    assert one == two and len(two["songs"]) == 2
