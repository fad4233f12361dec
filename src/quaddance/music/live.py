"""Live audio sources for ``quaddance live``: a file played at real-time pace, or a microphone.

Both yield ``AudioBlock``s: mono float32 samples at the tracker's rate (``SR_HZ``) with their
song time, the seconds of audio since the source started. A block is yielded only once all its
samples have "happened": ``FileSource`` waits for the wall clock (it is never faster than real
time, so the analysis sees only the audio up to now), ``MicSource`` hands over what the sound
card has recorded.

sounddevice (PortAudio) is imported only when a microphone is opened: where the PortAudio
library or an input device is missing, ``MicSource`` raises one ``QuaddanceError`` line.

`track_file` and `track_samples` run the online beat tracker over a whole recording as fast as
the CPU allows, block by block exactly as ``live`` feeds it (``quaddance analyze --online``,
the benchmarks and the tests use them).
"""

from __future__ import annotations

import dataclasses
import queue
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.music.analysis import median_beat_period_s
from quaddance.music.online_beats import (
    BLOCK_S,
    SR_HZ,
    BeatEvent,
    OnlineBeatTracker,
    TrackerState,
)

MIC_STALL_S = 2.0
"""A microphone that delivers nothing for this long has stopped: an error, not a hang."""

MIC_QUEUE_BLOCKS = 512
"""Blocks the microphone may queue (about 6 s at the default block) before dropping audio."""


@dataclass(frozen=True)
class AudioBlock:
    """Mono audio with its song time.

    Attributes:
        samples: (n,) float32 samples at ``sr_hz``.
        t_start_s: song time of the first sample, seconds.
        sr_hz: sample rate, Hz.
    """

    samples: np.ndarray
    t_start_s: float
    sr_hz: int

    @property
    def t_end_s(self) -> float:
        """Song time just after the last sample, seconds."""
        return self.t_start_s + len(self.samples) / self.sr_hz


class ArraySource:
    """Audio already in memory, cut into blocks; paced by the wall clock when ``realtime``.

    Args:
        y: (n,) mono samples.
        sr_hz: their sample rate, Hz.
        block_s: block length, seconds (rounded to whole samples).
        realtime: wait until each block's last sample is due on the wall clock (never faster
            than real time); False yields as fast as the caller takes them (tests, benchmarks).
    """

    def __init__(
        self, y: np.ndarray, sr_hz: int, block_s: float = BLOCK_S, realtime: bool = False
    ) -> None:
        if block_s <= 0:
            raise QuaddanceError(f"audio block length must be > 0 s, got {block_s}")
        self.y = np.ascontiguousarray(y, dtype=np.float32).reshape(-1)
        self.sr_hz = int(sr_hz)
        self.block_len = max(1, round(block_s * sr_hz))
        self.realtime = realtime

    @property
    def duration_s(self) -> float:
        return len(self.y) / self.sr_hz

    def __iter__(self) -> Iterator[AudioBlock]:
        start_wall_s = time.monotonic()
        for i in range(0, len(self.y), self.block_len):
            block = AudioBlock(self.y[i : i + self.block_len], i / self.sr_hz, self.sr_hz)
            if self.realtime:
                # The block exists only once its last sample has played.
                wait_s = start_wall_s + block.t_end_s - time.monotonic()
                if wait_s > 0:
                    time.sleep(wait_s)
            yield block


class FileSource(ArraySource):
    """An audio file played through the live path at real-time pace.

    Decoded by ``load_audio`` (same checks and one-line errors as every other command) at the
    tracker's rate, then cut into blocks.

    Args:
        path: wav, flac, ogg or mp3 file.
        block_s: block length, seconds.
        realtime: pace blocks by the wall clock; False is for tests and benchmarks only.
        start_s: play from this far into the file, seconds (music already playing, as a
            microphone in a room hears it); song time 0 is there.

    Raises:
        InputFileError: the file cannot be read, or ``start_s`` is not within it.
    """

    def __init__(
        self,
        path: str | Path,
        block_s: float = BLOCK_S,
        realtime: bool = True,
        start_s: float = 0.0,
    ) -> None:
        from quaddance.errors import InputFileError
        from quaddance.music.audio import load_audio

        self.path = Path(path)
        y, sr = load_audio(path, sr=SR_HZ)
        first = round(start_s * sr) if np.isfinite(start_s) else -1
        if not 0 <= first < len(y):
            raise InputFileError(
                path, f"--start {start_s:g} s is not within the song (0 to {len(y) / sr:.1f} s)"
            )
        self.start_s = first / sr
        super().__init__(y[first:], sr, block_s=block_s, realtime=realtime)


@dataclass(frozen=True)
class OnlineTrack:
    """What the online tracker reported over a whole recording.

    Attributes:
        beats: the beat events in the order reported (before and after the lock).
        block_end_s: (n_blocks,) song time of the end of each block fed, seconds.
        locked: (n_blocks,) whether the tracker was locked after each block.
        tempo_bpm: (n_blocks,) its tempo after each block, BPM (0 before any estimate).
        final: its state after the last block.
        tracker_s: wall-clock seconds spent inside the tracker (decoding not counted).
        source: the file tracked ("" for samples).
    """

    beats: tuple[BeatEvent, ...]
    block_end_s: np.ndarray
    locked: np.ndarray
    tempo_bpm: np.ndarray
    final: TrackerState
    tracker_s: float
    source: str = ""

    @property
    def beats_s(self) -> np.ndarray:
        """(n,) times of the beats, song seconds."""
        return np.array([b.time_s for b in self.beats], dtype=np.float64)

    @property
    def downbeats_s(self) -> np.ndarray:
        """(n,) times of the beats reported as downbeats, song seconds."""
        return np.array([b.time_s for b in self.beats if b.downbeat], dtype=np.float64)

    def first_lock_s(self, after_s: float = 0.0) -> float | None:
        """Song time of the end of the first block at or after ``after_s`` after which the
        tracker was locked, seconds; None if it never was."""
        found = np.flatnonzero(self.locked & (self.block_end_s >= after_s))
        return float(self.block_end_s[found[0]]) if found.size else None

    @property
    def locked_tempo_bpm(self) -> float:
        """Tempo from the median period of the beats after the first lock, as ``analyze``
        takes its tempo from its beats (`analysis.median_beat_period_s`), BPM; 0 without a
        lock."""
        lock_s = self.first_lock_s()
        after = self.beats_s[self.beats_s >= lock_s] if lock_s is not None else np.zeros(0)
        return 60.0 / median_beat_period_s(after) if after.size >= 2 else 0.0

    def to_json_dict(self) -> dict[str, Any]:
        """The keys of ``analyze``'s JSON that an online tracker has (``tempo_bpm``:
        `locked_tempo_bpm`) and ``lock_s`` (`first_lock_s`, null without a lock); times
        rounded to 0.1 ms, as ``analyze`` writes them."""
        lock_s = self.first_lock_s()
        return {
            "tempo_bpm": round(self.locked_tempo_bpm, 3),
            "beats_s": [round(float(t), 4) for t in self.beats_s],
            "downbeats_s": [round(float(t), 4) for t in self.downbeats_s],
            "lock_s": None if lock_s is None else round(lock_s, 4),
            "duration_s": round(float(self.block_end_s[-1]) if self.block_end_s.size else 0.0, 4),
            "source": self.source,
        }

    def save_json(self, path: str | Path) -> None:
        """Write `to_json_dict` as JSON, atomically."""
        from quaddance.fileio import write_json

        write_json(path, self.to_json_dict())

    def summary(self) -> str:
        """One line for a person: tempo, beats and the lock."""
        lock_s = self.first_lock_s()
        lock = "no lock" if lock_s is None else f"locked at {lock_s:.2f} s"
        return f"tempo {self.locked_tempo_bpm:.1f} BPM, {len(self.beats)} beats, {lock}"


def track_samples(
    y: np.ndarray, sr_hz: int = SR_HZ, song_start: bool = True, block_s: float = BLOCK_S
) -> OnlineTrack:
    """Run the online beat tracker over ``y`` block by block, as ``live`` feeds it, without
    waiting for the wall clock.

    Args:
        y: (n,) mono samples at ``sr_hz``, which must be the tracker's ``SR_HZ``.
        sr_hz: their sample rate, Hz.
        song_start: the tracker's (False: the music may already be playing, as heard by a
            microphone or from a file started part-way).
        block_s: block length, seconds.
    """
    tracker = OnlineBeatTracker(sr_hz, song_start=song_start)
    beats: list[BeatEvent] = []
    end_s: list[float] = []
    locked: list[bool] = []
    tempo_bpm: list[float] = []
    tracker_s = 0.0
    for block in ArraySource(y, sr_hz, block_s=block_s):
        t0 = time.perf_counter()
        beats += tracker.update(block.samples, block.t_end_s)
        tracker_s += time.perf_counter() - t0
        state = tracker.state
        end_s.append(block.t_end_s)
        locked.append(state.locked)
        tempo_bpm.append(state.tempo_bpm)
    return OnlineTrack(
        tuple(beats),
        np.asarray(end_s, dtype=np.float64),
        np.asarray(locked, dtype=bool),
        np.asarray(tempo_bpm, dtype=np.float64),
        tracker.state,
        tracker_s,
    )


def track_file(path: str | Path, start_s: float = 0.0, block_s: float = BLOCK_S) -> OnlineTrack:
    """`track_samples` of an audio file decoded as `FileSource` decodes it, from ``start_s``
    on (song time 0 there; the tracker is told the music may already be playing when
    ``start_s`` > 0, as ``live --from-file --start`` tells it).

    Raises:
        InputFileError: the file cannot be read, or ``start_s`` is not within it.
    """
    source = FileSource(path, block_s=block_s, realtime=False, start_s=start_s)
    track = track_samples(source.y, source.sr_hz, song_start=start_s == 0, block_s=block_s)
    return dataclasses.replace(track, source=str(path))


def _import_sounddevice() -> Any:
    """sounddevice, or one line saying why there is no audio input."""
    try:
        import sounddevice
    except OSError as err:  # raised at import when the PortAudio library is missing
        raise QuaddanceError(
            f"no audio input device: PortAudio is not installed ({err}); "
            "install it with apt-get install libportaudio2"
        ) from err
    except ImportError as err:
        raise QuaddanceError(
            "no audio input device: the sounddevice package is missing (pip install sounddevice)"
        ) from err
    return sounddevice


class MicSource:
    """A microphone or line-in, through sounddevice (PortAudio).

    Recorded at ``samplerate_hz`` when the device supports it, else at the device's own rate
    and resampled; mixed to mono (the first channel). Song time counts recorded samples, so it
    is the time since the stream started. Use as a context manager or call ``close()``.

    Args:
        device: sounddevice's device index or name substring; None = the default input.
        samplerate_hz: rate of the blocks yielded, Hz (the tracker's rate).
        block_s: block length, seconds.

    Raises:
        QuaddanceError: "no audio input device: ..." when PortAudio is missing, there is no
            input device, or the device cannot be opened.
    """

    def __init__(
        self, device: int | str | None = None, samplerate_hz: int = SR_HZ, block_s: float = BLOCK_S
    ) -> None:
        sd = _import_sounddevice()
        self.sr_hz = int(samplerate_hz)
        self.block_len = max(1, round(block_s * self.sr_hz))
        self.dropped_blocks = 0
        self._samples_out = 0  # samples yielded: the song time of the next block
        self._pending = np.zeros(0, dtype=np.float32)
        self._closed = False
        self._queue: queue.Queue[np.ndarray] = queue.Queue(maxsize=MIC_QUEUE_BLOCKS)
        name = "the default input" if device is None else repr(device)
        try:
            info = sd.query_devices(device, kind="input")
        except (ValueError, sd.PortAudioError) as err:
            raise QuaddanceError(
                f"no audio input device: {name}: {_one_line(err)} "
                f"({_count_inputs(sd)} input devices found)"
            ) from err
        if int(info.get("max_input_channels", 0)) < 1:
            raise QuaddanceError(f"no audio input device: {name} has no input channels")
        self.device_name = str(info.get("name", name))
        device_sr = self.sr_hz
        try:
            sd.check_input_settings(device=device, channels=1, samplerate=self.sr_hz)
        except (ValueError, sd.PortAudioError):
            # The card cannot record at our rate: record at its own and resample.
            device_sr = int(info["default_samplerate"])
        self._resampler = None
        if device_sr != self.sr_hz:
            import soxr

            self._resampler = soxr.ResampleStream(device_sr, self.sr_hz, 1, dtype="float32")
        try:
            self._stream = sd.InputStream(
                device=device,
                channels=1,
                samplerate=device_sr,
                blocksize=max(1, round(block_s * device_sr)),
                dtype="float32",
                callback=self._callback,
            )
        except (ValueError, sd.PortAudioError) as err:
            raise QuaddanceError(
                f"no audio input device: {self.device_name} cannot be opened: {_one_line(err)}"
            ) from err
        try:
            self._stream.start()
        except sd.PortAudioError as err:
            self._stream.close()
            raise QuaddanceError(
                f"no audio input device: {self.device_name} cannot be opened: {_one_line(err)}"
            ) from err

    def _callback(self, indata: np.ndarray, frames: int, time_info: Any, status: Any) -> None:
        # PortAudio's thread: only copy and queue; a full queue drops (counted) audio rather
        # than blocking the sound card.
        try:
            self._queue.put_nowait(indata[:, 0].copy())
        except queue.Full:
            self.dropped_blocks += 1

    def __iter__(self) -> Iterator[AudioBlock]:
        while True:
            try:
                raw = self._queue.get(timeout=MIC_STALL_S)
            except queue.Empty:
                raise QuaddanceError(
                    f"audio input {self.device_name}: no audio for {MIC_STALL_S:g} s "
                    "(the device stopped)"
                ) from None
            if self._resampler is not None:
                raw = self._resampler.resample_chunk(raw)
            self._pending = np.concatenate([self._pending, raw])
            while len(self._pending) >= self.block_len:
                samples = self._pending[: self.block_len]
                self._pending = self._pending[self.block_len :]
                block = AudioBlock(samples, self._samples_out / self.sr_hz, self.sr_hz)
                self._samples_out += self.block_len
                yield block

    def close(self) -> None:
        """Stop and close the input stream (a second call does nothing)."""
        if self._closed:
            return
        self._closed = True
        self._stream.stop()
        self._stream.close()

    def __enter__(self) -> MicSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split()) or type(err).__name__


def _count_inputs(sd: Any) -> int:
    """Input devices PortAudio lists (0 where it cannot even list them)."""
    try:
        return sum(1 for d in sd.query_devices() if int(d.get("max_input_channels", 0)) > 0)
    except Exception:  # only for the message: any failure means none usable
        return 0
