"""Decoding audio files into mono float32 arrays, with clear errors for unusable files, and
writing audio (`write_audio`).

Every number a file's header gives (sample rate, channels, length) is checked before it is
used, and decoding is bounded: a file longer than `MAX_SONG_S` is refused from its header
when the header says so, and otherwise as soon as decoding passes the limit. The file is
decoded in blocks that are mixed to mono and resampled as they arrive, so memory holds only
the result (`MAX_SONG_S` at `DEFAULT_SR`: 106 MB), whatever the file's rate and channels.

Sample values: NaN or infinity is refused. Float files may go past full scale (a float master
peaking at +6 dBFS is still music): if the decoded mono audio peaks above 1, it is divided by
its peak, so that analysis sees ordinary levels and the result lies in [-1, 1]. A peak above
`MAX_FLOAT_PEAK` (60 dB over full scale) is not audio but garbage, and is refused.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from quaddance.errors import InputFileError, OutputFileError, not_a_file

DEFAULT_SR = 22050
"""Analysis sample rate, Hz (librosa's default: enough for beats, 2x cheaper than 44.1 kHz)."""

SUPPORTED_SUFFIXES = (".wav", ".flac", ".ogg", ".oga", ".mp3", ".aif", ".aiff")
"""File types we decode; libsndfile >= 1.1 (bundled with soundfile) reads all of them."""

WRITABLE_SUFFIXES = (".wav", ".flac", ".ogg")
"""File types `write_audio` writes (libsndfile writes them with no extra codec)."""

SILENCE_PEAK = 1e-4
"""A file whose peak amplitude is below this (-80 dBFS) is treated as silent."""

MAX_SONG_S = 20 * 60.0
"""Longest song we dance to, s (20 minutes: a long DJ mix; `dance` runs it in ~2 minutes)."""

MIN_FILE_SR_HZ = 4000
"""Lowest sample rate accepted, Hz (below it only the bass is left; telephone audio is 8 kHz)."""

MAX_FILE_SR_HZ = 384_000
"""Highest sample rate accepted, Hz (the highest studio rate in use)."""

MAX_CHANNELS = 64
"""Most channels accepted (more than any surround or ambisonic music format)."""

MAX_FLOAT_PEAK = 1e3
"""Float samples beyond this magnitude (+60 dBFS) are refused as not audio."""

_BLOCK_FRAMES = 1 << 16
"""Frames decoded at a time (1.5 s at 44.1 kHz; <= 16 MB at `MAX_CHANNELS`)."""

_DECODE_ERRORS: tuple[type[BaseException], ...] = (RuntimeError, ValueError, OSError, EOFError)
"""What decoders raise for a corrupt file (soundfile's LibsndfileError is a RuntimeError)."""


def load_audio(
    path: str | Path,
    sr: int = DEFAULT_SR,
    min_duration_s: float = 2.0,
    max_duration_s: float = MAX_SONG_S,
) -> tuple[np.ndarray, int]:
    """Read an audio file, mix it to mono and resample it.

    Args:
        path: wav, flac, ogg or mp3 file.
        sr: sample rate of the result, Hz.
        min_duration_s: shorter files are refused, seconds (no beat grid fits in less).
        max_duration_s: longer files are refused before they are decoded in full, seconds.

    Returns:
        ``(y, sr)``: ``y`` is (n,) float32 samples in [-1, 1] at ``sr`` Hz.

    Raises:
        InputFileError: the file is missing, not a supported or decodable audio file, has an
            implausible header (sample rate, channels), is empty, silent, shorter than
            ``min_duration_s`` or longer than ``max_duration_s``, or holds NaN, infinite or
            absurdly large samples.
    """
    import soundfile as sf

    path = Path(path)
    if not path.is_file():
        raise not_a_file(path)
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise InputFileError(
            path, f"unsupported file type '{suffix or '(none)'}'; use wav, flac, ogg or mp3"
        )
    if path.stat().st_size == 0:
        raise InputFileError(path, "is empty (0 bytes)")
    try:
        info = sf.info(str(path))
    except _DECODE_ERRORS:
        file_sr, blocks = _open_with_audioread(path, max_duration_s)
    else:
        _check_header(path, info.samplerate, info.channels, info.frames, max_duration_s)
        file_sr, blocks = int(info.samplerate), _soundfile_blocks(path)
    return _decode(path, blocks, file_sr, sr, min_duration_s, max_duration_s), sr


def _check_header(
    path: Path, file_sr: float, channels: int, frames: float | None, max_duration_s: float
) -> None:
    """Refuse implausible header numbers, and a song too long, before decoding anything."""
    if not (np.isfinite(file_sr) and MIN_FILE_SR_HZ <= file_sr <= MAX_FILE_SR_HZ):
        raise InputFileError(
            path,
            f"sample rate {file_sr:g} Hz in the header is outside "
            f"{MIN_FILE_SR_HZ}-{MAX_FILE_SR_HZ} Hz; the file is corrupt",
        )
    if not 1 <= channels <= MAX_CHANNELS:
        raise InputFileError(
            path, f"{channels} channels in the header; between 1 and {MAX_CHANNELS} are accepted"
        )
    if frames is not None and np.isfinite(frames) and frames / file_sr > max_duration_s:
        raise InputFileError(path, _too_long(frames / file_sr, max_duration_s))


def _too_long(duration_s: float, max_duration_s: float) -> str:
    return (
        f"is too long: {duration_s / 60:.1f} min of audio, at most {max_duration_s / 60:g} min "
        "is danced (cut the song)"
    )


def _soundfile_blocks(path: Path) -> Iterator[np.ndarray]:
    """(frames, channels) float32 blocks from libsndfile, until the decoder has no more.

    Read until a read comes back empty, not for the frame count the header gives:
    ``soundfile.blocks`` trusts that count, and for a truncated mp3 it repeats the last block
    up to the length the header claims (a 0.15 s file read as 2 minutes)."""
    import soundfile as sf

    with sf.SoundFile(str(path)) as f:
        while True:
            block = f.read(_BLOCK_FRAMES, dtype="float32", always_2d=True)
            if len(block) == 0:
                return
            yield block


def _open_with_audioread(path: Path, max_duration_s: float) -> tuple[int, Iterator[np.ndarray]]:
    """Fallback decoder (audioread: ffmpeg or GStreamer) for files libsndfile refuses.

    Returns the file's sample rate and a generator of (frames, channels) float32 blocks.
    """
    problem = f"cannot be decoded: the file is corrupt or is not really {path.suffix} audio"
    try:
        import audioread

        reader = audioread.audio_open(str(path))
    except Exception as err:  # audioread's backends raise many unrelated types
        raise InputFileError(path, problem) from err
    try:
        duration_s = float(reader.duration or 0.0)
        file_sr, channels = int(reader.samplerate), int(reader.channels)
    except Exception as err:
        reader.close()
        raise InputFileError(path, problem) from err
    try:
        _check_header(path, file_sr, channels, duration_s * file_sr, max_duration_s)
    except InputFileError:
        reader.close()
        raise

    def blocks() -> Iterator[np.ndarray]:
        with reader:
            pending = b""
            for buf in reader:  # 16-bit native-endian interleaved PCM
                pending += bytes(buf)
                usable = len(pending) // (2 * channels) * (2 * channels)
                pcm = np.frombuffer(pending[:usable], dtype="<i2")
                pending = pending[usable:]
                yield (pcm.astype(np.float32) / 32768.0).reshape(-1, channels)

    return file_sr, blocks()


def _decode(
    path: Path,
    blocks: Iterator[np.ndarray],
    file_sr: int,
    sr: int,
    min_duration_s: float,
    max_duration_s: float,
) -> np.ndarray:
    """Mix ``blocks`` to mono and resample them to ``sr`` as they arrive; check every sample."""
    import soxr

    max_frames = int(max_duration_s * file_sr) + 1
    # soxr "HQ" is what librosa.resample(res_type="soxr_hq") uses, streamed here.
    stream = soxr.ResampleStream(file_sr, sr, 1, dtype="float32", quality="HQ")
    out: list[np.ndarray] = []
    frames, peak = 0, 0.0
    try:
        for block in blocks:
            if block.size == 0:
                continue
            if not np.all(np.isfinite(block)):
                raise InputFileError(path, "contains invalid samples (NaN or infinity)")
            block_peak = float(np.max(np.abs(block)))
            if block_peak > MAX_FLOAT_PEAK:
                raise InputFileError(
                    path,
                    f"contains samples of magnitude {block_peak:.3g}, far beyond full scale "
                    "(1.0); not audio",
                )
            peak = max(peak, block_peak)
            frames += block.shape[0]
            if frames > max_frames:
                raise InputFileError(path, _too_long(frames / file_sr, max_duration_s))
            mono = block.mean(axis=1, dtype=np.float32)
            out.append(mono if file_sr == sr else stream.resample_chunk(mono))
        if file_sr != sr:
            out.append(stream.resample_chunk(np.zeros(0, dtype=np.float32), last=True))
    except _DECODE_ERRORS as err:
        raise InputFileError(
            path, f"cannot be decoded: the file is corrupt or is not really {path.suffix} audio"
        ) from err
    if frames == 0:
        raise InputFileError(path, "contains no audio samples")
    duration_s = frames / file_sr
    if duration_s < min_duration_s:
        raise InputFileError(
            path, f"is too short: {duration_s:.2f} s of audio, at least {min_duration_s:g} s needed"
        )
    if peak < SILENCE_PEAK:
        raise InputFileError(path, "is silent (peak below -80 dBFS)")
    y = np.concatenate(out)
    out_peak = float(np.max(np.abs(y))) if y.size else 0.0
    if out_peak > 1.0:
        # A float master past full scale (or resampling overshoot on a full-scale file):
        # normalised, so that analysis sees ordinary levels and y stays in [-1, 1].
        y /= np.float32(out_peak)
    return np.ascontiguousarray(y, dtype=np.float32)


def check_audio_output(path: str | Path) -> Path:
    """``path`` checked as `quaddance.fileio.check_output_file` checks it, and for a suffix in
    `WRITABLE_SUFFIXES`; call it before the work that makes the audio.

    Raises:
        OutputFileError: the suffix is not one `write_audio` writes, or the path cannot be
            written.
    """
    from quaddance.fileio import check_output_file

    path = Path(path)
    if path.suffix.lower() not in WRITABLE_SUFFIXES:
        suffix = f"as {path.suffix}" if path.suffix else "with no suffix"
        raise OutputFileError(path, f"cannot write audio {suffix}: name it .wav, .flac or .ogg")
    return check_output_file(path)


def write_audio(path: str | Path, y: np.ndarray, sr: int) -> None:
    """Write (n,) samples in [-1, 1] at ``sr`` Hz to ``path`` atomically, in the format its
    suffix names (`WRITABLE_SUFFIXES`; `check_audio_output` says why not)."""
    import soundfile as sf

    from quaddance.fileio import atomic_path

    check_audio_output(path)
    with atomic_path(path) as tmp:
        sf.write(str(tmp), np.asarray(y, dtype=np.float32), sr)
