"""Decoding audio files into mono float32 arrays, with clear errors for unusable files."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quaddance.errors import InputFileError

DEFAULT_SR = 22050
"""Analysis sample rate, Hz (librosa's default: enough for beats, 2x cheaper than 44.1 kHz)."""

SUPPORTED_SUFFIXES = (".wav", ".flac", ".ogg", ".oga", ".mp3", ".aif", ".aiff")
"""File types we decode; libsndfile >= 1.1 (bundled with soundfile) reads all of them."""

SILENCE_PEAK = 1e-4
"""A file whose peak amplitude is below this (-80 dBFS) is treated as silent."""


def load_audio(
    path: str | Path, sr: int = DEFAULT_SR, min_duration_s: float = 2.0
) -> tuple[np.ndarray, int]:
    """Read an audio file, mix it to mono and resample it.

    Args:
        path: wav, flac, ogg or mp3 file.
        sr: sample rate of the result, Hz.
        min_duration_s: shorter files are refused, seconds (no beat grid fits in less).

    Returns:
        ``(y, sr)``: ``y`` is (n,) float32 samples in [-1, 1] at ``sr`` Hz.

    Raises:
        InputFileError: the file is missing, not a supported or decodable audio file, empty,
            silent or shorter than ``min_duration_s``.
    """
    import soundfile as sf

    path = Path(path)
    if not path.exists():
        raise InputFileError(path, "no such file")
    if path.is_dir():
        raise InputFileError(path, "is a directory, not an audio file")
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise InputFileError(
            path, f"unsupported file type '{suffix or '(none)'}'; use wav, flac, ogg or mp3"
        )
    if path.stat().st_size == 0:
        raise InputFileError(path, "is empty (0 bytes)")
    try:
        data, file_sr = sf.read(str(path), dtype="float32", always_2d=True)
    except (sf.LibsndfileError, RuntimeError, ValueError, OSError):
        y, file_sr = _load_with_librosa(path)
    else:
        y = data.mean(axis=1)
    if y.size == 0:
        raise InputFileError(path, "contains no audio samples")
    if not np.all(np.isfinite(y)):
        raise InputFileError(path, "contains invalid samples (NaN or infinity)")
    duration_s = y.size / file_sr
    if duration_s < min_duration_s:
        raise InputFileError(
            path, f"is too short: {duration_s:.2f} s of audio, at least {min_duration_s:g} s needed"
        )
    if float(np.max(np.abs(y))) < SILENCE_PEAK:
        raise InputFileError(path, "is silent (peak below -80 dBFS)")
    if file_sr != sr:
        import librosa

        y = librosa.resample(y, orig_sr=file_sr, target_sr=sr)
    return np.ascontiguousarray(y, dtype=np.float32), sr


def _load_with_librosa(path: Path) -> tuple[np.ndarray, int]:
    """Fallback decoder (audioread / ffmpeg through librosa) for files libsndfile refuses."""
    import warnings

    import librosa

    try:
        with warnings.catch_warnings():
            # librosa warns that it is falling back to audioread; the error below says enough.
            warnings.simplefilter("ignore")
            y, file_sr = librosa.load(str(path), sr=None, mono=True)
    except Exception as err:
        raise InputFileError(
            path, f"cannot be decoded: the file is corrupt or is not really {path.suffix} audio"
        ) from err
    return np.asarray(y, dtype=np.float32), int(file_sr)
