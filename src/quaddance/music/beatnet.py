"""A learned beat and downbeat activation, BeatNet's causal CRNNs: part of both beat trackers'
onset envelopes (`analysis.AnalysisConfig.beatnet_weight`, the song heard at several speeds;
`SpeedsActivationStream`, `online_beats.BEATNET_WEIGHT` and ``BEATNET_STRETCHES`` (once) for
the online one), and what the real-music benchmark's BeatNet tracker decodes
(``benchmarks/bar_hmm.py``).

BeatNet (Heydari, Cwitkowitz and Duan, "BeatNet: CRNN and particle filtering for online joint
beat downbeat and meter tracking", ISMIR 2021; https://github.com/mjhydri/BeatNet) is a small
network (about 400 k weights) trained on annotated real music (Ballroom, Beatles, Rock Corpus,
GTZAN...). Its weights are published under CC BY 4.0, which allows any use with attribution:
``data/beatnet/`` holds its three models (each trained with one data set left out), converted
from the PyPI wheel ``BeatNet==1.1.3`` into one ONNX graph that averages them (run by
onnxruntime) by ``scripts/fetch_beatnet.py``, with the licence beside it.

The network is causal (a one-directional LSTM): a song can be run at once or in pieces, its
state kept between them. The front end (numpy) reproduces madmom's features as BeatNet
computes them (``LOG_SPECT``: 22.05 kHz, 64 ms Hann frames every 20 ms, a 24-band-per-octave
triangular filterbank from 30 Hz to 17 kHz, log10(1 + x) and its positive first difference);
``tests/test_beat_activation.py`` checks both against numbers madmom and torch produced.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

SR_HZ = 22050
"""Sample rate of the network's input, Hz."""
HOP = 441
"""Samples between frames: 20 ms, 50 frames/s."""
FRAME = 1411
"""Samples per frame: 64 ms (``int(0.064 * SR_HZ)``, as BeatNet computes it)."""
FPS = SR_HZ / HOP
"""Activation frames per second (50)."""
BANDS_PER_OCTAVE = 24
FMIN_HZ, FMAX_HZ, FREF_HZ = 30.0, 17000.0, 440.0
WEIGHTS_DIR = Path(str(resources.files("quaddance") / "data" / "beatnet"))
"""Where the converted weights and their licence are (``scripts/fetch_beatnet.py``)."""
MODEL = "beatnet_ensemble.onnx"
"""BeatNet's three networks (trained with GTZAN, Ballroom and the Rock Corpus left out in turn)
side by side, their outputs averaged, as one ONNX graph (``scripts/fetch_beatnet.py``)."""
N_FEATURES = 272
"""Inputs of the network per frame: 136 log bands and their positive differences."""
STATE_SHAPE = (3, 2, 1, 150)
"""Recurrent state: (networks, LSTM layers, batch, cells)."""
_BLOCK_FRAMES = 1024
"""Frames transformed at a time (about 6 MB of spectra)."""


def _log_filterbank(n_fft_bins: int) -> np.ndarray:
    """(n_fft_bins, n_bands) madmom's ``LogarithmicFilterbank`` (unique, area-normalised,
    overlapping triangular filters on a 24-per-octave grid tuned to A440)."""
    bin_hz = np.fft.fftfreq(n_fft_bins * 2, 1.0 / SR_HZ)[:n_fft_bins]
    lo = np.floor(np.log2(FMIN_HZ / FREF_HZ) * BANDS_PER_OCTAVE)
    hi = np.ceil(np.log2(FMAX_HZ / FREF_HZ) * BANDS_PER_OCTAVE)
    freqs = FREF_HZ * 2.0 ** (np.arange(lo, hi) / BANDS_PER_OCTAVE)
    freqs = freqs[np.searchsorted(freqs, FMIN_HZ) :]
    freqs = freqs[: np.searchsorted(freqs, FMAX_HZ, "right")]
    # Nearest FFT bin of each frequency; low bands that share a bin count once.
    idx = np.clip(bin_hz.searchsorted(freqs), 1, n_fft_bins - 1)
    idx = idx - (freqs - bin_hz[idx - 1] < bin_hz[idx] - freqs)
    bins = np.unique(idx)
    bank = np.zeros((n_fft_bins, len(bins) - 2), dtype=np.float32)
    for band, (start, center, stop) in enumerate(zip(bins[:-2], bins[1:-1], bins[2:], strict=True)):
        if stop - start < 2:  # a filter too narrow for a triangle is one bin
            center, stop = start, start + 1
        tri = np.concatenate(
            [
                np.linspace(0.0, 1.0, center - start, endpoint=False),
                np.linspace(1.0, 0.0, stop - center, endpoint=False),
            ]
        )
        bank[start:stop, band] = np.maximum(bank[start:stop, band], tri / tri.sum())
    return bank


@functools.cache
def _front_end() -> tuple[np.ndarray, np.ndarray]:
    return np.hanning(FRAME).astype(np.float32), _log_filterbank(FRAME >> 1)


def log_spectrum(frames: np.ndarray) -> np.ndarray:
    """(n, n_bands) log10(1 + filtered magnitude) of (n, FRAME) audio frames."""
    import scipy.fft

    window, bank = _front_end()
    out = np.empty((len(frames), bank.shape[1]), dtype=np.float32)
    # Blocks of frames keep the windowed copies and spectra small, whatever the song's length.
    for i in range(0, len(frames), _BLOCK_FRAMES):
        spec = scipy.fft.rfft(frames[i : i + _BLOCK_FRAMES] * window, axis=-1)
        out[i : i + _BLOCK_FRAMES] = np.abs(spec[:, : FRAME >> 1]) @ bank
    return np.log10(1.0 + out)


def frame_audio(y: np.ndarray) -> np.ndarray:
    """(ceil(len / HOP), FRAME) frames of mono audio at SR_HZ, frame i centred on sample
    i * HOP, zeros outside the signal (madmom's ``FramedSignal``, origin at the centre)."""
    y = np.asarray(y, dtype=np.float32)
    n = -(-len(y) // HOP)
    # Frame i starts at sample i * HOP - FRAME // 2: at i * HOP once FRAME // 2 zeros lead.
    pad = np.concatenate([np.zeros(FRAME // 2, np.float32), y, np.zeros(FRAME, np.float32)])
    return np.lib.stride_tricks.sliding_window_view(pad, FRAME)[::HOP][:n]


def features(y: np.ndarray) -> np.ndarray:
    """(n, 2 * n_bands) the network's input for mono audio at SR_HZ: the log spectrum and its
    positive difference to the frame before (zero at the first frame)."""
    spec = log_spectrum(frame_audio(y))
    return with_onsets(spec, spec[:1])


def with_onsets(spec: np.ndarray, before: np.ndarray) -> np.ndarray:
    """(n, 2 * n_bands) the network's input: log spectra ``spec`` and their positive
    difference to the frame before (``before``, (1, n_bands), for the first)."""
    return np.hstack([spec, np.maximum(np.diff(spec, axis=0, prepend=before), 0.0)])


@functools.cache
def _session():
    import onnxruntime as ort

    opts = ort.SessionOptions()
    # One thread: the analysis runs beside the simulation, and a stream runs a few frames a block.
    opts.intra_op_num_threads = opts.inter_op_num_threads = 1
    return ort.InferenceSession(str(WEIGHTS_DIR / MODEL), opts, providers=["CPUExecutionProvider"])


class BeatActivation:
    """Causal beat and downbeat probabilities, frame by frame or for a whole song.

    ``run(features)`` runs a sequence on from the networks' current state and ``step(frame)``
    one frame; both return (..., 2): P(beat) (a beat that is not a downbeat) and P(downbeat),
    the mean over BeatNet's three networks of their softmax without its "no beat" class.
    """

    def __init__(self) -> None:
        self._session = _session()
        self.reset()

    def reset(self) -> None:
        self._h = np.zeros(STATE_SHAPE, np.float32)
        self._c = np.zeros(STATE_SHAPE, np.float32)

    def run(self, feats: np.ndarray) -> np.ndarray:
        feats = np.ascontiguousarray(feats, dtype=np.float32).reshape(-1, N_FEATURES)
        if len(feats) == 0:
            return np.zeros((0, 2), np.float32)
        probs, self._h, self._c = self._session.run(
            None, {"features": feats, "h0": self._h, "c0": self._c}
        )
        return probs

    def step(self, frame_features: np.ndarray) -> np.ndarray:
        return self.run(frame_features)[0]


def beat_activation(y: np.ndarray, sr: int, stretch: float = 1.0) -> np.ndarray:
    """(n, 2) P(beat), P(downbeat) at FPS frames/s (frame i at i / FPS seconds) of mono audio.

    Audio at another rate is resampled to SR_HZ first. With ``stretch`` != 1 the network hears
    the song played ``stretch`` times as long (its tempo divided by ``stretch``, its pitch moved
    with it, as a record played at another speed): frame i is then at i / (FPS * stretch)
    seconds of the song.
    """
    if sr != SR_HZ or stretch != 1.0:
        import soxr

        y = soxr.resample(np.asarray(y, dtype=np.float32), sr, SR_HZ * stretch, quality="HQ")
    return BeatActivation().run(features(y))


class BeatActivationStream:
    """`BeatActivation` over audio that arrives in blocks (the online tracker's): frame j spans
    the FRAME samples that end at sample (j + 1) * HOP (zeros before the stream's start), so
    it is computed as soon as its last sample arrives, never looking ahead."""

    def __init__(self) -> None:
        self._net = BeatActivation()
        self._audio = np.zeros(FRAME - HOP, np.float32)  # the window's past, then new samples
        self._prev_spec = np.zeros((1, _front_end()[1].shape[1]), np.float32)  # silence before
        self.samples = 0  # samples of the stream that ended a frame so far

    def push(self, samples: np.ndarray) -> np.ndarray:
        """Add mono samples at SR_HZ; return (m, 2) P(beat), P(downbeat) of the m frames they
        complete, frame k ending at sample ``samples_before + (k + 1) * HOP``."""
        self._audio = np.concatenate([self._audio, np.asarray(samples, np.float32)])
        m = (len(self._audio) - (FRAME - HOP)) // HOP
        if m == 0:
            return np.zeros((0, 2), np.float32)
        frames = np.lib.stride_tricks.sliding_window_view(self._audio, FRAME)[::HOP][:m]
        spec = log_spectrum(frames)
        feats = with_onsets(spec, self._prev_spec)
        self._prev_spec = spec[-1:]
        self._audio = self._audio[m * HOP :]
        self.samples += m * HOP
        return self._net.run(feats)


class SpeedsActivationStream:
    """`BeatActivationStream` heard at several speeds at once, averaged: what
    `beat_activation`'s ``stretch`` is to a whole song, for audio that arrives in blocks.

    Each speed ``s`` other than 1 is a causal resampler (soxr's stream, its output aligned to
    the input's time and about 20 ms behind it) into its own network: its frame j ends at
    sample ``(j + 1) * HOP / s`` of the stream. Each frame of the speed-1 stream (the clock:
    ``push`` returns its frames, as `BeatActivationStream` does) takes the mean of its own
    probabilities and, of every other speed, those of the newest frame that has ended by then.
    """

    def __init__(self, stretches: Sequence[float] = (1.0,)) -> None:
        if 1.0 not in stretches:
            raise ValueError(f"stretches must hold 1 (the clock), got {tuple(stretches)}")
        import soxr

        self._clock = BeatActivationStream()
        self._others = [
            _Stretched(s, soxr.ResampleStream(SR_HZ, SR_HZ * s, 1, dtype="float32"))
            for s in dict.fromkeys(stretches)
            if s != 1.0
        ]

    @property
    def samples(self) -> int:
        """Samples of the stream that ended a frame so far (of the speed-1 stream)."""
        return self._clock.samples

    def push(self, samples: np.ndarray) -> np.ndarray:
        """Add mono samples at SR_HZ; return (m, 2) P(beat), P(downbeat) of the m frames of
        the speed-1 stream they complete, averaged over the speeds (`BeatActivationStream.push`)."""
        samples = np.asarray(samples, np.float32)
        start = self._clock.samples
        probs = self._clock.push(samples)
        if not self._others:
            return probs
        ends = start + HOP * np.arange(1, len(probs) + 1)
        total, count = probs.astype(np.float64), np.ones((len(probs), 1))
        for other in self._others:
            got, count_one = other.push(samples, ends)
            total += got
            count += count_one
        return (total / count).astype(np.float32)


class _Stretched:
    """One speed of `SpeedsActivationStream`: its resampler, network and the frames not yet
    used, their end in samples of the unstretched stream."""

    def __init__(self, stretch: float, resampler: Any) -> None:
        self.stretch = stretch
        self.resampler = resampler
        self.net = BeatActivationStream()
        self.ends = np.zeros(0)
        self.probs = np.zeros((0, 2), np.float32)

    def push(self, samples: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Feed ``samples``; return, for each clock frame ending at ``ends``, the probabilities
        of this speed's newest frame ended by then (zeros before its first) and 1 where there
        is one (else 0)."""
        before = self.net.samples
        probs = self.net.push(self.resampler.resample_chunk(samples))
        frame_ends = (before + HOP * np.arange(1, len(probs) + 1)) / self.stretch
        self.ends = np.concatenate([self.ends, frame_ends])
        self.probs = np.vstack([self.probs, probs])
        latest = np.searchsorted(self.ends, ends, side="right") - 1
        has = latest >= 0
        got = np.zeros((len(ends), 2))
        got[has] = self.probs[latest[has]]
        if len(ends):
            # Frames before the newest one used are never needed again.
            keep = max(int(latest[-1]), 0)
            self.ends, self.probs = self.ends[keep:], self.probs[keep:]
        return got, has[:, None].astype(np.float64)
