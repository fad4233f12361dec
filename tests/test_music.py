"""Music in: decoding, beat tracking, downbeats, sections, the demo song, the analyze CLI."""

from __future__ import annotations

import itertools
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from typer.testing import CliRunner

from benchmarks.beats import (
    BENCH_SONGS,
    EXTRA_TUNING_SONGS,
    INSTALL_HINT,
    TICKS_PER_BEAT,
    MidiSongSpec,
    beat_f_measure,
    find_soundfont,
    metrical_level_f_measure,
    render_midi,
    write_midi,
)
from quaddance.cli import app
from quaddance.errors import InputFileError, OutputFileError, QuaddanceError
from quaddance.music.analysis import (
    Analysis,
    AnalysisConfig,
    _track_beats,
    analyze,
    analyze_file,
    offbeat_harmony,
)
from quaddance.music.audio import load_audio
from quaddance.music.click import (
    CLICK_HZ,
    CLICK_S,
    DOWNBEAT_CLICK_HZ,
    SONG_PEAK,
    click_track,
    with_clicks,
)
from quaddance.music.synth import DEMO_TEMPO_BPM, render_song

SR = 22050
JSON_KEYS = {"tempo_bpm", "beats_s", "downbeats_s", "onset_env", "rms_env", "env_fps", "sections_s"}


# --- the F-measure ----------------------------------------------------------------------------


def test_f_measure_counts_hits_within_70_ms_one_to_one() -> None:
    ref = np.arange(10) * 0.5
    assert beat_f_measure(ref, ref + 0.06) == pytest.approx(1.0)
    assert beat_f_measure(ref, ref + 0.08) == 0.0
    # Double tempo: every reference beat is found (recall 1) but half the estimates are extra.
    assert beat_f_measure(ref, np.arange(20) * 0.25) == pytest.approx(2 * 0.5 / 1.5)
    # Two estimates next to one reference beat: only one of them may count.
    assert beat_f_measure([1.0], [0.98, 1.02]) == pytest.approx(2 * 0.5 * 1.0 / 1.5)
    assert beat_f_measure(ref, []) == 0.0


def test_metrical_level_f_picks_the_estimate_s_level_and_phase() -> None:
    ref = np.arange(40) * 0.5  # 120 BPM
    # Half tempo on the second, fourth, ... beat: every estimate is a true beat.
    half_odd = ref[1::2] + 0.02
    assert beat_f_measure(ref, half_odd) == pytest.approx(2 * 0.5 / 1.5)
    assert metrical_level_f_measure(ref, half_odd) == pytest.approx(1.0)
    assert metrical_level_f_measure(ref, ref[0::2]) == pytest.approx(1.0)
    # Double tempo: the reference gains the midpoints between its beats.
    double = np.arange(79) * 0.25
    assert metrical_level_f_measure(ref, double) == pytest.approx(1.0)
    assert metrical_level_f_measure(ref, ref - 0.03) == pytest.approx(1.0)


def test_metrical_level_f_scores_off_beat_tracking_low() -> None:
    ref = np.arange(40) * 0.5
    off = ref + 0.25  # the right tempo, on the "and"s
    assert metrical_level_f_measure(ref, off) == 0.0
    # Half tempo on the off-beats matches neither phase of the half-tempo reference.
    assert metrical_level_f_measure(ref, off[0::2]) == 0.0
    # Three beats per two: only every third estimate is a true beat.
    assert metrical_level_f_measure(ref, np.arange(27) * 0.75) < 0.5


# --- the synthesiser --------------------------------------------------------------------------


def test_render_song_truth_matches_its_tempo_map() -> None:
    y, truth = render_song(100.0, 12.0, seed=1, tempo_change=(6.0, 125.0))
    assert y.dtype == np.float32 and y.shape == (12 * SR,)
    gaps = np.diff(truth.beats_s)
    assert np.allclose(gaps[truth.beats_s[1:] <= 6.0], 0.6)
    assert np.allclose(gaps[truth.beats_s[:-1] >= 6.0], 60.0 / 125.0)
    assert np.all(np.isin(truth.downbeats_s, truth.beats_s))
    assert np.all(np.isin(truth.section_change_s, truth.downbeats_s))
    y2, _ = render_song(100.0, 12.0, seed=1, tempo_change=(6.0, 125.0))
    assert np.array_equal(y, y2)  # same seed, same song


@pytest.mark.parametrize("tempo_bpm", [40.0, 62.0, 63.0, 200.0])
def test_render_song_fills_the_last_bar_at_any_tempo(tempo_bpm: float) -> None:
    # 62 BPM x 20 s ends a bar exactly on the grid's last beat (an IndexError before).
    y, truth = render_song(tempo_bpm, 20.0, seed=0)
    assert y.shape == (20 * SR,) and np.isfinite(y).all()
    assert truth.beats_s[-1] < 20.0 and np.allclose(np.diff(truth.beats_s), 60.0 / tempo_bpm)


# --- beat tracking ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("tempo_bpm", "kwargs"),
    [
        (96.0, {"swing": 0.8, "intro_s": 4.0, "seed": 11}),  # swung, with a quiet intro
        (138.0, {"syncopation": True, "seed": 12}),  # off-beat stabs, kick and bass
        (100.0, {"tempo_change": (10.0, 124.0), "seed": 13}),  # tempo change at 10 s
    ],
)
def test_beats_found_on_generated_songs(tempo_bpm: float, kwargs: dict) -> None:
    y, truth = render_song(tempo_bpm, 20.0, sr=SR, **kwargs)
    result = analyze(y, SR)
    assert beat_f_measure(truth.beats_s, result.beats_s) >= 0.85
    # The right tempo octave: the median beat interval matches the song's final tempo.
    assert result.tempo_bpm == pytest.approx(truth.extra["final_tempo_bpm"], rel=0.04)
    assert beat_f_measure(truth.downbeats_s, result.downbeats_s) >= 0.8
    # Each true section change is found within one bar.
    bar_s = 4 * 60.0 / truth.extra["final_tempo_bpm"]
    for change_s in truth.section_change_s:
        assert np.min(np.abs(result.sections_s - change_s)) < bar_s


def test_demo_song_beats_downbeats_and_section(demo_song: tuple[Path, object]) -> None:
    path, truth = demo_song
    result = analyze_file(path)
    assert result.source == str(path)
    assert result.tempo_bpm == pytest.approx(DEMO_TEMPO_BPM, abs=1.0)
    assert beat_f_measure(truth.beats_s, result.beats_s) >= 0.95
    assert beat_f_measure(truth.downbeats_s, result.downbeats_s) >= 0.9
    assert result.sections_s[0] == 0.0
    assert np.min(np.abs(result.sections_s[1:] - truth.section_change_s[0])) < 0.1
    n_frames = round(result.duration_s * result.env_fps)
    assert abs(result.onset_env.size - n_frames) <= 1
    assert result.rms_env.size == result.onset_env.size
    # The loud second section is louder in the RMS envelope.
    cut = round(truth.section_change_s[0] * result.env_fps)
    assert result.rms_env[cut:].mean() > 1.5 * result.rms_env[:cut].mean()


def _midi_song(name: str, tmp_path: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """(audio, beat times s, tempo BPM) of a benchmark MIDI song rendered with fluidsynth."""
    if shutil.which("fluidsynth") is None:
        pytest.skip(f"needs fluidsynth: {INSTALL_HINT}")
    spec = next(s for s in (*BENCH_SONGS, *EXTRA_TUNING_SONGS) if s.name == name)
    beats_s = write_midi(spec, tmp_path / "song.mid")
    render_midi(tmp_path / "song.mid", tmp_path / "song.wav", find_soundfont(), SR)
    y, _ = load_audio(tmp_path / "song.wav", sr=SR)
    return y[: round((2 * beats_s[-1] - beats_s[-2]) * SR)], beats_s, spec.tempo_bpm


@pytest.mark.parametrize(
    ("name", "levels"),
    [
        # Kick on 1 and 3, snare on 2 and 4: not to be heard at half tempo (78 BPM).
        ("tune_punk_156", (1.0,)),
        ("ballad_70_intro", (1.0,)),  # a true slow song with a backbeat must stay slow
        # Even eighth notes and no drums: 72 BPM or 144, both in the dance range.
        ("piano_72_arpeggio", (1.0, 2.0)),
    ],
)
def test_tempo_octave_on_midi_songs(name: str, levels: tuple[float, ...], tmp_path: Path) -> None:
    y, beats_s, tempo_bpm = _midi_song(name, tmp_path)
    result = analyze(y, SR)
    assert min(abs(result.tempo_bpm / (k * tempo_bpm) - 1.0) for k in levels) < 0.03
    assert metrical_level_f_measure(beats_s, result.beats_s) >= 0.95


@pytest.mark.parametrize(("from_bpm", "to_bpm"), [(80.0, 64.0), (64.0, 80.0), (100.0, 125.0)])
def test_the_beat_dp_keeps_its_phase_across_an_abrupt_tempo_change(
    from_bpm: float, to_bpm: float
) -> None:
    # Beats with off-beats nearly as strong, and a tempo that changes within half a second
    # at 30 s. The interval across the change lies between the two periods; charging it
    # against the later period alone dropped the beats around the change or moved the rest
    # of the song onto the off-beats (F 0.96, 0.94, 0.44).
    fps = SR / AnalysisConfig().hop_length
    beats_s = [0.5]
    while beats_s[-1] < 58.5:
        beats_s.append(beats_s[-1] + 60.0 / (from_bpm if beats_s[-1] < 30.0 else to_bpm))
    onset = np.zeros(round(60.0 * fps))
    for b, nxt in itertools.pairwise(beats_s):
        onset[round(b * fps)] += 1.0
        onset[round((b + nxt) / 2 * fps)] += 0.9
    period = np.interp(
        np.arange(len(onset)) / fps, [29.75, 30.25], [60.0 / from_bpm, 60.0 / to_bpm]
    )
    frames = _track_beats(onset, period * fps, tightness=3000.0, steps_per_frame=2)
    assert beat_f_measure(np.array(beats_s[:-1]), frames / fps) >= 0.98


def test_keys_on_the_off_beats_do_not_pull_the_beats(tmp_path: Path) -> None:
    # Skanking keys on every off-beat, a syncopated bass, no drums: only the bass line's
    # changes of pitch on beat 1 tell where the beat is.
    y, beats_s, _ = _midi_song("tune_skank_100_nodrums", tmp_path)
    result = analyze(y, SR)
    assert result.extra["offbeat_shift"]
    assert beat_f_measure(beats_s, result.beats_s) >= 0.9


def test_offbeat_harmony_says_where_the_bass_changes_pitch() -> None:
    # A bass line that moves to another note every 20 frames: beats on its changes are on the
    # beat; beats half-way between them, on the off-beats; a bass that never moves tells nothing.
    n_frames, step = 400, 20
    chroma = np.zeros((12, n_frames))
    for k in range(0, n_frames, step):
        chroma[(5 * k // step) % 12, k : k + step] = 1.0
    beats = np.arange(step, n_frames - step, step)
    cfg = AnalysisConfig()
    assert not offbeat_harmony(chroma, beats, cfg)
    assert offbeat_harmony(chroma, beats + step // 2, cfg)
    assert offbeat_harmony(chroma, beats[:9] + step // 2, cfg)  # 8 beats, the analyser's minimum
    assert not offbeat_harmony(np.ones((12, n_frames)), beats + step // 2, cfg)


def test_silence_has_no_beats() -> None:
    result = analyze(np.zeros(3 * SR, dtype=np.float32), SR)
    assert result.beats_s.size == 0 and result.sections_s.tolist() == [0.0]


def test_a_files_level_does_not_move_its_beats_downbeats_or_sections() -> None:
    """A song heard 3 dB quieter, or 20 dB, is analysed as the song itself: before the
    analysis heard every file at one level, 3 dB moved beats by a frame and moved sections,
    and the dance, whose seed mixes in the beat times, with them."""
    y, _ = render_song(97.0, 40.0, seed=21, swing=0.3)
    y = y * np.linspace(0.4, 1.0, len(y), dtype=np.float32)  # a crescendo: peak below 0.9
    results = [analyze(gain * y, SR) for gain in (1.0, 0.707, 0.1)]
    first = results[0]
    assert first.beats_s.size > 40
    for other in results[1:]:
        np.testing.assert_array_equal(other.beats_s, first.beats_s)
        np.testing.assert_array_equal(other.downbeats_s, first.downbeats_s)
        np.testing.assert_array_equal(other.sections_s, first.sections_s)
        np.testing.assert_allclose(other.rms_env, first.rms_env, rtol=1e-4, atol=1e-7)


# --- decoding ---------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["wav", "flac", "ogg", "mp3"])
def test_load_audio_formats(tmp_path: Path, fmt: str) -> None:
    if fmt.upper() not in sf.available_formats():
        pytest.skip(f"this libsndfile ({sf.__libsndfile_version__}) cannot write {fmt}")
    y, _ = render_song(120.0, 3.0, seed=2, sr=44100)
    stereo = np.stack([y, 0.5 * y], axis=1)
    path = tmp_path / f"song.{fmt}"
    sf.write(str(path), stereo, 44100, format=fmt.upper())
    loaded, sr = load_audio(path, sr=SR)
    assert sr == SR and loaded.dtype == np.float32 and loaded.ndim == 1
    assert abs(loaded.size - 3 * SR) <= 0.01 * SR
    import librosa

    expected = 0.75 * librosa.resample(y, orig_sr=44100, target_sr=SR)
    n = min(loaded.size, expected.size)
    # Mono mix of (y, y/2) is 0.75 y; lossy codecs keep the waveform close.
    assert np.corrcoef(loaded[:n], expected[:n])[0, 1] > 0.9
    assert np.max(np.abs(loaded)) == pytest.approx(np.max(np.abs(expected)), rel=0.15)


def test_truncated_mp3_is_read_at_its_real_length(tmp_path: Path) -> None:
    """A cut mp3 keeps a header that claims the whole song; libsndfile's block reader then
    repeated its last block up to that length. The decoded length must be the real one."""
    if "MP3" not in sf.available_formats():
        pytest.skip(f"this libsndfile ({sf.__libsndfile_version__}) cannot write mp3")
    y, _ = render_song(120.0, 20.0, seed=3, sr=44100)
    whole = tmp_path / "whole.mp3"
    sf.write(str(whole), np.stack([y, y], axis=1), 44100, format="MP3")
    data = whole.read_bytes()
    cut = tmp_path / "cut.mp3"
    cut.write_bytes(data[: len(data) // 4])
    assert sf.info(str(cut)).duration > 15.0  # the header still claims the whole song
    loaded, sr = load_audio(cut, sr=SR)
    assert 3.0 < loaded.size / sr < 7.0
    np.testing.assert_allclose(loaded, load_audio(whole, sr=SR)[0][: loaded.size], atol=0.05)
    tiny = tmp_path / "tiny.mp3"
    tiny.write_bytes(data[:3000])
    with pytest.raises(InputFileError, match=r"tiny.mp3: is too short: 0\.\d+ s"):
        load_audio(tiny)


def _write(path: Path, y: np.ndarray) -> Path:
    sf.write(str(path), y, SR)
    return path


@pytest.mark.parametrize(
    ("name", "make", "words"),
    [
        ("missing.wav", lambda p: p, "no such file"),
        ("empty.wav", lambda p: p.write_bytes(b"") and p, "empty"),
        ("corrupt.wav", lambda p: p.write_bytes(b"RIFF\x00\x01garbage" * 50) and p, "corrupt"),
        ("corrupt.mp3", lambda p: p.write_bytes(bytes(range(256)) * 20) and p, "corrupt"),
        ("silent.wav", lambda p: _write(p, np.zeros(3 * SR, dtype=np.float32)), "silent"),
        ("short.wav", lambda p: _write(p, 0.5 * np.ones(SR // 2, dtype=np.float32)), "too short"),
        ("song.xyz", lambda p: p.write_bytes(b"\x00" * 100) and p, "unsupported file type"),
    ],
)
def test_load_audio_errors_name_the_file(tmp_path: Path, name: str, make, words: str) -> None:
    path = tmp_path / name
    make(path)
    with pytest.raises(InputFileError) as info:
        load_audio(path)
    assert name in str(info.value) and words in str(info.value)


# --- the analysis file and the CLI ------------------------------------------------------------


def test_analysis_json_round_trip_and_bad_files(tmp_path: Path) -> None:
    y, _ = render_song(110.0, 8.0, seed=4)
    result = analyze(y, SR)
    path = tmp_path / "a.json"
    result.save_json(path)
    back = Analysis.load_json(path)
    assert back.tempo_bpm == pytest.approx(result.tempo_bpm, abs=1e-3)
    assert np.allclose(back.beats_s, result.beats_s, atol=1e-4)
    assert np.allclose(back.rms_env, result.rms_env, atol=1e-6)
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(InputFileError, match=r"bad\.json"):
        Analysis.load_json(bad)
    bad.write_text(json.dumps({"tempo_bpm": 120}))
    with pytest.raises(InputFileError, match="missing"):
        Analysis.load_json(bad)


def test_analyze_cli_writes_all_keys(demo_song: tuple[Path, object], tmp_path: Path) -> None:
    path, truth = demo_song
    out = tmp_path / "out" / "analysis.json"
    result = CliRunner().invoke(app, ["analyze", str(path), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "sections" in result.output
    printed_bpm = float(re.search(r"tempo ([0-9.]+) BPM", result.output).group(1))
    assert printed_bpm == pytest.approx(118.0, abs=0.5)  # the demo song's tempo
    data = json.loads(out.read_text())
    assert data["tempo_bpm"] == pytest.approx(printed_bpm, abs=0.05)
    assert set(data) >= JSON_KEYS
    assert len(data["beats_s"]) == pytest.approx(truth.beats_s.size, abs=1)
    assert len(data["onset_env"]) == len(data["rms_env"]) > 1000
    missing = CliRunner().invoke(app, ["analyze", str(tmp_path / "nope.wav")])
    assert isinstance(missing.exception, InputFileError)


def test_demo_song_cli_is_deterministic(demo_song: tuple[Path, object], tmp_path: Path) -> None:
    path, _ = demo_song
    out = tmp_path / "again.wav"
    result = CliRunner().invoke(app, ["demo-song", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_bytes() == path.read_bytes()
    assert sf.info(str(out)).duration == pytest.approx(30.0, abs=0.01)


def _click_pitch_hz(x: np.ndarray, start: int, sr: int) -> float:
    seg = x[start : start + round(CLICK_S * sr)]
    spectrum = np.abs(np.fft.rfft(seg, n=8 * len(seg)))
    return float(np.fft.rfftfreq(8 * len(seg), 1.0 / sr)[np.argmax(spectrum)])


def test_click_track_starts_each_click_at_its_beat_and_marks_the_downbeats() -> None:
    n = 3 * SR
    beats_s = [-0.1, 0.5, 1.0, 1.5, 2.0, 2.99, 3.5]  # the first and last lie outside the song
    x = click_track(n, SR, beats_s, downbeats_s=[0.5, 1.505])
    inside = [b for b in beats_s if 0 <= b < 3.0]
    for b in inside:
        start = round(b * SR)
        assert np.all(x[start - 20 : start] == 0.0), b  # silent up to the beat
        assert np.abs(x[start : start + 10]).max() > 0.3, b  # loud at once
    assert _click_pitch_hz(x, round(0.5 * SR), SR) == pytest.approx(DOWNBEAT_CLICK_HZ, rel=0.02)
    assert _click_pitch_hz(x, round(1.5 * SR), SR) == pytest.approx(DOWNBEAT_CLICK_HZ, rel=0.02)
    for b in (1.0, 2.0):
        assert _click_pitch_hz(x, round(b * SR), SR) == pytest.approx(CLICK_HZ, rel=0.02)
    # Sound only in the clicks that lie inside the song; the one at 2.99 s is cut at the end.
    loud = np.flatnonzero(np.abs(x) > 1e-3)
    starts = [round(b * SR) for b in inside]
    assert all(
        any(0 <= i - s < CLICK_S * SR for s in starts) for i in loud[:: max(1, len(loud) // 500)]
    )
    assert len(x) == n and np.abs(x).max() <= 1.0


def test_with_clicks_scales_the_song_and_never_clips() -> None:
    rng = np.random.default_rng(0)
    y = 5.0 * rng.standard_normal(4 * SR).astype(np.float32)  # a float master far above 1
    beats_s = np.arange(0.0, 4.0, 0.2)  # as dense as beats may be
    mixed = with_clicks(y, SR, beats_s, beats_s[::4])
    assert np.abs(mixed).max() <= 1.0
    bare = with_clicks(y, SR, [])
    assert np.abs(bare).max() == pytest.approx(SONG_PEAK, rel=1e-5)
    assert np.allclose(
        mixed - bare, (1.0 - SONG_PEAK) * click_track(len(y), SR, beats_s, beats_s[::4]), atol=1e-6
    )


@pytest.mark.parametrize("tracker", [[], ["--online"]], ids=["offline", "online"])
def test_analyze_click_writes_the_song_with_its_beats_clicked(
    demo_song: tuple[Path, object], tmp_path: Path, tracker: list[str]
) -> None:
    path, _ = demo_song
    out, click = tmp_path / "a.json", tmp_path / "click.wav"
    result = CliRunner().invoke(
        app, ["analyze", str(path), *tracker, "-o", str(out), "--click", str(click)]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    written, sr = sf.read(str(click), dtype="float32")
    y, sr_song = load_audio(path)
    assert sr == sr_song and written.shape == y.shape
    expected = with_clicks(y, sr, data["beats_s"], data["downbeats_s"])
    assert np.abs(written - expected).max() < 2.0 / 2**15  # 16-bit wav
    assert len(data["beats_s"]) > 40 and len(data["downbeats_s"]) > 10


def test_audio_outputs_refuse_a_suffix_they_cannot_write(
    demo_song: tuple[Path, object], tmp_path: Path
) -> None:
    path, _ = demo_song
    out = tmp_path / "a.json"
    bad = CliRunner().invoke(
        app, ["analyze", str(path), "-o", str(out), "--click", str(tmp_path / "c.mp3")]
    )
    assert isinstance(bad.exception, OutputFileError) and "c.mp3" in str(bad.exception)
    assert not out.exists()  # refused before the analysis, not after it
    demo = CliRunner().invoke(app, ["demo-song", str(tmp_path / "demo")])
    assert isinstance(demo.exception, OutputFileError) and "no suffix" in str(demo.exception)


# --- the benchmark's songs --------------------------------------------------------------------


def test_bench_midi_beats_follow_the_tempo_map(tmp_path: Path) -> None:
    import mido

    spec = next(s for s in BENCH_SONGS if s.tempo_change is not None)
    beats_s = write_midi(spec, tmp_path / "song.mid")
    midi = mido.MidiFile(str(tmp_path / "song.mid"))
    assert midi.ticks_per_beat == TICKS_PER_BEAT
    gaps = np.diff(beats_s)
    assert gaps[0] == pytest.approx(60.0 / spec.tempo_bpm)
    assert gaps[-1] == pytest.approx(60.0 / spec.tempo_change[1])
    # mido's own clock agrees with our beat times at the end of the song.
    assert midi.length == pytest.approx(beats_s[-1] + gaps[-1], abs=0.05)


def test_bench_without_fluidsynth_says_how_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(QuaddanceError, match="apt-get install"):
        render_midi(tmp_path / "a.mid", tmp_path / "a.wav", tmp_path / "gm.sf2")
    assert "fluidsynth" in INSTALL_HINT


def test_bench_midi_notes_all_end_even_when_swing_overtakes_the_next_note(tmp_path: Path) -> None:
    """A triplet-swung off-beat sixteenth of an arpeggio lands less than half a sixteenth before
    the next note: its note must still end after it starts (a hanging note made fluidsynth
    render a 38 GB file without end)."""
    import mido

    spec = MidiSongSpec("arp_swing", 122, "rock", "arpeggio", "reggae", 57, 32, 1006, swing=1.0)
    write_midi(spec, tmp_path / "song.mid")
    midi = mido.MidiFile(str(tmp_path / "song.mid"))
    open_notes: dict[tuple[int, int], int] = {}
    n_notes = 0
    for msg in mido.merge_tracks(midi.tracks):
        key = (getattr(msg, "channel", -1), getattr(msg, "note", -1))
        if msg.type == "note_on" and msg.velocity > 0:
            assert key not in open_notes, f"note {key} starts again before it ended"
            open_notes[key] = 1
            n_notes += 1
        elif msg.type == "note_off" or (msg.type == "note_on" and msg.velocity == 0):
            assert open_notes.pop(key, None) is not None, f"note {key} ends before it starts"
    assert n_notes > 100
    assert not open_notes


def test_bench_midi_render_that_never_ends_fails_clearly(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import benchmarks.beats as beats

    def endless(cmd: list[str], **kwargs: object) -> None:
        Path(cmd[cmd.index("-F") + 1]).write_bytes(b"RIFF")  # the partial file
        raise subprocess.TimeoutExpired(cmd, kwargs["timeout"])

    monkeypatch.setattr(beats.subprocess, "run", endless)
    monkeypatch.setattr(shutil, "which", lambda name: "/usr/bin/" + name)
    with pytest.raises(QuaddanceError, match=r"a\.mid .*did not finish|did not finish .*a\.mid"):
        render_midi(tmp_path / "a.mid", tmp_path / "a.wav", tmp_path / "gm.sf2")
    assert not (tmp_path / "a.wav").exists()


def test_dance_level_halves_fast_beats_and_doubles_slow_ones() -> None:
    from quaddance.layout import DANCE_TEMPO_BPM
    from quaddance.music.analysis import dance_level

    fast = np.arange(40) * 60.0 / 200.0  # 200 BPM
    strength = np.tile([1.0, 3.0], 20)  # the odd beats are the stronger
    np.testing.assert_allclose(dance_level(fast, strength), fast[1::2])  # 100 BPM
    slow = np.arange(10) * 60.0 / 50.0  # 50 BPM
    doubled = dance_level(slow, np.ones(10))
    np.testing.assert_allclose(np.diff(doubled), 0.6)  # 100 BPM
    inside = np.arange(20) * 60.0 / 175.0
    assert dance_level(inside, np.ones(20)) is inside
    for beats_s in (fast, slow, inside):
        bpm = 60.0 / np.median(np.diff(dance_level(beats_s, np.ones(len(beats_s)))))
        assert DANCE_TEMPO_BPM[0] <= bpm <= DANCE_TEMPO_BPM[1]


@pytest.mark.parametrize(("click_bpm", "level_bpm"), [(200.0, 100.0), (55.0, 110.0)])
def test_the_analyser_reports_a_level_inside_the_dance_range(click_bpm, level_bpm) -> None:
    # Click tracks outside the dance range: at 55 BPM the tempo search finds 55 (the search
    # reaches 50), and the beats are doubled into the range; at 200 it already prefers 100.
    y = np.zeros(int(20.0 * SR), dtype=np.float32)
    click = np.sin(2 * np.pi * 1000.0 * np.arange(220) / SR) * np.hanning(220)
    for t_s in np.arange(0.5, 19.5, 60.0 / click_bpm):
        i = int(t_s * SR)
        y[i : i + 220] += click.astype(np.float32)
    result = analyze(y, SR)
    assert result.tempo_bpm == pytest.approx(level_bpm, rel=0.02)
    assert np.all(np.diff(result.beats_s) >= 0.2)


def test_the_tempo_is_read_finer_than_the_frame_grid_of_the_beats() -> None:
    # 140 BPM beats on the envelope's frames: single intervals are 18 or 19 frames (143.6 or
    # 136.0 BPM); spans of 4 beats read the tempo within a quarter of a frame per beat.
    from quaddance.music.analysis import median_beat_period_s

    fps = SR / 512
    beats_s = np.round(np.arange(80) * 60.0 / 140.0 * fps) / fps
    assert 60.0 / np.median(np.diff(beats_s)) == pytest.approx(143.55, abs=0.01)
    assert 60.0 / median_beat_period_s(beats_s) == pytest.approx(140.0, rel=0.005)
    # A silent break (beats missing for 10 s) does not move it; two beats give their interval.
    gap = np.concatenate([beats_s[:40], beats_s[40:] + 10.0])
    assert 60.0 / median_beat_period_s(gap) == pytest.approx(140.0, rel=0.005)
    assert median_beat_period_s(np.array([1.0, 1.5])) == pytest.approx(0.5)


def test_a_click_track_reports_its_tempo_within_half_a_percent() -> None:
    y = np.zeros(int(30.0 * SR), dtype=np.float32)
    click = np.sin(2 * np.pi * 1000.0 * np.arange(220) / SR) * np.hanning(220)
    for t_s in np.arange(0.5, 29.5, 60.0 / 140.0):
        i = int(t_s * SR)
        y[i : i + 220] += click.astype(np.float32)
    assert analyze(y, SR).tempo_bpm == pytest.approx(140.0, rel=0.005)


@pytest.mark.parametrize("seed", [0, 1])
def test_beats_keep_their_phase_through_a_passage_of_louder_off_beats(seed: int) -> None:
    # 137 BPM kicks on the beat (18.9 envelope frames a beat); for 16 s in the middle the
    # kicks drop to half and a snare twice as loud plays each off-beat, then the song goes on
    # as before. The beats stay on the kicks, as a dancer keeps the step
    # (`AnalysisConfig.tightness`, `beat_steps_per_frame`): with beats on whole frames and a
    # tightness of 1000 they slid onto the snares and back (F 0.59 for both seeds).
    rng = np.random.default_rng(seed)
    y = np.zeros(int(40.0 * SR), dtype=np.float32)
    t = np.arange(int(0.15 * SR)) / SR
    kick = np.sin(2 * np.pi * 55.0 * t) * np.exp(-t / 0.05)
    kick += rng.standard_normal(len(t)) * np.exp(-t / 0.005)  # the beater's click
    snare = 0.5 * rng.standard_normal(len(t)) * np.exp(-t / 0.03)
    period_s = 60.0 / 137.0
    beats_s = np.arange(0.5, 39.5, period_s)
    for b in beats_s:
        passage = 12.0 <= b < 28.0
        i, j = int(b * SR), int((b + period_s / 2) * SR)
        y[i : i + len(t)] += (0.5 if passage else 1.0) * kick
        if passage:
            y[j : j + len(t)] += 2.0 * snare
    result = analyze(y, SR)
    assert beat_f_measure(beats_s, result.beats_s) >= 0.95
    inside = (result.beats_s >= 12.0) & (result.beats_s < 28.0)
    assert (
        beat_f_measure(beats_s[(beats_s >= 12.0) & (beats_s < 28.0)], result.beats_s[inside])
        >= 0.95
    )
