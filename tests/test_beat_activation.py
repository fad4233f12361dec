"""The BeatNet tracker of the real-music benchmark: its activation (madmom's front end in
numpy, BeatNet's networks in ONNX) and its bar-pointer decoder.

The reference numbers in ``tests/data/beatnet_reference.npz`` were computed by madmom (the
features, with the processors BeatNet chains) and by torch's own layers loaded with BeatNet's
published weights (the activations), by ``scripts/beatnet_reference.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.bar_hmm import DecoderConfig, decode, state_space
from benchmarks.beats import beat_f_measure
from quaddance.music import beatnet as ba

REFERENCE = Path(__file__).parent / "data" / "beatnet_reference.npz"


@pytest.fixture(scope="module")
def reference() -> dict[str, np.ndarray]:
    with np.load(REFERENCE) as npz:
        return {k: npz[k] for k in npz.files}


def test_features_are_madmom_s(reference) -> None:
    feats = ba.features(reference["audio"])
    assert feats.shape == reference["features"].shape == (250, 272)
    np.testing.assert_allclose(feats, reference["features"], atol=1e-5)


def test_the_network_hears_the_beats_of_a_song(reference) -> None:
    act = ba.beat_activation(reference["audio"], ba.SR_HZ)
    frames = np.round(reference["beats_s"] * ba.FPS).astype(int)
    on_beat = act.sum(axis=1)[frames[frames < len(act)]]
    assert on_beat.mean() > 5.0 * act.sum(axis=1).mean() / 2.0


def test_the_ensemble_is_the_mean_of_its_networks(reference) -> None:
    act = ba.BeatActivation().run(reference["features"])
    mean = np.mean([reference[f"activation_{m}"] for m in (1, 2, 3)], axis=0)
    np.testing.assert_allclose(act, mean, atol=1e-4)


def test_frame_by_frame_is_the_whole_sequence_and_causal(reference) -> None:
    feats = reference["features"]
    whole = ba.BeatActivation().run(feats)
    stepper = ba.BeatActivation()
    steps = np.array([stepper.step(f) for f in feats])
    np.testing.assert_allclose(steps, whole, atol=1e-5)
    # The first half does not depend on what follows it.
    changed = feats.copy()
    changed[125:] = 0.0
    np.testing.assert_array_equal(ba.BeatActivation().run(changed)[:125], whole[:125])


def _streamed(y: np.ndarray, seed: int) -> np.ndarray:
    """`BeatActivationStream` fed ``y`` in blocks of random sizes."""
    rng, stream, parts, i = np.random.default_rng(seed), ba.BeatActivationStream(), [], 0
    while i < len(y):
        k = int(rng.integers(1, 3000))
        parts.append(stream.push(y[i : i + k]))
        i += k
    assert stream.samples == len(y) // ba.HOP * ba.HOP
    return np.concatenate(parts)


def test_a_stream_is_the_same_in_any_blocks_and_never_looks_ahead(reference) -> None:
    y = reference["audio"]
    act = _streamed(y, seed=0)
    assert act.shape == (len(y) // ba.HOP, 2)
    np.testing.assert_allclose(_streamed(y, seed=1), act, atol=1e-5)
    # Frame j ends at sample (j + 1) * HOP: changing the audio after it changes no frame up to j.
    cut = 100 * ba.HOP
    changed = y.copy()
    changed[cut:] = 0.0
    np.testing.assert_allclose(_streamed(changed, seed=2)[:100], act[:100], atol=1e-5)
    assert np.abs(_streamed(changed, seed=2)[100:] - act[100:]).max() > 0.1


def test_a_stream_hears_the_beats_as_they_end(reference) -> None:
    act = _streamed(reference["audio"], seed=0).sum(axis=1)
    # A frame hears a beat once its window, which ends at the frame's end, holds it: at most
    # 2 frames (40 ms) after the beat.
    beats = reference["beats_s"][reference["beats_s"] * ba.FPS < len(act) - 3]
    lags = np.array([np.argmax(act[round(t * ba.FPS) : round(t * ba.FPS) + 6]) for t in beats])
    on_beat = np.array([act[round(t * ba.FPS) + lag] for t, lag in zip(beats, lags, strict=True)])
    assert on_beat.mean() > 5.0 * act.mean() / 2.0
    assert np.median(lags) <= 2


def test_other_sample_rates_are_resampled(reference) -> None:
    import soxr

    y = reference["audio"]
    y44 = soxr.resample(y, ba.SR_HZ, 44100, quality="HQ")
    a22, a44 = ba.beat_activation(y, ba.SR_HZ), ba.beat_activation(y44, 44100)
    n = min(len(a22), len(a44))
    # Resampling twice takes the top of the band: the same activation, but not to the digit.
    assert np.abs(a44[:n] - a22[:n]).mean() < 0.02
    assert np.corrcoef(a44[:n].sum(axis=1), a22[:n].sum(axis=1))[0, 1] > 0.95


def test_the_weights_ship_with_their_licence_and_attribution() -> None:
    data = ba.WEIGHTS_DIR
    assert "Attribution 4.0 International" in (data / "LICENSE.txt").read_text()
    attribution = (data / "ATTRIBUTION.txt").read_text()
    assert "BeatNet==1.1.3" in attribution and "CC BY 4.0" in attribution
    import onnx

    graph = onnx.load(str(data / ba.MODEL)).graph
    assert [i.name for i in graph.input] == ["features", "h0", "c0"]
    assert sum(node.op_type == "LSTM" for node in graph.node) == 3 * 2  # 3 nets, 2 layers


# --- the decoder ------------------------------------------------------------------------------


def _activation(beats_s: np.ndarray, beats_per_bar: int, n: int, fps: float = 50.0):
    """A clean activation: a beat (or downbeat) peak two frames wide at each beat."""
    act = np.full((n, 2), 0.01)
    for i, t in enumerate(beats_s):
        f = round(t * fps)
        col = 1 if i % beats_per_bar == 0 else 0
        for d, p in ((0, 0.9), (1, 0.4)):
            if f + d < n:
                act[f + d, col] = p
    return act


@pytest.mark.parametrize("beats_per_bar", [3, 4])
def test_decoder_finds_the_beats_bars_and_meter(beats_per_bar: int) -> None:
    beats_s = np.arange(0.5, 29.0, 60.0 / 100.0)
    act = _activation(beats_s, beats_per_bar, round(beats_s[-1] * 50) + 5)
    out = decode(act, 50.0)
    found_s = out.beat_frames / 50.0
    assert out.beats_per_bar == beats_per_bar
    assert beat_f_measure(beats_s, found_s) > 0.97
    # Each beat found is on a true beat, within a frame.
    assert np.abs(found_s[:, None] - beats_s[None, :]).min(axis=1).max() < 0.02
    assert beat_f_measure(beats_s[::beats_per_bar], found_s[out.downbeat]) > 0.95


def test_decoder_follows_a_tempo_change() -> None:
    slow = np.arange(0.4, 15.0, 0.6)  # 100 BPM
    fast = slow[-1] + np.arange(1, 30) * 0.5  # then 120 BPM
    beats_s = np.concatenate([slow, fast])
    act = _activation(beats_s, 4, int(beats_s[-1] * 50) + 30)
    found_s = decode(act, 50.0).beat_frames / 50.0
    assert beat_f_measure(beats_s, found_s) > 0.97


def test_decoder_picks_a_level_inside_its_range() -> None:
    # 240 BPM, above the range, in bars of 4 beats at half that tempo.
    cfg = DecoderConfig()
    beats_s = np.arange(0.3, 20.0, 60.0 / 240.0)
    found_s = decode(_activation(beats_s, 8, 1000), 50.0, cfg).beat_frames / 50.0
    bpm = 60.0 / np.median(np.diff(found_s))
    assert cfg.min_bpm <= bpm <= cfg.max_bpm
    assert bpm == pytest.approx(120.0, rel=0.03)


def test_state_space_transitions_only_at_beat_starts() -> None:
    space = state_space(50.0, DecoderConfig())
    inner = np.setdiff1d(np.arange(space.n_states), space.beat_start)
    # Inside a beat a state comes from the one before it, at the same tempo.
    assert np.all(space.interval[space.prev[inner]] == space.interval[inner])
    assert np.all(space.position[inner] == space.position[space.prev[inner]] + 1)
    # A beat start comes from the last frame of the beat before, at any tempo.
    ends = space.beat_start_from.ravel()
    nxt = (space.position[ends] + 1) % space.interval[ends]
    assert np.all(nxt == 0)
    # Keeping the tempo is the likeliest way into each beat start.
    own = np.searchsorted(space.intervals, space.block_interval[space.beat_start_block])
    assert np.all(np.argmax(space.log_trans, axis=1) == own)


def test_the_real_music_bench_scores_the_beatnet_tracker(reference, tmp_path: Path) -> None:
    import soundfile as sf

    from benchmarks.real_music import RealSong, report_md, score_song, song_means

    path = tmp_path / "song.wav"
    sf.write(path, reference["audio"], ba.SR_HZ)
    beats_s = reference["beats_s"]
    song = RealSong(
        name="s", title="t", artist="a", split="heldout", kind="recording", audio_path=path,
        beats_s=beats_s, downbeats_s=beats_s[::4], tempo_bpm=(120.0, 120.0), meter="4/4",
        licence="CC-BY-SA-3.0", duration_s=len(reference["audio"]) / ba.SR_HZ,
    )  # fmt: skip
    row = score_song(song)
    assert row["f_metrical_beatnet"] >= 0.9 and row["tempo_ok_beatnet"]
    mean = song_means([row])
    assert mean["f_beatnet"] == row["f_beatnet"] and mean["tempo_ok_beatnet"] == 1
    results = {"command": "c", "set": "s", "metric": "m", "means": {"heldout": mean},
               "songs": [row]}  # fmt: skip
    text = report_md(results)
    assert "| BeatNet's CRNNs (CC BY 4.0) + bar-pointer HMM |" in text
    assert "weights CC BY 4.0, converted by `scripts/fetch_beatnet.py`" in text


# --- where the trackers use it ----------------------------------------------------------------


def test_the_analyser_mixes_beatnet_into_its_envelopes_only_when_asked(
    reference, monkeypatch: pytest.MonkeyPatch
) -> None:
    from quaddance.music import analysis

    y = reference["audio"]
    once = analysis._features(y, ba.SR_HZ, analysis.AnalysisConfig(beatnet_stretches=(1.0,)))
    assert once.beatnet.shape == (len(once.raw_onset), 2)
    # Heard once, the activation at the onset frames is BeatNet's own, read at the same times.
    own = ba.beat_activation(y, ba.SR_HZ)
    at = np.round(np.arange(len(once.raw_onset)) / once.fps * ba.FPS).astype(int)
    inside = at < len(own)
    assert np.corrcoef(once.beatnet[inside, 0], own[at[inside], 0])[0, 1] > 0.95
    # By default it is heard at several speeds: another activation, still on the same beats.
    on = analysis._features(y, ba.SR_HZ, analysis.AnalysisConfig())
    assert len(analysis.AnalysisConfig().beatnet_stretches) > 1
    assert on.beatnet.shape == once.beatnet.shape
    assert not np.allclose(on.beatnet, once.beatnet, atol=1e-3)
    assert np.corrcoef(on.beatnet[:, 0], once.beatnet[:, 0])[0, 1] > 0.8

    def no_network(*args: object) -> None:
        raise AssertionError("BeatNet ran with beatnet_weight = 0")

    monkeypatch.setattr(ba, "beat_activation", no_network)
    off = analysis._features(y, ba.SR_HZ, analysis.AnalysisConfig(beatnet_weight=0.0))
    assert off.beatnet.shape == (len(off.raw_onset), 0)
    assert not np.allclose(off.beat_onset, on.beat_onset)


@pytest.mark.parametrize("stretch", [0.9, 1.1])
def test_a_song_heard_faster_or_slower_maps_back_onto_its_own_time(reference, stretch) -> None:
    from quaddance.music import analysis

    y, fps = reference["audio"], 100.0
    n = round(len(y) / ba.SR_HZ * fps)
    once = analysis._beatnet_frames(y, ba.SR_HZ, n, fps, (1.0,))[:, 0]
    heard = analysis._beatnet_frames(y, ba.SR_HZ, n, fps, (stretch,))[:, 0]
    # The stretched copy is 0.5 s longer or shorter over these 5 s: read back at the wrong
    # rate, its peaks would drift off the song's beats by up to 50 frames here.
    lags = np.arange(-10, 11)
    corr = [np.corrcoef(np.roll(heard, lag)[20:-20], once[20:-20])[0, 1] for lag in lags]
    assert abs(lags[int(np.argmax(corr))]) <= 2
    assert max(corr) > 0.7
    beats = np.round(reference["beats_s"] * fps).astype(int)
    beats = beats[beats < n]
    assert heard[beats].mean() > 3.0 * heard.mean()


def test_the_online_front_end_reads_beatnet_causally_in_any_blocks(reference) -> None:
    from quaddance.music import online_beats

    y = reference["audio"]

    def learned(block: int) -> np.ndarray:
        feats = online_beats._Features()
        spectra = [s for i in range(0, len(y), block) for s in feats.push(y[i : i + block])]
        return np.array([(s.learned, s.learned_down) for s in spectra])

    one = learned(len(y))
    assert one.shape == (len(y) // online_beats.HOP, 2)
    np.testing.assert_allclose(learned(100), one, atol=1e-5)
    np.testing.assert_allclose(learned(4096), one, atol=1e-5)
    # Onset frame i (ending at sample (i + 1) * 256) holds BeatNet's newest frame that has
    # ended by then: frame j ends at (j + 1) * 441.
    stream = ba.BeatActivationStream().push(y)
    j = (np.arange(len(one)) + 1) * online_beats.HOP // ba.HOP - 1
    expected = np.where(j[:, None] >= 0, stream[np.maximum(j, 0)], 0.0)
    np.testing.assert_allclose(one[:, 0], expected.sum(axis=1), atol=1e-5)
    np.testing.assert_allclose(one[:, 1], expected[:, 1], atol=1e-5)


def test_a_stream_heard_once_is_the_plain_stream(reference) -> None:
    y = reference["audio"]
    speeds = ba.SpeedsActivationStream((1.0,))
    np.testing.assert_array_equal(speeds.push(y), ba.BeatActivationStream().push(y))
    assert speeds.samples == len(y) // ba.HOP * ba.HOP
    with pytest.raises(ValueError, match="must hold 1"):
        ba.SpeedsActivationStream((0.9, 1.1))


@pytest.mark.parametrize("stretch", [0.9, 1.1])
def test_a_stream_heard_faster_or_slower_maps_back_onto_its_own_time(reference, stretch) -> None:
    y = reference["audio"]
    speeds = ba.SpeedsActivationStream((1.0, stretch))
    mixed = np.concatenate([speeds.push(y[i : i + 2205]) for i in range(0, len(y), 2205)])
    once = ba.BeatActivationStream().push(y)
    assert mixed.shape == once.shape
    # The mean of two: what the stretched stream gave each frame. Read back at the wrong rate,
    # its peaks would drift off the song's by up to 25 frames over these 5 s; read right, they
    # come with the song's or a frame or two after (the resampler's delay, the newest frame).
    heard = (2.0 * mixed - once)[:, 0]
    lags = np.arange(-10, 11)
    corr = [np.corrcoef(np.roll(heard, lag)[20:-20], once[20:-20, 0])[0, 1] for lag in lags]
    assert -2 <= lags[int(np.argmax(corr))] <= 0
    assert max(corr) > 0.7
