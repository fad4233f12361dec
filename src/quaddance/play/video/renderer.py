"""`VideoRenderer`: a video of poses that may still be coming in, and `render_video`.

The render workers (`WorkerPool`) start when the renderer is created; `stream` opens the
video and starts the encoder (`RenderTask`); `VideoStream.add` takes poses while the dance is
simulated and hands out each frame once its poses and its camera position are known.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.play.video.config import VIDEO_FPS, RenderCfg, check_size
from quaddance.play.video.encode import RenderTask, check_audio
from quaddance.play.video.poses import check_poses, follow_lookat, resample_qpos
from quaddance.play.video.scene import ModelSource, load_model
from quaddance.play.video.workers import WorkerPool

#: Sim steps between hand-outs of frames while poses stream in (0.5 s at 50 Hz): each
#: hand-out recomputes the camera path of the frames so far, so not every step.
_STREAM_EVERY = 25


class VideoRenderer:
    """Rendering processes started ahead of the poses they will draw.

    Creating one spawns the workers at once; each builds (or loads) the model, makes its EGL
    context and draws a warm-up frame while the caller goes on analysing the music. Then
    `stream` opens the video: poses can be added while the dance is still being simulated
    (`VideoStream.add`), and frames are handed out round robin as soon as their camera
    position is known; one ffmpeg encodes them in order (H.264) and muxes the song (AAC) in
    the same pass. `render` (all poses at once) is a shorthand. One video per
    instance; use it as a context manager (or call `close`) so the workers always end.
    """

    def __init__(
        self,
        model: ModelSource = None,
        width: int = 640,
        height: int = 480,
        workers: int = 2,
        cfg: RenderCfg | None = None,
    ) -> None:
        """Start the render workers now: ``model``, ``width``, ``height`` and ``workers`` as
        in `WorkerPool`; ``cfg``: look, camera and encoder settings."""
        self.width, self.height, self.cfg = width, height, cfg or RenderCfg()
        self._pool = WorkerPool(model, width, height, workers, self.cfg)
        self._used = False
        self._task: RenderTask | None = None

    def __enter__(self) -> VideoRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the workers (if still running) and remove the temporary files.

        Also after an interrupt mid-video: the encoder is stopped first, so that the render
        thread unwinds and removes its temporary output before we return.
        """
        task_running = self._task is not None and self._task.running()
        if task_running:
            self._task.kill_encoder()
        # A worker with no job (an error before rendering) need not finish starting up.
        self._pool.stop(grace_s=2.0 if self._used and not task_running else 0.1)
        if self._task is not None:
            self._task.join(timeout=10.0)
        self._pool.close()

    def stream(
        self,
        n_poses: int,
        sim_fps: float,
        out_path: str | Path,
        audio_path: str | Path | None = None,
        audio_offset_s: float = 0.0,
        fps: float = VIDEO_FPS,
        target_markers: bool = False,
        progress: bool = True,
    ) -> VideoStream:
        """Open the video of ``n_poses`` poses at ``sim_fps`` that will be added one by one
        (`VideoStream.add`); the encoder starts now. Arguments as in `render_video`;
        ``target_markers``: `add` will pass each step's targets."""
        check_size(self.width, self.height, fps)
        if audio_offset_s < 0 or not np.isfinite(audio_offset_s):
            raise QuaddanceError(f"audio_offset_s must be >= 0, got {audio_offset_s}")
        if not sim_fps > 0:
            raise QuaddanceError(f"sim_fps must be > 0, got {sim_fps}")
        if n_poses < 1:
            raise QuaddanceError(f"a video needs at least one pose, got {n_poses}")
        audio = Path(audio_path) if audio_path is not None else None
        if audio is not None:
            check_audio(audio)
        if self._used:
            raise QuaddanceError("a VideoRenderer renders one video; make a new one")
        self._used = True
        n_frames = max(1, round(n_poses / sim_fps * fps))
        task = RenderTask(
            self._pool, Path(out_path), n_frames, fps, audio, audio_offset_s, progress
        )
        self._task = task
        task.begin()
        return VideoStream(self._pool, task, n_poses, sim_fps, fps, target_markers)

    def render(
        self,
        qpos_s: np.ndarray,
        sim_fps: float,
        out_path: str | Path,
        *,
        audio_path: str | Path | None = None,
        audio_offset_s: float = 0.0,
        fps: float = VIDEO_FPS,
        target_heights_m: np.ndarray | None = None,
        progress: bool = True,
    ) -> dict[str, Any]:
        """Render all poses at once and wait for the video; the arguments (checked before
        anything starts) and the result are `render_video`'s."""
        qpos = np.asarray(qpos_s, dtype=float)
        layout = self._pool.layout
        nq = layout.nq if layout is not None else qpos.shape[-1]
        qpos = check_poses(nq, qpos, sim_fps, target_heights_m)
        stream = self.stream(
            len(qpos), sim_fps, out_path, audio_path, audio_offset_s, fps,
            target_heights_m is not None, progress,
        )  # fmt: skip
        stream.add(qpos, target_heights_m)
        return stream.finish().wait()


class VideoStream:
    """Poses going into a video while the simulation makes them (see `VideoRenderer.stream`).

    Frame k shows sim time k / fps: it is drawn once the poses around that time and those
    the camera smoothing looks ahead to are in, so the frames are exactly those of a video
    rendered from the whole trajectory at once.
    """

    def __init__(
        self,
        pool: WorkerPool,
        task: RenderTask,
        n_poses: int,
        sim_fps: float,
        fps: float,
        target_markers: bool,
    ) -> None:
        self._pool, self._task = pool, task
        self.n_poses, self.sim_fps, self.fps = n_poses, sim_fps, fps
        self._qpos: np.ndarray | None = None  # (n_poses, nq), allocated with the first pose
        self._targets = np.zeros((n_poses, 4)) if target_markers else None
        self._count = 0  # poses added
        self._sent = 0  # frames handed out
        self._times_s = np.arange(task.n_frames) / fps
        # Frame k interpolates poses i0 and i1 = i0 + 1 (clipped), as resample_qpos does.
        pos = np.clip(self._times_s * sim_fps, 0.0, n_poses - 1)
        self._needs = np.minimum(np.floor(pos).astype(int) + 1, n_poses - 1)
        # Frames the camera smoothing reaches ahead (gaussian_smooth: 4 sigma), plus one.
        self._ahead = int(np.ceil(4.0 * pool.cfg.smooth_s * fps)) + 1

    def add(self, qpos: np.ndarray, target_heights_m: np.ndarray | None = None) -> None:
        """Append poses (nq,) or (m, nq) and, with target markers, their targets (4,) or
        (m, 4); frames whose poses are all in go out to the workers every few steps."""
        rows = np.atleast_2d(np.asarray(qpos, dtype=float))
        n = len(rows)
        if self._count + n > self.n_poses:
            raise QuaddanceError(f"more poses than the {self.n_poses} announced")
        if self._qpos is None:
            self._qpos = np.zeros((self.n_poses, rows.shape[1]))
        self._qpos[self._count : self._count + n] = rows
        if self._targets is not None:
            if target_heights_m is None:
                raise QuaddanceError("this video shows target markers: pass the targets")
            self._targets[self._count : self._count + n] = np.atleast_2d(target_heights_m)
        before, self._count = self._count, self._count + n
        if self._count // _STREAM_EVERY > before // _STREAM_EVERY:
            self._hand_out(final=False)

    def finish(self) -> RenderTask:
        """All poses are in: hand out the remaining frames; returns the task to wait on."""
        if self._count != self.n_poses:
            raise QuaddanceError(f"{self._count} poses added, {self.n_poses} announced")
        self._task.poses_done = time.perf_counter()
        self._hand_out(final=True)
        return self._task

    def _hand_out(self, final: bool) -> None:
        pool, task = self._pool, self._task
        if not pool.layout_known.is_set():
            if not final:
                return  # the first worker is still starting: hand out later, don't wait
            while not pool.layout_known.wait(0.2):
                if not task.running():
                    return  # the task failed; wait() raises its error
        layout = pool.layout
        assert layout is not None and self._qpos is not None
        if self._qpos.shape[1] != layout.nq:
            raise QuaddanceError(f"qpos must have {layout.nq} columns, got {self._qpos.shape[1]}")
        if not np.all(np.isfinite(self._qpos[: self._count])):
            raise QuaddanceError("qpos_s contains NaN or inf")
        known = int(np.searchsorted(self._needs, self._count - 1, side="right"))
        if not final:
            known -= self._ahead  # their camera position still depends on poses to come
        if known > self._sent:
            self._send_frames(known)
        if final:
            pool.send(("end",))

    def _send_frames(self, known: int) -> None:
        """Hand out frames [sent, known): their poses and camera path are complete."""
        pool, layout = self._pool, self._pool.layout
        assert layout is not None and self._qpos is not None
        frames = resample_qpos(
            layout, self._qpos, self.sim_fps, self._times_s[: known + self._ahead]
        )
        lookat = follow_lookat(layout, frames, self.fps, pool.cfg)
        new = slice(self._sent, known)
        targets = None
        if self._targets is not None:
            # Step-hold, not interpolation: a marker shows the target of the sim step on screen.
            idx = np.minimum(
                (self._times_s[new] * self.sim_fps + 1e-9).astype(int), self.n_poses - 1
            )
            targets = self._targets[idx]
        pool.send(("frames", self._sent, frames[new], lookat[new], targets))
        self._sent = known


def render_video(
    model: ModelSource,
    qpos_s: np.ndarray,
    sim_fps: float,
    out_path: str | Path,
    audio_path: str | Path | None = None,
    audio_offset_s: float = 0.0,
    fps: float = VIDEO_FPS,
    width: int = 640,
    height: int = 480,
    target_heights_m: np.ndarray | None = None,
    progress: bool = True,
    workers: int = 2,
    cfg: RenderCfg | None = None,
) -> dict[str, Any]:
    """Render a pose trajectory to an H.264 video, with the song as AAC sound.

    The video lasts ``T / sim_fps`` seconds; frame k shows the pose at sim time k / fps
    (interpolated). The song is played from ``audio_offset_s`` into the file (the song time
    of sim time 0) and cut at the video's end. The output is written atomically: on any
    failure an existing ``out_path`` is left as it was. To overlap the workers' start-up
    with other work, create a `VideoRenderer` early and call its `render` later instead.

    Args:
        model: the model, or a function that builds it, or None for the dance scene with
            visual meshes. It must have the qpos layout of ``qpos_s``; use the visual model
            (a physics-only model is drawn with its collision shapes). The workers load a
            copy saved to a temporary file.
        qpos_s: (T, nq) poses, sample i at sim time i / sim_fps.
        sim_fps: sample rate of ``qpos_s``, Hz (the policy's 50 Hz).
        out_path: the video file (.mp4).
        audio_path: the song, any format ffmpeg reads; None for a silent video.
        audio_offset_s: song time at sim time 0, s (>= 0).
        fps: video frame rate.
        width, height: frame size in pixels (even).
        target_heights_m: (T, 4) foot-height targets (FL, FR, RL, RR), m: draws a
            translucent marker above each front foot at its target height.
        progress: show a rich progress bar.
        workers: rendering processes; one per core is fastest.
        cfg: look, camera and encoder settings.

    Returns:
        Timing: ``frames``, ``fps``, ``width``, ``height``, ``workers``, ``duration_s`` (of the
        video), ``startup_wait_s`` (waiting for the workers' start-up), ``workers_ready_s``
        (their start-up, from creation, wall), ``worker_startup_cpu_s`` (its CPU seconds, all
        workers), ``render_s`` (wall time rendering and encoding the
        frames), ``worker_cpu_s`` (CPU seconds of the workers and the encoder), ``mux_s``
        (encoder tail after the last frame), ``total_s``, ``frames_per_s`` (frames /
        total_s), ``realtime_factor`` (duration_s / total_s; above 1 is faster than real time).
    """
    # Argument errors are reported before any process starts.
    check_size(width, height, fps)
    if workers < 1:
        raise QuaddanceError(f"workers must be >= 1, got {workers}")
    if audio_offset_s < 0 or not np.isfinite(audio_offset_s):
        raise QuaddanceError(f"audio_offset_s must be >= 0, got {audio_offset_s}")
    if audio_path is not None:
        check_audio(Path(audio_path))
    base_model = load_model(model, (cfg or RenderCfg()).robot)
    check_poses(base_model.nq, qpos_s, sim_fps, target_heights_m)
    with VideoRenderer(base_model, width, height, workers, cfg) as renderer:
        return renderer.render(
            qpos_s,
            sim_fps,
            out_path,
            audio_path=audio_path,
            audio_offset_s=audio_offset_s,
            fps=fps,
            target_heights_m=target_heights_m,
            progress=progress,
        )
