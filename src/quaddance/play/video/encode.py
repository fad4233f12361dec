"""Encoding: the workers' frames piped in order into one ffmpeg (from imageio-ffmpeg), which
encodes H.264 and muxes the song as AAC, trimmed to the video, in the same pass
(`RenderTask`, a background thread); and what ffmpeg tells of a song or a video file.

Frame k shows sim time k / fps, and the song starts at ``audio_offset_s`` into the file, so
sound and motion stay in sync.
"""

from __future__ import annotations

import contextlib
import re
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

from quaddance.errors import InputFileError, QuaddanceError
from quaddance.fileio import atomic_path
from quaddance.play.video.config import RenderCfg
from quaddance.play.video.workers import WorkerPool, children_cpu_s


def ffmpeg_exe() -> str:
    """Path of the ffmpeg that imageio-ffmpeg ships."""
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


def run_ffmpeg(args: list[str]) -> subprocess.CompletedProcess[str]:
    """Run ffmpeg with ``args`` (no stdin, overwriting), its output captured as text."""
    cmd = [ffmpeg_exe(), "-hide_banner", "-nostdin", "-y", *args]
    return subprocess.run(cmd, capture_output=True, text=True, check=False)


def check_audio(audio_path: Path) -> None:
    """Fail before rendering, not after, when ffmpeg cannot decode the song."""
    if not audio_path.is_file():
        raise InputFileError(audio_path, "audio file not found")
    probe = run_ffmpeg(
        ["-v", "error", "-i", str(audio_path), "-t", "0.1", "-vn", "-f", "null", "-"]
    )
    if probe.returncode != 0:
        reason = probe.stderr.strip().splitlines()[-1] if probe.stderr.strip() else "unknown"
        raise InputFileError(audio_path, f"ffmpeg cannot decode this audio ({reason})")


def encoder_args(
    width: int,
    height: int,
    fps: float,
    n_frames: int,
    audio: Path | None,
    audio_offset_s: float,
    cfg: RenderCfg,
) -> list[str]:
    """ffmpeg arguments (all but the output file): raw RGB frames on stdin -> H.264, the
    song from ``audio_offset_s`` -> AAC, both cut at the last frame, moov atom first."""
    args = ["-v", "error", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{width}x{height}"]
    args += ["-r", f"{fps:g}", "-i", "pipe:0"]
    if audio is not None:
        args += ["-ss", f"{audio_offset_s:.6f}", "-i", str(audio)]
    args += ["-map", "0:v:0", "-c:v", "libx264", "-pix_fmt", "yuv420p"]
    args += ["-crf", str(cfg.crf), "-preset", cfg.preset, "-threads", str(cfg.encoder_threads)]
    if audio is not None:
        args += ["-map", "1:a:0?", "-c:a", "aac", "-aac_coder", cfg.aac_coder]
        args += ["-b:a", cfg.audio_bitrate]
    args += ["-t", f"{n_frames / fps:.6f}", "-movflags", "+faststart", "-f", "mp4"]
    return args


def video_info(path: str | Path) -> dict[str, Any]:
    """Duration and streams of a video file as ffmpeg reports them (ffprobe is not shipped).

    Returns:
        ``duration_s`` (float or None), ``has_video``, ``has_audio`` (bool).
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "video file not found")
    text = run_ffmpeg(["-i", str(path)]).stderr  # "-i" alone exits 1 after printing the header
    match = re.search(r"Duration:\s*(\d+):(\d+):(\d+(?:\.\d+)?)", text)
    duration = None
    if match:
        h, m, s = match.groups()
        duration = 3600 * int(h) + 60 * int(m) + float(s)
    return {
        "duration_s": duration,
        "has_video": bool(re.search(r"Stream #\S+.*: Video:", text)),
        "has_audio": bool(re.search(r"Stream #\S+.*: Audio:", text)),
    }


class _Progress:
    """A rich progress bar, or nothing."""

    def __init__(self, enabled: bool, label: str, total: int) -> None:
        self._bar = None
        if enabled:
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeRemainingColumn,
            )

            self._bar = Progress(
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeRemainingColumn(),
                transient=True,
            )
            self._bar.start()
            self._task = self._bar.add_task(label, total=total)

    def advance(self, n: int) -> None:
        if self._bar is not None:
            self._bar.advance(self._task, n)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None


class RenderTask:
    """A video being encoded in a background thread from the frames of a `WorkerPool`."""

    def __init__(
        self,
        pool: WorkerPool,
        out_path: Path,
        n_frames: int,
        fps: float,
        audio: Path | None,
        audio_offset_s: float,
        progress: bool,
    ) -> None:
        self.pool, self.out_path = pool, out_path
        self.n_frames, self.fps, self.progress = n_frames, fps, progress
        self.args = encoder_args(
            pool.width, pool.height, fps, n_frames, audio, audio_offset_s, pool.cfg
        )
        self.total_start = time.perf_counter()
        self.poses_done: float | None = None  # when the last pose came in
        self._encoder: subprocess.Popen[bytes] | None = None
        self._result: dict[str, Any] | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="quaddance-video", daemon=True)

    def begin(self) -> None:
        self._thread.start()

    def running(self) -> bool:
        return self._thread.is_alive()

    def join(self, timeout: float) -> None:
        self._thread.join(timeout)

    def kill_encoder(self) -> None:
        """Stop ffmpeg (after an interrupt), so that the thread unwinds and removes its
        temporary output."""
        if self._encoder is not None and self._encoder.poll() is None:
            self._encoder.kill()

    def _run(self) -> None:
        try:
            self._result = self._encode()
        except BaseException as err:  # handed to the caller by wait()
            self._error = err

    def wait(self) -> dict[str, Any]:
        """Block until the video is written; returns its timing or raises the failure."""
        while self._thread.is_alive():
            self._thread.join(timeout=0.2)  # short joins keep Ctrl-C responsive
        if self._error is not None:
            raise self._error
        assert self._result is not None
        return self._result

    def _encode(self) -> dict[str, Any]:
        """Pipe the workers' frames, in order, into ffmpeg (runs in the task thread)."""
        pool = self.pool
        wait_start = time.perf_counter()
        pool.wait_ready()
        ready = time.perf_counter()
        bar = _Progress(self.progress, "Rendering video", self.n_frames)
        try:
            with atomic_path(self.out_path) as tmp_out:
                err_path = pool.tmp_dir / "ffmpeg.log"
                with open(err_path, "wb") as err:
                    cmd = [ffmpeg_exe(), "-hide_banner", "-y", *self.args, str(tmp_out)]
                    proc = subprocess.Popen(
                        cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=err
                    )
                    self._encoder = proc
                try:
                    assert proc.stdin is not None
                    assert pool.slots is not None
                    for k in range(self.n_frames):
                        worker = k % pool.n_workers
                        _, slot = pool.receive(worker)
                        try:
                            proc.stdin.write(pool.slots.frame(worker, slot))
                        except BrokenPipeError:
                            break  # ffmpeg stopped: its log says why
                        bar.advance(1)
                    frames_done = time.perf_counter()
                    with contextlib.suppress(BrokenPipeError):
                        proc.stdin.close()
                    returncode = proc.wait()
                except BaseException:
                    proc.kill()
                    proc.wait()
                    raise
                if returncode != 0:
                    # The song was probed before: a failure here is the encoder's.
                    log = err_path.read_text(errors="replace").strip()
                    reason = log.splitlines()[-1] if log else f"exit code {returncode}"
                    raise QuaddanceError(f"ffmpeg could not write {self.out_path} ({reason})")
            encode_end = time.perf_counter()
        finally:
            bar.close()
        for i in range(pool.n_workers):
            kind, _ = pool.receive(i)
            assert kind == "done", kind
        for worker_proc in pool.procs:
            worker_proc.join(timeout=5.0)
        total_s = encode_end - self.total_start
        video_s = self.n_frames / self.fps
        return {
            "frames": self.n_frames,
            "fps": self.fps,
            "width": pool.width,
            "height": pool.height,
            "workers": min(pool.n_workers, self.n_frames),
            "duration_s": video_s,
            "startup_wait_s": ready - wait_start,
            "workers_ready_s": max(pool.ready_at) - pool.created,
            "worker_startup_cpu_s": sum(pool.startup_cpu_s),
            "render_s": encode_end - ready,
            "tail_s": encode_end - (self.poses_done or encode_end),
            "worker_cpu_s": children_cpu_s() - pool.cpu_before,
            "mux_s": encode_end - frames_done,
            "total_s": total_s,
            "frames_per_s": self.n_frames / total_s,
            "realtime_factor": video_s / total_s,
        }
