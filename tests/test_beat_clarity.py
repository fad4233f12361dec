"""Beat clarity: audio without a steady beat (noise, speech) is told apart from music with one,
and the user hears it in one ``note:`` line where a dance is made from the analysed beats."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from test_robot_choice import _quaddance

from quaddance.music.analysis import Analysis, AnalysisConfig, analyze, beat_clarity
from quaddance.music.synth import render_song

SR = 22050
FPS = 43.0
NOTE = "no clear steady beat"


def _noise(seconds: float, seed: int = 0) -> np.ndarray:
    return (0.2 * np.random.default_rng(seed).standard_normal(int(seconds * SR))).astype(np.float32)


def test_an_envelope_that_pulses_at_a_dance_tempo_is_clear_and_noise_is_not() -> None:
    pulses = np.zeros(2000)
    pulses[:: round(FPS * 60 / 100)] = 1.0  # 100 BPM
    assert beat_clarity(pulses, FPS) > 0.8
    noise = np.abs(np.random.default_rng(1).standard_normal(2000))
    assert abs(beat_clarity(noise, FPS)) < 0.1
    # Pulses at 30 BPM: no lag inside the dance range (60-180 BPM) falls on them.
    slow = np.zeros(2000)
    slow[:: round(FPS * 2)] = 1.0
    assert beat_clarity(slow, FPS) < 0.1
    assert beat_clarity(np.ones(2000), FPS) == 0.0  # flat: nothing pulses
    assert beat_clarity(pulses[:30], FPS) == 0.0  # shorter than a beat at 60 BPM


def test_noise_gets_a_note_and_a_song_does_not() -> None:
    noisy = analyze(_noise(20.0), SR)
    assert noisy.beat_clarity < AnalysisConfig().min_beat_clarity
    notes = noisy.notes("noise.wav")
    assert len(notes) == 1 and notes[0].startswith(f"noise.wav: {NOTE}"), notes
    y, _ = render_song(100.0, 20.0, seed=3)
    song = analyze(y, SR)
    assert song.beat_clarity >= AnalysisConfig().min_beat_clarity
    assert song.notes("song.wav") == []


def test_the_analysis_file_keeps_the_clarity_and_an_older_file_has_none(tmp_path: Path) -> None:
    result = analyze(_noise(10.0), SR)
    path = tmp_path / "a.json"
    result.save_json(path)
    back = Analysis.load_json(path)
    assert back.beat_clarity == pytest.approx(result.beat_clarity, abs=1e-3)
    assert back.notes("x") == result.notes("x") != []
    data = json.loads(path.read_text())
    del data["beat_clarity"]
    path.write_text(json.dumps(data))
    older = Analysis.load_json(path)
    assert older.beat_clarity is None and older.notes("x") == []


def test_analyze_and_choreograph_say_so_unless_the_beats_come_from_a_file(
    monkeypatch, capsys, tmp_path: Path
) -> None:
    song = tmp_path / "hiss.wav"
    sf.write(song, _noise(12.0, seed=2), SR)
    note = f"note: hiss.wav: {NOTE}"
    code, err = _quaddance(monkeypatch, capsys, "analyze", song, "-o", tmp_path / "a.json")
    assert code == 0 and any(line.startswith(note) for line in err), err
    code, err = _quaddance(monkeypatch, capsys, "choreograph", song, "-o", tmp_path / "d.npz")
    assert code == 0 and any(line.startswith(note) for line in err), err
    beats = tmp_path / "beats.txt"
    beats.write_text("\n".join(f"{0.5 * k:.1f}" for k in range(1, 24)))
    code, err = _quaddance(
        monkeypatch, capsys, "choreograph", song, "--beats", beats, "-o", tmp_path / "e.npz"
    )
    assert code == 0 and not any(NOTE in line for line in err), err


def test_the_benchmark_s_noises_are_heard_as_beatless() -> None:
    from benchmarks.beat_clarity import clarity, noises

    drawn = noises()
    assert set(drawn) == {"white noise", "brown noise", "crackle"}
    assert all(clarity(y) < AnalysisConfig().min_beat_clarity for y in drawn.values())
    assert all(np.array_equal(drawn[k], v) for k, v in noises().items())  # one fixed seed
