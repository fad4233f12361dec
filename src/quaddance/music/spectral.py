"""Spectral building blocks of the two analysers, without importing librosa on the way.

Importing librosa (numba, scipy.signal) costs 2.5-3 s of CPU, which was almost all of the
song analysis in `dance`'s helper process, and that process is on the command's critical path
on 2 cores (measured: 3.3 s CPU for a 12 s song, 0.1 s of it the analysis itself). So:

- The filter banks, librosa's own, depend only on (sr, n_fft, n_mels). Those the analysers
  use are computed by librosa once (`write_filterbanks`) and ship in ``data/filterbanks.npz``;
  a test checks them against librosa, so a new librosa cannot leave them stale. Any other
  shape is computed by librosa when asked for.
- The STFT magnitude, the dB scaling, the peak normalisation and the RMS are the few numpy
  lines of the librosa functions of the same names, with the same defaults; the tests check
  them against librosa too.
"""

from __future__ import annotations

import contextlib
import functools
import zipfile
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

SHIPPED = ((22050, 2048, 96), (22050, 1024, 64))
"""(sr, n_fft, n_mels) of the filter banks in ``data/filterbanks.npz``: the offline analyser's
(`analysis.AnalysisConfig`) and the online tracker's (`online_beats`)."""

_FIELDS = ("mel", "mel_hz", "chroma")
_BLOCK_FRAMES = 1024
"""STFT frames transformed at a time: about 33 MB of float64 windows and spectra at n_fft
2048, whatever the song's length."""


@dataclass(frozen=True)
class FilterBanks:
    """librosa's filter banks for one (sr, n_fft, n_mels), in the types librosa returns."""

    mel: np.ndarray
    """(n_mels, 1 + n_fft // 2) ``librosa.filters.mel(sr=sr, n_fft=n_fft, n_mels=n_mels,
    fmax=sr / 2)`` (Slaney mel scale and area normalisation)."""
    mel_hz: np.ndarray
    """(n_mels,) centre frequency of each mel band, Hz: ``librosa.mel_frequencies(n_mels +
    2, fmax=sr / 2)[1:-1]``."""
    chroma: np.ndarray
    """(12, 1 + n_fft // 2) ``librosa.filters.chroma(sr=sr, n_fft=n_fft, tuning=0.0)``: A440
    assumed (estimating the tuning is a third of the analysis time; chroma only tells chords
    apart)."""
    freqs_hz: np.ndarray
    """(1 + n_fft // 2,) centre frequency of each STFT bin, Hz."""


def _key(sr: int, n_fft: int, n_mels: int) -> str:
    return f"{sr}_{n_fft}_{n_mels}"


def _librosa_banks(sr: int, n_fft: int, n_mels: int) -> dict[str, np.ndarray]:
    import librosa

    return {
        "mel": librosa.filters.mel(sr=sr, n_fft=n_fft, n_mels=n_mels, fmax=sr / 2),
        "mel_hz": librosa.mel_frequencies(n_mels=n_mels + 2, fmax=sr / 2)[1:-1],
        "chroma": librosa.filters.chroma(sr=sr, n_fft=n_fft, tuning=0.0),
    }


def _shipped_path() -> Path:
    return Path(str(resources.files("quaddance") / "data" / "filterbanks.npz"))


@functools.lru_cache(maxsize=8)
def filterbanks(sr: int, n_fft: int, n_mels: int) -> FilterBanks:
    """librosa's mel and chroma filter banks for this shape: from the shipped file where it
    has them, else from librosa."""
    key = _key(sr, n_fft, n_mels)
    banks = None
    if (int(sr), int(n_fft), int(n_mels)) in SHIPPED:
        # Our own file, written by `write_filterbanks`; never a user's, and never pickled. An
        # install that lost or damaged it still works, at librosa's import cost.
        with (
            contextlib.suppress(OSError, ValueError, KeyError, zipfile.BadZipFile),
            np.load(_shipped_path(), allow_pickle=False) as f,
        ):
            banks = {name: f[f"{key}/{name}"] for name in _FIELDS}
    if banks is None:
        banks = _librosa_banks(sr, n_fft, n_mels)
    freqs_hz = np.fft.rfftfreq(n_fft, 1.0 / sr)  # what librosa.fft_frequencies computes
    for array in (*banks.values(), freqs_hz):
        array.setflags(write=False)  # shared by every caller through the cache
    return FilterBanks(freqs_hz=freqs_hz, **banks)


def write_filterbanks(path: str | Path | None = None) -> Path:
    """Compute the `SHIPPED` filter banks with librosa and write them (atomically) to
    ``path``, by default the package's ``data/filterbanks.npz``."""
    from quaddance.fileio import atomic_path

    path = Path(path) if path is not None else _shipped_path()
    arrays = {
        f"{_key(*shape)}/{name}": value
        for shape in SHIPPED
        for name, value in _librosa_banks(*shape).items()
    }
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)
    return path


def stft_magnitude(y: np.ndarray, n_fft: int, hop_length: int) -> np.ndarray:
    """(1 + n_fft // 2, frames) ``np.abs(librosa.stft(y, n_fft=n_fft, hop_length=hop_length))``
    with librosa's defaults: periodic Hann window of n_fft, frames centred on multiples of
    ``hop_length`` (``n_fft // 2`` zeros padded at both ends), in ``y``'s float precision."""
    y = np.asarray(y)
    if not np.issubdtype(y.dtype, np.floating):
        y = y.astype(np.float32)
    pad = n_fft // 2
    padded = np.concatenate([np.zeros(pad, y.dtype), y, np.zeros(pad, y.dtype)])
    n_frames = 1 + (len(padded) - n_fft) // hop_length
    if n_frames < 1:
        raise ValueError(f"{len(y)} samples are too few for an STFT of {n_fft}")
    frames = np.lib.stride_tricks.sliding_window_view(padded, n_fft)[::hop_length][:n_frames]
    # Periodic Hann (scipy.signal.get_window("hann", n_fft, fftbins=True)), in float64 as
    # librosa's: the frames are windowed and transformed in float64, then stored in y's type.
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n_fft) / n_fft)
    out = np.empty((1 + n_fft // 2, n_frames), dtype=y.dtype)
    for start in range(0, n_frames, _BLOCK_FRAMES):
        block = frames[start : start + _BLOCK_FRAMES] * window
        out[:, start : start + len(block)] = np.abs(np.fft.rfft(block, axis=1)).T
    return out


def power_to_db(power: np.ndarray, top_db: float = 80.0, amin: float = 1e-10) -> np.ndarray:
    """``librosa.power_to_db(power, ref=np.max, top_db=top_db)``: dB relative to the peak,
    nothing below ``top_db`` under it."""
    power = np.asarray(power)
    log_spec = 10.0 * np.log10(np.maximum(amin, power))
    log_spec -= 10.0 * np.log10(max(amin, float(power.max())))
    return np.maximum(log_spec, log_spec.max() - top_db)


def normalize_peak(x: np.ndarray, axis: int = 0) -> np.ndarray:
    """``librosa.util.normalize(x, norm=np.inf, axis=axis)``: each slice along ``axis``
    divided by its largest magnitude; all-zero (or subnormal) slices are left as they are."""
    x = np.asarray(x)
    length = np.max(np.abs(x), axis=axis, keepdims=True)
    length[length < np.finfo(x.dtype).tiny] = 1.0
    return x / length


def rms_from_stft(stft: np.ndarray, n_fft: int) -> np.ndarray:
    """(frames,) RMS of each frame from its magnitude spectrum (n_fft // 2 + 1, frames), as
    ``librosa.feature.rms(S=stft, frame_length=n_fft)[0]`` computes it (Parseval, the DC and
    Nyquist bins counted once)."""
    power = np.abs(stft) ** 2  # a copy, in the spectrum's own precision as librosa's
    power[0] *= 0.5
    if n_fft % 2 == 0:
        power[-1] *= 0.5
    return np.sqrt(2.0 * power.sum(axis=0) / n_fft**2)
