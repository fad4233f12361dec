"""Headless video of a rollout, with the song as its soundtrack.

Frames are rendered on the CPU by MuJoCo's `mujoco.Renderer` through EGL and Mesa's software
rasteriser (llvmpipe; Debian packages libegl1, libegl-mesa0, libgl1-mesa-dri). OSMesa is not
used: it crashed in processes that had imported torch.

Rendering always runs in worker processes started with the 'spawn' method, never in the
caller: MuJoCo picks its GL backend once, when it is first imported, so only a fresh process
whose environment says ``MUJOCO_GL=egl`` is sure to get EGL. The frames are split into
contiguous chunks, one per worker; each worker pipes its frames to its own ffmpeg (from
imageio-ffmpeg) as an H.264 segment; the segments are then joined without re-encoding and the
song is muxed in as AAC, trimmed to the video. Frame k shows sim time k / fps, and the song
starts at ``audio_offset_s`` into the file, so sound and motion stay in sync. A script that
calls `render_video` needs the usual ``if __name__ == "__main__":`` guard, because 'spawn'
re-imports the main module in each worker (a worker that dies that way is reported).

What makes it fast enough (640x480 on 2 cores, see `bench_render`): shadows, reflections and
multisampling are off, and the Go1's 206 k-triangle visual meshes are simplified in the
workers' private model copies by vertex clustering (`simplify_meshes`), which looks the same
at this size and renders several times faster on llvmpipe.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import queue as queue_module
import subprocess
import tempfile
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from quaddance.errors import InputFileError, QuaddanceError
from quaddance.fileio import atomic_path, write_json
from quaddance.play.metrics import gaussian_smooth
from quaddance.sim import go1

ModelSource = mujoco.MjModel | Callable[[], mujoco.MjModel] | None
"""A model to render, or a zero-argument function that builds one; None means the dance scene
with its visual meshes (`quaddance.sim.scene.build_model(visual=True)`)."""

EGL_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri"
"""Debian packages that headless EGL rendering on the CPU needs."""


@dataclass(frozen=True)
class RenderCfg:
    """Look, camera and encoder settings of the video."""

    #: Named model camera (e.g. "tracking") instead of the smoothed follow camera.
    camera: str | None = None
    #: Follow camera: distance to the look-at point, m. Frames the 0.65 m Go1 with room for
    #: raised legs at MuJoCo's default 45 degree field of view (chosen by eye).
    distance_m: float = 1.3
    #: Follow camera direction of view, degrees: 225 looks from the robot's front-left
    #: (+x, +y) back towards it, a 3/4 view of the front legs.
    azimuth_deg: float = 225.0
    elevation_deg: float = -15.0
    #: Look-at point relative to the base position, m (a bit below the trunk, so both the
    #: body and the feet stay in the frame).
    lookat_offset_m: tuple[float, float, float] = (0.0, 0.0, -0.08)
    #: Gaussian smoothing of the look-at path, s, so the camera does not shake with the trunk.
    smooth_s: float = 0.4
    #: Vertex-clustering cell for the visual meshes, m; None keeps the full meshes.
    #: 8 mm: 18 % faster than 4 mm (about one pixel at 640x480 and 1.3 m) and looks the
    #: same at that size; 16 mm shows facets (all measured; the full meshes have 206 k
    #: triangles).
    mesh_cell_m: float | None = 0.008
    #: Off-screen multisampling; 0 halves llvmpipe's cost (measured 6.6 -> 12.6 frames/s).
    msaa_samples: int = 0
    shadows: bool = False  # 1.6 vs 10.4 frames/s measured with shadows and reflections on/off
    reflections: bool = False
    #: Target markers: translucent spheres above the front feet.
    marker_radius_m: float = 0.025
    marker_rgba: tuple[tuple[float, float, float, float], ...] = (
        (1.0, 0.55, 0.1, 0.55),  # FL orange, as in the plots
        (0.15, 0.55, 1.0, 0.55),  # FR blue
    )
    #: H.264 settings: crf 20 is visually clean; "veryfast" keeps encoding cheap beside the
    #: software renderer that shares the cores.
    crf: int = 20
    preset: str = "veryfast"
    audio_bitrate: str = "160k"


class RenderError(QuaddanceError):
    """Rendering failed in a worker; ``worker_traceback`` holds the worker's traceback."""

    def __init__(self, message: str, worker_traceback: str = "") -> None:
        super().__init__(message)
        self.worker_traceback = worker_traceback


# --- frame preparation (caller's process) -----------------------------------------------------


def _default_model() -> mujoco.MjModel:
    from quaddance.sim.scene import build_model

    return build_model(visual=True)


def _quat_slices(model: mujoco.MjModel) -> list[slice]:
    """qpos slices holding unit quaternions (free and ball joints)."""
    out = []
    for j in range(model.njnt):
        adr = int(model.jnt_qposadr[j])
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            out.append(slice(adr + 3, adr + 7))
        elif model.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
            out.append(slice(adr, adr + 4))
    return out


def resample_qpos(
    model: mujoco.MjModel, qpos_s: np.ndarray, sim_fps: float, times_s: np.ndarray
) -> np.ndarray:
    """Poses at arbitrary times: linear interpolation, quaternions normalised (nlerp).

    Args:
        model: gives the qpos layout (which entries are quaternions).
        qpos_s: (T, nq) poses sampled at ``sim_fps`` Hz, sample i at time i / sim_fps.
        sim_fps: sample rate of ``qpos_s``, Hz.
        times_s: (N,) times, s; clipped to the sampled span.

    Returns:
        (N, nq) poses.
    """
    qpos = np.asarray(qpos_s, dtype=float)
    pos = np.clip(np.asarray(times_s, dtype=float) * sim_fps, 0.0, qpos.shape[0] - 1)
    i0 = np.floor(pos).astype(int)
    i1 = np.minimum(i0 + 1, qpos.shape[0] - 1)
    w = (pos - i0)[:, None]
    a, b = qpos[i0], qpos[i1].copy()
    for sl in _quat_slices(model):
        # q and -q are the same rotation: interpolate along the shorter arc.
        flip = np.sum(a[:, sl] * b[:, sl], axis=1) < 0
        b[flip, sl] *= -1.0
    out = (1.0 - w) * a + w * b
    for sl in _quat_slices(model):
        norm = np.linalg.norm(out[:, sl], axis=1, keepdims=True)
        out[:, sl] /= np.where(norm > 0, norm, 1.0)
    return out


def follow_lookat(
    model: mujoco.MjModel, qpos_frames: np.ndarray, fps: float, cfg: RenderCfg
) -> np.ndarray:
    """Smoothed look-at points of the follow camera, (N, 3) m, from the base position."""
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if not free:
        return np.tile(np.asarray(model.stat.center, dtype=float), (len(qpos_frames), 1))
    adr = int(model.jnt_qposadr[free[0]])
    base = qpos_frames[:, adr : adr + 3] + np.asarray(cfg.lookat_offset_m)
    return gaussian_smooth(base, cfg.smooth_s * fps)


# --- rendering (worker processes) --------------------------------------------------------------


def simplify_meshes(model: mujoco.MjModel, cell_m: float) -> int:
    """Simplify every mesh of ``model`` in place by vertex clustering, for drawing only.

    Vertices in the same ``cell_m`` cube merge into their centroid; triangles that collapse
    are dropped. The kept triangles are written to the front of each mesh's face block and
    ``mesh_facenum`` shrinks, which is all the renderer reads when it uploads the meshes.
    Use only on a model copy that is drawn, never simulated (mesh collision data is stale).

    Returns:
        Number of triangles left, summed over meshes.
    """
    total = 0
    for i in range(model.nmesh):
        vadr, vnum = int(model.mesh_vertadr[i]), int(model.mesh_vertnum[i])
        fadr, fnum = int(model.mesh_faceadr[i]), int(model.mesh_facenum[i])
        if vnum == 0 or fnum == 0:
            continue
        verts = model.mesh_vert[vadr : vadr + vnum]
        faces = model.mesh_face[fadr : fadr + fnum].copy()
        cells = np.floor(verts / cell_m).astype(np.int64)
        cells -= cells.min(axis=0)
        dims = cells.max(axis=0) + 1
        keys = (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]  # one int per cell
        _, first, cluster = np.unique(keys, return_index=True, return_inverse=True)
        centroid = np.zeros((len(first), 3))
        np.add.at(centroid, cluster, verts)
        centroid /= np.bincount(cluster)[:, None]
        verts[first] = centroid  # each cluster is drawn at its first vertex, moved to the centroid
        merged = first[cluster][faces]
        keep = (
            (merged[:, 0] != merged[:, 1])
            & (merged[:, 1] != merged[:, 2])
            & (merged[:, 0] != merged[:, 2])
        )
        n_keep = int(keep.sum())
        # Normals and texture coordinates stay those of the original corners: close enough.
        normals = model.mesh_facenormal[fadr : fadr + fnum][keep].copy()
        model.mesh_face[fadr : fadr + n_keep] = merged[keep]
        model.mesh_facenormal[fadr : fadr + n_keep] = normals
        if model.mesh_texcoordnum[i] > 0:
            texcoords = model.mesh_facetexcoord[fadr : fadr + fnum][keep].copy()
            model.mesh_facetexcoord[fadr : fadr + n_keep] = texcoords
        model.mesh_facenum[i] = n_keep
        total += n_keep
    return total


class FrameRenderer:
    """Draws poses of one model to RGB arrays. Create it only in a process using EGL."""

    def __init__(self, model: mujoco.MjModel, width: int, height: int, cfg: RenderCfg) -> None:
        self.model = model
        self.cfg = cfg
        model.vis.global_.offwidth = max(width, int(model.vis.global_.offwidth))
        model.vis.global_.offheight = max(height, int(model.vis.global_.offheight))
        model.vis.quality.offsamples = cfg.msaa_samples
        if cfg.mesh_cell_m:
            simplify_meshes(model, cfg.mesh_cell_m)
        self.data = mujoco.MjData(model)
        self.renderer = mujoco.Renderer(model, height, width)
        flags = self.renderer.scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SHADOW] = cfg.shadows
        flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = cfg.reflections
        self.option = mujoco.MjvOption()
        if model.nmesh == 0:
            # A physics-only model (no visual meshes): show the collision shapes instead.
            self.option.geomgroup[3] = 1
        if cfg.camera is not None:
            if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, cfg.camera) < 0:
                raise QuaddanceError(f"the model has no camera named {cfg.camera!r}")
            self.camera: mujoco.MjvCamera | str = cfg.camera
        else:
            cam = mujoco.MjvCamera()
            cam.type = mujoco.mjtCamera.mjCAMERA_FREE
            cam.distance = cfg.distance_m
            cam.azimuth = cfg.azimuth_deg
            cam.elevation = cfg.elevation_deg
            self.camera = cam
        self.front_sites = [
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name) for name in go1.FEET[:2]
        ]

    def render(
        self,
        qpos: np.ndarray,
        lookat: np.ndarray | None = None,
        target_heights_m: np.ndarray | None = None,
    ) -> np.ndarray:
        """One frame, (height, width, 3) uint8.

        Args:
            qpos: (nq,) pose.
            lookat: (3,) follow-camera look-at point, m; ignored with a named camera.
            target_heights_m: (4,) targets (FL, FR, RL, RR), m: draws the front-foot markers.
        """
        self.data.qpos[:] = qpos
        mujoco.mj_forward(self.model, self.data)
        if isinstance(self.camera, mujoco.MjvCamera) and lookat is not None:
            self.camera.lookat[:] = lookat
        self.renderer.update_scene(self.data, camera=self.camera, scene_option=self.option)
        if target_heights_m is not None:
            self._add_markers(np.asarray(target_heights_m, dtype=float))
        return self.renderer.render()

    def _add_markers(self, target_heights_m: np.ndarray) -> None:
        scene = self.renderer.scene
        for foot, site in enumerate(self.front_sites):
            if site < 0 or scene.ngeom >= scene.maxgeom or not np.isfinite(target_heights_m[foot]):
                continue
            pos = self.data.site_xpos[site].copy()
            # The foot site is the centre of the foot sphere, whose bottom is the foot height.
            pos[2] = target_heights_m[foot] + go1.FOOT_RADIUS_M
            mujoco.mjv_initGeom(
                scene.geoms[scene.ngeom],
                mujoco.mjtGeom.mjGEOM_SPHERE,
                np.array([self.cfg.marker_radius_m, 0.0, 0.0]),
                pos,
                np.eye(3).reshape(-1),
                np.asarray(self.cfg.marker_rgba[foot], dtype=np.float32),
            )
            scene.ngeom += 1


@dataclass
class _Job:
    """One worker's share of the frames. Only paths and settings: the spawn start-up pipe
    then carries a few kB, and a worker that dies while starting cannot block the caller
    (CPython keeps writing a large payload into the pipe of a dead child)."""

    worker: int
    model_path: Path  # the model, saved by mj_saveModel
    frames_path: Path  # .npz: qpos (n, nq), lookat (n, 3), optionally targets (n, 4)
    width: int
    height: int
    fps: float
    cfg: RenderCfg
    segment: Path | None = None  # write an H.264 segment here ...
    pngs: list[Path] | None = None  # ... or one PNG per frame here


def _make_jobs(
    tmp_dir: Path,
    model: mujoco.MjModel,
    qpos: np.ndarray,
    lookat: np.ndarray,
    targets: np.ndarray | None,
    n_workers: int,
    **job_args: Any,
) -> list[_Job]:
    """Split the frames into contiguous chunks, one per worker, saved under ``tmp_dir``."""
    model_path = tmp_dir / "model.mjb"
    mujoco.mj_saveModel(model, str(model_path), None)
    jobs = []
    chunks = [c for c in np.array_split(np.arange(len(qpos)), n_workers) if len(c)]
    for i, chunk in enumerate(chunks):
        arrays = {"qpos": qpos[chunk], "lookat": lookat[chunk]}
        if targets is not None:
            arrays["targets"] = targets[chunk]
        frames_path = tmp_dir / f"frames{i:02d}.npz"
        np.savez(frames_path, **arrays)
        jobs.append(_Job(worker=i, model_path=model_path, frames_path=frames_path, **job_args))
    return jobs


def _worker(job: _Job, messages: Any) -> None:
    """Entry point of a rendering process: render the job, report progress on ``messages``."""
    try:
        import imageio_ffmpeg

        start = time.perf_counter()
        model = mujoco.MjModel.from_binary_path(str(job.model_path))
        with np.load(job.frames_path) as arrays:
            qpos, lookat = arrays["qpos"], arrays["lookat"]
            targets = arrays.get("targets")
        frames = FrameRenderer(model, job.width, job.height, job.cfg)
        writer = None
        if job.segment is not None:
            writer = imageio_ffmpeg.write_frames(
                str(job.segment),
                (job.width, job.height),
                fps=job.fps,
                codec="libx264",
                quality=None,
                macro_block_size=2,
                ffmpeg_log_level="error",
                output_params=["-crf", str(job.cfg.crf), "-preset", job.cfg.preset],
            )
            writer.send(None)  # starts ffmpeg
        reported = 0
        for k in range(len(qpos)):
            image = frames.render(qpos[k], lookat[k], None if targets is None else targets[k])
            if writer is not None:
                writer.send(np.ascontiguousarray(image))
            elif job.pngs is not None:
                _write_png(job.pngs[k], image)
            if k + 1 - reported >= 5 or k + 1 == len(qpos):
                messages.put(("progress", job.worker, k + 1 - reported))
                reported = k + 1
        if writer is not None:
            writer.close()
        messages.put(("done", job.worker, time.perf_counter() - start))
    except BaseException:
        messages.put(("error", job.worker, traceback.format_exc()))


def _write_png(path: Path, image: np.ndarray) -> None:
    import imageio.v3 as iio

    with atomic_path(path) as tmp:
        iio.imwrite(tmp, image, extension=".png")


def _run_workers(jobs: Sequence[_Job], n_frames: int, progress: bool, label: str) -> float:
    """Run one spawned process per job; returns the wall time, s. Raises RenderError."""
    # The workers inherit this environment; MuJoCo reads MUJOCO_GL when they import it.
    os.environ.setdefault("MUJOCO_GL", "egl")
    ctx = mp.get_context("spawn")
    messages = ctx.Queue()
    procs = [ctx.Process(target=_worker, args=(job, messages), daemon=True) for job in jobs]
    start = time.perf_counter()
    bar = _Progress(progress, label, n_frames)
    try:
        for proc in procs:
            proc.start()
        finished: set[int] = set()
        while len(finished) < len(procs):
            try:
                kind, worker, payload = messages.get(timeout=1.0)
            except queue_module.Empty:
                dead = [
                    i for i, p in enumerate(procs) if i not in finished and p.exitcode is not None
                ]
                if dead:
                    raise RenderError(
                        f"render worker {dead[0]} exited with code {procs[dead[0]].exitcode} "
                        "(see its output above; a calling script needs an "
                        "'if __name__ == \"__main__\":' guard; headless rendering needs EGL, "
                        f"Debian: {EGL_PACKAGES})"
                    ) from None
                continue
            if kind == "progress":
                bar.advance(payload)
            elif kind == "done":
                finished.add(worker)
            else:
                last = payload.strip().splitlines()[-1] if payload.strip() else "unknown error"
                raise RenderError(
                    f"rendering failed: {last} (headless rendering needs EGL; Debian: "
                    f"{EGL_PACKAGES})",
                    worker_traceback=payload,
                )
        for proc in procs:
            proc.join()
        return time.perf_counter() - start
    finally:
        bar.close()
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=5)
        messages.close()


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


# --- public API ---------------------------------------------------------------------------------


def _load_model(model: ModelSource) -> mujoco.MjModel:
    if model is None:
        return _default_model()
    if isinstance(model, mujoco.MjModel):
        return model
    if callable(model):
        return model()
    raise QuaddanceError(f"model must be an MjModel or a function that builds one, got {model!r}")


def _check_poses(
    model: mujoco.MjModel, qpos_s: np.ndarray, sim_fps: float, targets: np.ndarray | None
) -> np.ndarray:
    qpos = np.asarray(qpos_s, dtype=float)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq or qpos.shape[0] < 1:
        raise QuaddanceError(f"qpos_s must be (T, {model.nq}) with T >= 1, got {qpos.shape}")
    if not np.all(np.isfinite(qpos)):
        raise QuaddanceError("qpos_s contains NaN or inf")
    if not sim_fps > 0:
        raise QuaddanceError(f"sim_fps must be > 0, got {sim_fps}")
    if targets is not None and np.shape(targets) != (qpos.shape[0], 4):
        raise QuaddanceError(
            f"target_heights_m must be ({qpos.shape[0]}, 4) like qpos_s, got {np.shape(targets)}"
        )
    return qpos


def _check_size(width: int, height: int, fps: float) -> None:
    if width < 16 or height < 16 or width % 2 or height % 2:
        raise QuaddanceError(f"video size must be even and at least 16x16, got {width}x{height}")
    if not fps > 0:
        raise QuaddanceError(f"fps must be > 0, got {fps}")


def _children_cpu_s() -> float:
    """CPU seconds of finished child processes (and the children they waited for)."""
    import resource

    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _ffmpeg(args: list[str]) -> subprocess.CompletedProcess[str]:
    import imageio_ffmpeg

    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-nostdin", "-y", *args]
    return subprocess.run(cmd, capture_output=True, text=True, check=False)


def _check_audio(audio_path: Path) -> None:
    """Fail before rendering, not after, when ffmpeg cannot decode the song."""
    if not audio_path.is_file():
        raise InputFileError(audio_path, "audio file not found")
    probe = _ffmpeg(["-v", "error", "-i", str(audio_path), "-t", "0.1", "-vn", "-f", "null", "-"])
    if probe.returncode != 0:
        reason = probe.stderr.strip().splitlines()[-1] if probe.stderr.strip() else "unknown"
        raise InputFileError(audio_path, f"ffmpeg cannot decode this audio ({reason})")


def render_video(
    model: ModelSource,
    qpos_s: np.ndarray,
    sim_fps: float,
    out_path: str | Path,
    audio_path: str | Path | None = None,
    audio_offset_s: float = 0.0,
    fps: float = 30.0,
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
    failure an existing ``out_path`` is left as it was.

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
        video), ``render_s`` (wall time rendering and encoding the frames),
        ``worker_cpu_s`` (CPU seconds of the workers and their encoders), ``mux_s``,
        ``total_s``, ``frames_per_s`` (frames / total_s), ``realtime_factor``
        (duration_s / total_s; above 1 is faster than real time).
    """
    total_start = time.perf_counter()
    cfg = cfg or RenderCfg()
    _check_size(width, height, fps)
    if workers < 1:
        raise QuaddanceError(f"workers must be >= 1, got {workers}")
    if audio_offset_s < 0 or not np.isfinite(audio_offset_s):
        raise QuaddanceError(f"audio_offset_s must be >= 0, got {audio_offset_s}")
    audio = Path(audio_path) if audio_path is not None else None
    if audio is not None:
        _check_audio(audio)
    base_model = _load_model(model)
    qpos = _check_poses(base_model, qpos_s, sim_fps, target_heights_m)

    duration_s = qpos.shape[0] / sim_fps
    n_frames = max(1, round(duration_s * fps))
    times_s = np.arange(n_frames) / fps
    frames_qpos = resample_qpos(base_model, qpos, sim_fps, times_s)
    lookat = follow_lookat(base_model, frames_qpos, fps, cfg)
    targets = None
    if target_heights_m is not None:
        src = np.asarray(target_heights_m, dtype=float)
        # Step-hold, not interpolation: a marker shows the target of the sim step on screen.
        targets = src[np.minimum((times_s * sim_fps + 1e-9).astype(int), len(src) - 1)]
    out_path = Path(out_path)
    with tempfile.TemporaryDirectory(prefix="quaddance-video-") as tmp_name:
        tmp_dir = Path(tmp_name)
        jobs = _make_jobs(
            tmp_dir,
            base_model,
            frames_qpos,
            lookat,
            targets,
            min(workers, n_frames),
            width=width,
            height=height,
            fps=fps,
            cfg=cfg,
        )
        for job in jobs:
            job.segment = tmp_dir / f"segment{job.worker:02d}.mp4"
        cpu_before = _children_cpu_s()
        render_s = _run_workers(jobs, n_frames, progress, "Rendering video")
        worker_cpu_s = _children_cpu_s() - cpu_before

        mux_start = time.perf_counter()
        concat_list = tmp_dir / "segments.txt"
        concat_list.write_text("".join(f"file '{job.segment}'\n" for job in jobs))
        args = ["-v", "error", "-f", "concat", "-safe", "0", "-i", str(concat_list)]
        if audio is not None:
            args += ["-ss", f"{audio_offset_s:.6f}", "-i", str(audio)]
        args += ["-map", "0:v:0", "-c:v", "copy"]
        if audio is not None:
            args += ["-map", "1:a:0?", "-c:a", "aac", "-b:a", cfg.audio_bitrate]
        args += ["-t", f"{n_frames / fps:.6f}", "-movflags", "+faststart"]
        with atomic_path(out_path) as tmp_out:
            result = _ffmpeg([*args, str(tmp_out)])
            if result.returncode != 0:
                reason = result.stderr.strip().splitlines()[-1] if result.stderr.strip() else ""
                if audio is not None:
                    raise InputFileError(audio, f"ffmpeg could not mux this audio ({reason})")
                raise QuaddanceError(f"ffmpeg could not write {out_path} ({reason})")
        mux_s = time.perf_counter() - mux_start

    total_s = time.perf_counter() - total_start
    video_s = n_frames / fps
    return {
        "frames": n_frames,
        "fps": fps,
        "width": width,
        "height": height,
        "workers": len(jobs),
        "duration_s": video_s,
        "render_s": render_s,
        "worker_cpu_s": worker_cpu_s,
        "mux_s": mux_s,
        "total_s": total_s,
        "frames_per_s": n_frames / total_s,
        "realtime_factor": video_s / total_s,
    }


def write_frames_png(
    model: ModelSource,
    qpos_s: np.ndarray,
    sim_fps: float,
    times_s: Sequence[float],
    out_dir: str | Path,
    width: int = 640,
    height: int = 480,
    target_heights_m: np.ndarray | None = None,
    cfg: RenderCfg | None = None,
) -> list[Path]:
    """Render stills at the given sim times as PNGs, e.g. to check what a video shows.

    Args:
        model, qpos_s, sim_fps, target_heights_m, cfg: as in `render_video`.
        times_s: sim times of the stills, s.
        out_dir: folder for ``frame_<i>_<time>s.png``; created if missing.

    Returns:
        The PNG paths, in the order of ``times_s``.
    """
    cfg = cfg or RenderCfg()
    _check_size(width, height, 1.0)
    base_model = _load_model(model)
    qpos = _check_poses(base_model, qpos_s, sim_fps, target_heights_m)
    times = np.asarray(times_s, dtype=float).reshape(-1)
    if len(times) == 0:
        return []
    frames_qpos = resample_qpos(base_model, qpos, sim_fps, times)
    # The camera is smoothed over the whole trajectory, as in the video, then sampled.
    all_times = np.arange(max(1, round(qpos.shape[0] / sim_fps * 30.0))) / 30.0
    path_lookat = follow_lookat(
        base_model, resample_qpos(base_model, qpos, sim_fps, all_times), 30.0, cfg
    )
    lookat = np.stack([np.interp(times, all_times, col) for col in path_lookat.T], axis=1)
    targets = None
    if target_heights_m is not None:
        src = np.asarray(target_heights_m, dtype=float)
        targets = src[np.clip((times * sim_fps + 1e-9).astype(int), 0, len(src) - 1)]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    pngs = [out_dir / f"frame_{i:03d}_{t:07.2f}s.png" for i, t in enumerate(times)]
    with tempfile.TemporaryDirectory(prefix="quaddance-stills-") as tmp_name:
        (job,) = _make_jobs(
            Path(tmp_name),
            base_model,
            frames_qpos,
            lookat,
            targets,
            1,
            width=width,
            height=height,
            fps=30.0,
            cfg=cfg,
            pngs=pngs,
        )
        _run_workers([job], len(times), progress=False, label="Rendering stills")
    return pngs


def video_info(path: str | Path) -> dict[str, Any]:
    """Duration and streams of a video file as ffmpeg reports them (ffprobe is not shipped).

    Returns:
        ``duration_s`` (float or None), ``has_video``, ``has_audio`` (bool).
    """
    import re

    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "video file not found")
    text = _ffmpeg(["-i", str(path)]).stderr  # "-i" alone exits 1 after printing the header
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


def _bench_trajectory(model: mujoco.MjModel, n: int, sim_fps: float) -> np.ndarray:
    """Standing pose with the front-left leg swinging, (n, nq)."""
    qpos = np.tile(model.key_qpos[0] if model.nkey else model.qpos0, (n, 1))
    t = np.arange(n) / sim_fps
    thigh = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "FL_thigh_joint")
    if thigh >= 0:
        qpos[:, model.jnt_qposadr[thigh]] -= 0.6 * np.sin(np.pi * t) ** 2
    return qpos


def bench_render(
    out_json: str | Path,
    seconds: float = 10.0,
    width: int = 640,
    height: int = 480,
    fps: float = 30.0,
    worker_counts: Sequence[int] = (1, 2),
    progress: bool = True,
) -> dict[str, Any]:
    """Benchmark: video frames per second at 640x480 with 1 and 2 rendering processes.

    Renders ``seconds`` of a standing Go1 swinging a front leg, with a sine tone as the
    soundtrack, and writes the timings as JSON to ``out_json``. Wall-clock rates depend on
    what else runs on the machine (the load average is recorded); CPU milliseconds per
    frame do not, and give the rate on ``n`` idle cores as ``n * 1000 / cpu_ms_per_frame``.

    Returns:
        ``{"runs": [render_video timing + cpu_ms_per_frame], "cpu_count", "loadavg", ...}``.
    """
    import soundfile as sf

    model = _default_model()
    sim_fps = 50.0
    qpos = _bench_trajectory(model, int(seconds * sim_fps), sim_fps)
    runs = []
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="quaddance-bench-") as tmp:
        song = Path(tmp) / "tone.wav"
        sr = 22050
        tone = 0.2 * np.sin(2 * np.pi * 440.0 * np.arange(int(seconds * sr)) / sr)
        sf.write(song, tone.astype(np.float32), sr)
        for n in worker_counts:
            timing = render_video(
                model,
                qpos,
                sim_fps,
                Path(tmp) / f"bench{n}.mp4",
                audio_path=song,
                fps=fps,
                width=width,
                height=height,
                progress=progress,
                workers=n,
            )
            timing["cpu_ms_per_frame"] = 1000.0 * timing["worker_cpu_s"] / timing["frames"]
            runs.append(timing)
    result = {
        "name": "render",
        "cpu_count": os.cpu_count(),
        "loadavg_1min": [load_before, os.getloadavg()[0]],
        "gl": os.environ.get("MUJOCO_GL"),
        "seconds_of_video": seconds,
        "runs": runs,
        "note": "frames_per_s and realtime_factor include worker start-up, encoding, muxing",
    }
    write_json(out_json, result)
    return result
