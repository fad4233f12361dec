"""Headless video of a rollout, with the song as its soundtrack.

Frames are rendered on the CPU by MuJoCo's `mujoco.Renderer` through EGL and Mesa's software
rasteriser (llvmpipe; Debian packages libegl1, libegl-mesa0, libgl1-mesa-dri). OSMesa is not
used: it crashed in processes that had imported torch.

Rendering always runs in worker processes started with the 'spawn' method, never in the
caller: MuJoCo picks its GL backend once, when it is first imported, so only a fresh process
whose environment says ``MUJOCO_GL=egl`` is sure to get EGL. `VideoRenderer` starts the
workers before the poses exist (``dance`` creates it before the music analysis), so their
start-up (model, EGL context, a warm-up frame) overlaps the caller's work. The workers then
draw the frames round robin into shared memory (`_FrameSlots`) and the caller pipes them, in
order, into one ffmpeg (from
imageio-ffmpeg) that encodes H.264 and muxes the song as AAC, trimmed to the video, in the
same pass. Frame k shows sim time k / fps, and the song starts at ``audio_offset_s`` into the
file, so sound and motion stay in sync. A script that renders needs the usual ``if __name__
== "__main__":`` guard, because 'spawn' re-imports the main module in each worker (a worker
that dies that way is reported).

What makes it fast enough (640x480 on 2 cores, see `bench_render`): shadows, reflections and
multisampling are off, and the Go1's 206 k-triangle visual meshes are simplified in the
workers' private model copies by vertex clustering (`simplify_meshes`), which looks the same
at this size and renders several times faster on llvmpipe; the infinite floor is drawn as a
finite one with fewer quads (`finite_planes`).
"""

from __future__ import annotations

import contextlib
import errno
import multiprocessing as mp
import os
import queue as queue_module
import subprocess
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from quaddance.children import ignore_sigint, sigint_blocked_for_children
from quaddance.errors import InputFileError, QuaddanceError
from quaddance.fileio import atomic_path, write_json
from quaddance.play.metrics import gaussian_smooth
from quaddance.sim import go1

ModelSource = mujoco.MjModel | Callable[[], mujoco.MjModel] | None
"""A model to render, or a zero-argument function that builds one; None means the dance scene
with its visual meshes (`quaddance.sim.scene.build_model(visual=True)`)."""

VIDEO_FPS = 25.0
"""Frame rate of the videos, Hz. 25 divides the 50 Hz policy rate (each frame is a simulated
pose, none interpolated) and draws a sixth fewer frames than 30: rendering is most of the
`dance` command's CPU time on 2 cores (`quaddance bench dance`)."""

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
    #: An infinite floor plane is drawn as this finite square (half size, m) with quads of
    #: ``floor_grid_m``. MuJoCo draws an infinite plane with up to 200 x 200 quads
    #: (mjMAXPLANEGRID): 30 ms of llvmpipe's time per 640x480 frame, against 20 ms for 30 m
    #: with 0.5 m quads, which looks the same except for the haze line at the horizon
    #: (measured; 1.4 of 255 mean difference below it). None keeps infinite planes.
    floor_half_size_m: float | None = 30.0
    floor_grid_m: float = 0.5
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
    #: H.264 settings: encoding shares the cores with the software renderer, so the cheapest
    #: preset. 300 frames of a dance at 640x480: "veryfast" crf 20 took 2.1 s CPU (0.6 MB),
    #: "ultrafast" crf 23 0.9 s (1.9 MB), PSNR 43 dB between the two (measured).
    crf: int = 23
    preset: str = "ultrafast"
    #: x264 threads: 1 took 4.3 s CPU for 900 frames, x264's own choice 4.8 s, same file
    #: size (measured); the render workers keep the cores busy anyway.
    encoder_threads: int = 1
    audio_bitrate: str = "160k"
    #: ffmpeg's AAC search: "fast" took 0.44 s CPU for the 30 s demo song, the default
    #: "twoloop" 1.04 s (measured); the soundtrack of a robot video needs no more.
    aac_coder: str = "fast"


class RenderError(QuaddanceError):
    """Rendering failed in a worker; ``worker_traceback`` holds the worker's traceback."""

    def __init__(self, message: str, worker_traceback: str = "") -> None:
        super().__init__(message)
        self.worker_traceback = worker_traceback


# --- frame preparation (caller's process) -----------------------------------------------------


def _default_model() -> mujoco.MjModel:
    from quaddance.sim.scene import build_model

    return build_model(visual=True)


@dataclass(frozen=True)
class QposLayout:
    """What turning poses into frames needs to know of a model: a render worker reports it
    for the model it built, so the caller never compiles the visual model itself."""

    nq: int
    #: (start, stop) qpos ranges holding unit quaternions (free and ball joints).
    quat_ranges: tuple[tuple[int, int], ...]
    #: qpos address of the first free joint (the base position); None: no free joint.
    base_adr: int | None
    #: ``model.stat.center``: the look-at point of a model without a free joint, m.
    center: tuple[float, float, float]

    @classmethod
    def of(cls, model: mujoco.MjModel) -> QposLayout:
        quats, base = [], None
        for j in range(model.njnt):
            adr = int(model.jnt_qposadr[j])
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                quats.append((adr + 3, adr + 7))
                base = adr if base is None else base
            elif model.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
                quats.append((adr, adr + 4))
        center = tuple(float(c) for c in model.stat.center)
        return cls(int(model.nq), tuple(quats), base, center)  # type: ignore[arg-type]


def _layout(model: mujoco.MjModel | QposLayout) -> QposLayout:
    return model if isinstance(model, QposLayout) else QposLayout.of(model)


def resample_qpos(
    model: mujoco.MjModel | QposLayout, qpos_s: np.ndarray, sim_fps: float, times_s: np.ndarray
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
    quats = [slice(a, b) for a, b in _layout(model).quat_ranges]
    qpos = np.asarray(qpos_s, dtype=float)
    pos = np.clip(np.asarray(times_s, dtype=float) * sim_fps, 0.0, qpos.shape[0] - 1)
    i0 = np.floor(pos).astype(int)
    i1 = np.minimum(i0 + 1, qpos.shape[0] - 1)
    w = (pos - i0)[:, None]
    a, b = qpos[i0], qpos[i1].copy()
    for sl in quats:
        # q and -q are the same rotation: interpolate along the shorter arc.
        flip = np.sum(a[:, sl] * b[:, sl], axis=1) < 0
        b[flip, sl] *= -1.0
    out = (1.0 - w) * a + w * b
    for sl in quats:
        norm = np.linalg.norm(out[:, sl], axis=1, keepdims=True)
        out[:, sl] /= np.where(norm > 0, norm, 1.0)
    return out


def follow_lookat(
    model: mujoco.MjModel | QposLayout, qpos_frames: np.ndarray, fps: float, cfg: RenderCfg
) -> np.ndarray:
    """Smoothed look-at points of the follow camera, (N, 3) m, from the base position."""
    layout = _layout(model)
    if layout.base_adr is None:
        return np.tile(np.asarray(layout.center, dtype=float), (len(qpos_frames), 1))
    adr = layout.base_adr
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


def finite_planes(model: mujoco.MjModel, half_size_m: float, grid_m: float) -> int:
    """Make every infinite plane of ``model`` (size 0) a finite square, for drawing only.

    Its texture keeps its size on the floor: an infinite plane's material repeats
    ``texrepeat`` times per metre, as a finite plane's does with ``texuniform`` set (set
    only on a material that no other kind of geom uses).

    Returns:
        Number of planes changed.
    """
    changed = 0
    plane = model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE
    for g in np.flatnonzero(plane):
        if model.geom_size[g, 0] > 0 and model.geom_size[g, 1] > 0:
            continue
        model.geom_size[g] = (half_size_m, half_size_m, grid_m)
        mat = model.geom_matid[g]
        if mat >= 0 and not np.any(model.geom_matid[~plane] == mat):
            model.mat_texuniform[mat] = 1
        changed += 1
    return changed


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
        if cfg.floor_half_size_m:
            finite_planes(model, cfg.floor_half_size_m, cfg.floor_grid_m)
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
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """One frame, (height, width, 3) uint8.

        Args:
            qpos: (nq,) pose.
            lookat: (3,) follow-camera look-at point, m; ignored with a named camera.
            target_heights_m: (4,) targets (FL, FR, RL, RR), m: draws the front-foot markers.
            out: (height, width, 3) uint8 array to draw into (returned); None: a new one.
        """
        self.data.qpos[:] = qpos
        mujoco.mj_forward(self.model, self.data)
        if isinstance(self.camera, mujoco.MjvCamera) and lookat is not None:
            self.camera.lookat[:] = lookat
        self.renderer.update_scene(self.data, camera=self.camera, scene_option=self.option)
        if target_heights_m is not None:
            self._add_markers(np.asarray(target_heights_m, dtype=float))
        return self.renderer.render(out=out)

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


WORKER_NICE = 5
"""How much lower the render workers' scheduling priority is than the caller's (nice steps).
Their start-up is not on the critical path of `dance` on 2 cores, the song's analysis and the
policy's imports are: a lower priority hands those the cores first and the workers take the
idle moments; once frames come, the simulation that feeds them goes first too."""


def _lower_priority(pid: int, steps: int) -> None:
    """Make process ``pid`` ``steps`` nice steps less urgent than this one (best effort)."""
    if steps <= 0 or not hasattr(os, "setpriority"):
        return
    with contextlib.suppress(OSError):  # gone already, or not allowed
        os.setpriority(os.PRIO_PROCESS, pid, min(19, os.getpriority(os.PRIO_PROCESS, 0) + steps))


@dataclass(frozen=True)
class _WorkerSpec:
    """What a rendering process is started with. Only a path and settings: the spawn
    start-up pipe then carries a few kB, and a worker that dies while starting cannot block
    the caller (CPython keeps writing a large payload into the pipe of a dead child)."""

    worker: int
    n_workers: int
    model_path: Path | None  # a model saved by mj_saveModel; None: build the dance scene
    # Where the first worker to build the dance scene saves it for the others, which start
    # one at a time (None: each builds its own): loading it takes 0.08 s CPU, building it
    # 0.47 s (measured).
    built_model_path: Path | None
    width: int
    height: int
    cfg: RenderCfg
    frames_path: Path  # the `_FrameSlots` file the worker draws into


#: Frames a worker may render ahead of the encoder (0.9 MB each at 640x480): slack for
#: the workers' uneven speed without holding the song in memory.
_FRAMES_AHEAD = 8

#: Frame slots per worker. A worker's frame messages wait in a queue of ``_FRAMES_AHEAD``,
#: so when it draws frame k, the encoder has taken frame k - 1 - _FRAMES_AHEAD off the queue
#: and finished writing frame k - 2 - _FRAMES_AHEAD: frame k's slot, shared with k - _SLOTS,
#: is free.
_SLOTS = _FRAMES_AHEAD + 2


def _reserve(fd: int, size: int) -> None:
    """Give the file ``size`` bytes of storage now: posix_fallocate, or zeros written where
    the system or its file system has none (macOS, some network file systems)."""
    fallocate = getattr(os, "posix_fallocate", None)
    if fallocate is not None:
        try:
            fallocate(fd, 0, size)
            return
        except OSError as err:
            if err.errno not in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
                raise
    zeros = bytes(min(size, 1 << 20))
    done = 0
    while done < size:
        done += os.write(fd, zeros[: size - done])


class _FrameSlots:
    """The workers' frames, in a file that the caller and the workers map: a frame goes to
    the encoder without crossing a pipe (measured in isolation with 640x480 frames: 0.9 ms
    CPU per frame for the two processes together, against 6.3 ms through a pickling queue; a
    12 s clip has 300 frames). In /dev/shm (memory) when it has room, else in ``fallback_dir``; the
    space is reserved at once (`_reserve`), so a full disk is an error here, never a SIGBUS
    mid-video."""

    def __init__(self, fallback_dir: Path, n_workers: int, width: int, height: int) -> None:
        self.shape = self._shape(n_workers, width, height)
        size = int(np.prod(self.shape))
        shm = Path("/dev/shm")
        in_memory = False
        if shm.is_dir() and hasattr(os, "statvfs"):
            with contextlib.suppress(OSError):
                st = os.statvfs(shm)
                in_memory = st.f_bavail * st.f_frsize > 2 * size
        fd, name = tempfile.mkstemp(
            prefix="quaddance-frames-", dir=shm if in_memory else fallback_dir
        )
        self.path = Path(name)
        try:
            _reserve(fd, size)
            self._map = np.memmap(self.path, dtype=np.uint8, mode="r+", shape=self.shape)
        except OSError as err:
            self.close()
            raise QuaddanceError(
                f"no room for the video's frame buffers ({size / 1e6:.0f} MB) in "
                f"{self.path.parent}: {err.strerror or err}"
            ) from None
        finally:
            os.close(fd)

    @staticmethod
    def _shape(n_workers: int, width: int, height: int) -> tuple[int, ...]:
        return (n_workers, _SLOTS, height, width, 3)

    @classmethod
    def attach(cls, path: Path, worker: int, n_workers: int, width: int, height: int) -> np.ndarray:
        """A worker's (``_SLOTS``, height, width, 3) slots in the file at ``path``."""
        shape = cls._shape(n_workers, width, height)
        return np.memmap(path, dtype=np.uint8, mode="r+", shape=shape)[worker]

    def frame(self, worker: int, slot: int) -> memoryview:
        """The bytes of one slot, without a copy."""
        return memoryview(self._map[worker, slot]).cast("B")

    def close(self) -> None:
        self._map = None  # unmapped once the last view is gone
        with contextlib.suppress(OSError):
            self.path.unlink()


#: Sim steps between hand-outs of frames while poses stream in (0.5 s at 50 Hz): each
#: hand-out recomputes the camera path of the frames so far, so not every step.
_STREAM_EVERY = 25


def _parent_alive() -> bool:
    parent = mp.parent_process()
    return parent is None or parent.is_alive()


def _put(out: Any, item: tuple[str, Any]) -> None:
    """Put on a bounded queue, giving up when the caller has died (nobody would read)."""
    while True:
        try:
            out.put(item, timeout=1.0)
            return
        except queue_module.Full:
            if not _parent_alive():
                raise SystemExit(1) from None


def _next_job(jobs: Any) -> Any:
    """The next message from the caller; None when told to stop or when the caller died."""
    while True:
        try:
            return jobs.get(timeout=1.0)
        except queue_module.Empty:
            if not _parent_alive():
                return None


def _worker(spec: _WorkerSpec, jobs: Any, out: Any, startup: Any) -> None:
    """Entry point of a rendering process.

    Start-up (model, EGL context, a warm-up frame: llvmpipe compiles its shaders on the
    first draw) happens at once; then the worker reports the model's `QposLayout` and draws
    what it is sent: chunks of frames ("frames", first index, qpos, lookat, targets or None)
    of which it takes every ``n_workers``-th frame from frame ``worker`` on, putting each
    image on ``out`` in order, until "end"; or ("stills", arrays, png paths).

    The workers start up one at a time (``startup``, a semaphore): meanwhile the caller is
    the critical path (music analysis) and keeps a core of a 2-core machine to itself.
    """
    ignore_sigint()  # the caller handles Ctrl-C
    if spec.n_workers > 1:
        # The workers are the parallelism: llvmpipe's own rasteriser threads only add
        # hand-offs (measured 27.7 -> 23.8 ms CPU per 640x480 frame single-threaded). Read
        # when the EGL context is made, so set before `FrameRenderer`; a user's value wins.
        os.environ.setdefault("LP_NUM_THREADS", "0")
    try:
        while not startup.acquire(timeout=1.0):
            if not _parent_alive():
                return
        try:
            if spec.model_path is not None:
                model = mujoco.MjModel.from_binary_path(str(spec.model_path))
            elif spec.built_model_path is not None and spec.built_model_path.is_file():
                model = mujoco.MjModel.from_binary_path(str(spec.built_model_path))
            else:
                model = _default_model()
                if spec.built_model_path is not None and spec.n_workers > 1:
                    with atomic_path(spec.built_model_path) as tmp:
                        mujoco.mj_saveModel(model, str(tmp), None)
            layout = QposLayout.of(model)
            frames = FrameRenderer(model, spec.width, spec.height, spec.cfg)
            frames.render(model.qpos0)
        finally:
            startup.release()
        slots = _FrameSlots.attach(
            spec.frames_path, spec.worker, spec.n_workers, spec.width, spec.height
        )
        drawn = 0  # frames drawn: frame j goes into slot j % _SLOTS
        # Wall-clock time (comparable across processes) and this process's CPU so far.
        _put(out, ("ready", (layout, time.time(), time.process_time())))
        start = None
        while (job := _next_job(jobs)) is not None:
            start = start or time.perf_counter()
            if job[0] == "end":
                break
            if job[0] == "stills":
                _, arrays, pngs = job
                targets = arrays.get("targets")
                for k in range(spec.worker, len(pngs), spec.n_workers):
                    tk = None if targets is None else targets[k]
                    _write_png(pngs[k], frames.render(arrays["qpos"][k], arrays["lookat"][k], tk))
                    _put(out, ("frame", None))
                break
            _, first, qpos, lookat, targets = job
            for i in range((spec.worker - first) % spec.n_workers, len(qpos), spec.n_workers):
                slot = drawn % _SLOTS
                tk = None if targets is None else targets[i]
                frames.render(qpos[i], lookat[i], tk, out=slots[slot])
                drawn += 1
                _put(out, ("frame", slot))
        else:
            return  # told to stop (or the caller died) before the end
        _put(out, ("done", time.perf_counter() - (start or time.perf_counter())))
    except (EOFError, SystemExit):
        return  # the caller went away
    except BaseException:
        _put(out, ("error", traceback.format_exc()))


def _write_png(path: Path, image: np.ndarray) -> None:
    import imageio.v3 as iio

    with atomic_path(path) as tmp:
        iio.imwrite(tmp, image, extension=".png")


class VideoRenderer:
    """Rendering processes started ahead of the poses they will draw.

    Creating one spawns the workers at once; each builds (or loads) the model, makes its EGL
    context and draws a warm-up frame while the caller goes on analysing the music. Then
    `stream` opens the video: poses can be added while the dance is still being simulated
    (`VideoStream.add`), and frames are handed out round robin as soon as their camera
    position is known; one ffmpeg encodes them in order (H.264) and muxes the song (AAC) in
    the same pass. `render` (all poses at once) and `start` are shorthands. One video per
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
        """
        Args:
            model: as in `render_video`; None (the dance scene) is built in the workers, not
                here, so the caller does not wait for the compilation.
            width, height: frame size in pixels (even).
            workers: rendering processes; one per core is fastest.
            cfg: look, camera and encoder settings.
        """
        _check_size(width, height, 1.0)
        if workers < 1:
            raise QuaddanceError(f"workers must be >= 1, got {workers}")
        self.width, self.height, self.n_workers = width, height, workers
        self.cfg = cfg or RenderCfg()
        self._created = time.time()
        self._ready_at: list[float] = []  # time.time() at which each worker was ready
        self._startup_cpu_s: list[float] = []
        self._tmp = tempfile.TemporaryDirectory(prefix="quaddance-video-")
        self._tmp_dir = Path(self._tmp.name)
        self._layout: QposLayout | None = None
        self._layout_known = threading.Event()
        model_path = None
        if model is not None:
            base = _load_model(model)
            self._layout = QposLayout.of(base)
            self._layout_known.set()
            model_path = self._tmp_dir / "model.mjb"
            mujoco.mj_saveModel(base, str(model_path), None)
        self._cpu_before = _children_cpu_s()
        self._used = False
        self._task: RenderTask | None = None
        self._encoder: subprocess.Popen[bytes] | None = None
        self._ready: list[bool] = [False] * workers
        self._jobs: list[Any] = []
        self._outs: list[Any] = []
        self._procs: list[Any] = []
        # The workers inherit this environment; MuJoCo reads MUJOCO_GL when they import it.
        # A user's backend wins; "disable" is what the command line sets for itself.
        if os.environ.get("MUJOCO_GL", "").strip().lower() in ("", "disable"):
            os.environ["MUJOCO_GL"] = "egl"
        ctx = mp.get_context("spawn")
        # Kept on self: the workers open it by name after __init__ has returned.
        self._startup = startup = ctx.Semaphore(1)
        built = self._tmp_dir / "scene.mjb" if model_path is None else None
        self._slots: _FrameSlots | None = None
        try:
            self._slots = _FrameSlots(self._tmp_dir, workers, width, height)
            for i in range(workers):
                spec = _WorkerSpec(
                    i, workers, model_path, built, width, height, self.cfg, self._slots.path
                )
                # Unbounded: handing out frames must never hold up the simulation.
                jobs = ctx.Queue()
                out = ctx.Queue(maxsize=_FRAMES_AHEAD)
                proc = ctx.Process(target=_worker, args=(spec, jobs, out, startup), daemon=True)
                with sigint_blocked_for_children():  # the caller handles Ctrl-C
                    proc.start()
                _lower_priority(proc.pid, WORKER_NICE)
                self._jobs.append(jobs)
                self._outs.append(out)
                self._procs.append(proc)
        except BaseException:
            self.close()
            raise

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
        if task_running and self._encoder is not None and self._encoder.poll() is None:
            self._encoder.kill()
        for jobs, proc in zip(self._jobs, self._procs, strict=False):
            if proc.is_alive():
                with contextlib.suppress(OSError, ValueError):  # it died meanwhile
                    jobs.put(None)
        for proc in self._procs:
            # A worker with no job (an error before rendering) need not finish starting up.
            proc.join(timeout=2.0 if self._used and not task_running else 0.1)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=5.0)
        if self._task is not None:
            self._task.join(timeout=10.0)
        for q in self._jobs + self._outs:
            q.cancel_join_thread()  # messages nobody will read must not block our exit
            q.close()
        self._jobs, self._outs, self._procs = [], [], []
        if self._slots is not None:
            self._slots.close()
        self._tmp.cleanup()

    # -- messages from the workers (read only by the thread that encodes)

    def _receive(self, worker: int) -> tuple[str, Any]:
        """The next message of one worker; raises RenderError if it failed or died."""
        out, proc = self._outs[worker], self._procs[worker]
        while True:
            try:
                kind, payload = out.get(timeout=1.0)
            except queue_module.Empty:
                if proc.exitcode is None:
                    continue
                try:  # its last words may still be in the pipe
                    kind, payload = out.get(timeout=1.0)
                except queue_module.Empty:
                    raise RenderError(
                        f"render worker {worker} exited with code {proc.exitcode} "
                        "(see its output above; a calling script needs an "
                        "'if __name__ == \"__main__\":' guard; headless rendering needs EGL, "
                        f"Debian: {EGL_PACKAGES})"
                    ) from None
            if kind == "error":
                last = payload.strip().splitlines()[-1] if payload.strip() else "unknown error"
                raise RenderError(
                    f"rendering failed: {last} (headless rendering needs EGL; Debian: "
                    f"{EGL_PACKAGES})",
                    worker_traceback=payload,
                )
            return kind, payload

    def _wait_ready(self, worker: int) -> None:
        if not self._ready[worker]:
            kind, (layout, ready_at, cpu_s) = self._receive(worker)
            assert kind == "ready", kind
            self._ready[worker] = True
            if self._layout is None:
                self._layout = layout
                self._layout_known.set()
            self._ready_at.append(ready_at)
            self._startup_cpu_s.append(cpu_s)

    def _claim(self) -> None:
        if self._used:
            raise QuaddanceError("a VideoRenderer renders one video; make a new one")
        self._used = True

    def _send(self, job: tuple[Any, ...]) -> None:
        for jobs in self._jobs:
            jobs.put(job)

    # -- the video

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
        _check_size(self.width, self.height, fps)
        if audio_offset_s < 0 or not np.isfinite(audio_offset_s):
            raise QuaddanceError(f"audio_offset_s must be >= 0, got {audio_offset_s}")
        if not sim_fps > 0:
            raise QuaddanceError(f"sim_fps must be > 0, got {sim_fps}")
        if n_poses < 1:
            raise QuaddanceError(f"a video needs at least one pose, got {n_poses}")
        audio = Path(audio_path) if audio_path is not None else None
        if audio is not None:
            _check_audio(audio)
        self._claim()
        n_frames = max(1, round(n_poses / sim_fps * fps))
        args = _encoder_args(
            self.width, self.height, fps, n_frames, audio, audio_offset_s, self.cfg
        )
        task = RenderTask(self, args, Path(out_path), n_frames, fps, progress)
        self._task = task
        task.begin()
        return VideoStream(self, task, n_poses, sim_fps, fps, target_markers)

    def render(
        self,
        qpos_s: np.ndarray,
        sim_fps: float,
        out_path: str | Path,
        audio_path: str | Path | None = None,
        audio_offset_s: float = 0.0,
        fps: float = VIDEO_FPS,
        target_heights_m: np.ndarray | None = None,
        progress: bool = True,
    ) -> dict[str, Any]:
        """Render the video and wait for it; the arguments and result are `render_video`'s."""
        return self.start(
            qpos_s, sim_fps, out_path, audio_path, audio_offset_s, fps, target_heights_m, progress
        ).wait()

    def start(
        self,
        qpos_s: np.ndarray,
        sim_fps: float,
        out_path: str | Path,
        audio_path: str | Path | None = None,
        audio_offset_s: float = 0.0,
        fps: float = VIDEO_FPS,
        target_heights_m: np.ndarray | None = None,
        progress: bool = True,
    ) -> RenderTask:
        """Start rendering all poses at once in a background thread; `RenderTask.wait`
        returns the timing or raises. Arguments are checked here, before anything starts."""
        qpos = np.asarray(qpos_s, dtype=float)
        nq = self._layout.nq if self._layout is not None else qpos.shape[-1]
        qpos = _check_poses(nq, qpos, sim_fps, target_heights_m)
        stream = self.stream(
            len(qpos), sim_fps, out_path, audio_path, audio_offset_s, fps,
            target_heights_m is not None, progress,
        )  # fmt: skip
        stream.add(qpos, target_heights_m)
        return stream.finish()

    def _encode(self, task: RenderTask) -> dict[str, Any]:
        """Pipe the workers' frames, in order, into ffmpeg (runs in the task thread)."""
        wait_start = time.perf_counter()
        for i in range(self.n_workers):
            self._wait_ready(i)
        ready = time.perf_counter()
        bar = _Progress(task.progress, "Rendering video", task.n_frames)
        try:
            with atomic_path(task.out_path) as tmp_out:
                err_path = self._tmp_dir / "ffmpeg.log"
                with open(err_path, "wb") as err:
                    cmd = [_ffmpeg_exe(), "-hide_banner", "-y", *task.args, str(tmp_out)]
                    proc = subprocess.Popen(
                        cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=err
                    )
                    self._encoder = proc
                try:
                    assert proc.stdin is not None
                    assert self._slots is not None
                    for k in range(task.n_frames):
                        worker = k % self.n_workers
                        _, slot = self._receive(worker)
                        try:
                            proc.stdin.write(self._slots.frame(worker, slot))
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
                    raise QuaddanceError(f"ffmpeg could not write {task.out_path} ({reason})")
            encode_end = time.perf_counter()
        finally:
            bar.close()
        for i in range(self.n_workers):
            kind, _ = self._receive(i)
            assert kind == "done", kind
        for proc_ in self._procs:
            proc_.join(timeout=5.0)
        total_s = encode_end - task.total_start
        video_s = task.n_frames / task.fps
        return {
            "frames": task.n_frames,
            "fps": task.fps,
            "width": self.width,
            "height": self.height,
            "workers": min(self.n_workers, task.n_frames),
            "duration_s": video_s,
            "startup_wait_s": ready - wait_start,
            "workers_ready_s": max(self._ready_at) - self._created,
            "worker_startup_cpu_s": sum(self._startup_cpu_s),
            "render_s": encode_end - ready,
            "tail_s": encode_end - (task.poses_done or encode_end),
            "worker_cpu_s": _children_cpu_s() - self._cpu_before,
            "mux_s": encode_end - frames_done,
            "total_s": total_s,
            "frames_per_s": task.n_frames / total_s,
            "realtime_factor": video_s / total_s,
        }

    def stills(self, arrays: dict[str, np.ndarray], pngs: list[Path]) -> None:
        """Draw the frames in ``arrays`` as PNGs at ``pngs`` (one each) and wait for them."""
        self._claim()
        self._send(("stills", arrays, pngs))
        for i in range(self.n_workers):
            self._wait_ready(i)
        for k in range(len(pngs)):
            self._receive(k % self.n_workers)
        for i in range(self.n_workers):
            self._receive(i)


class VideoStream:
    """Poses going into a video while the simulation makes them (see `VideoRenderer.stream`).

    Frame k shows sim time k / fps: it is drawn once the poses around that time and those
    the camera smoothing looks ahead to are in, so the frames are exactly those of a video
    rendered from the whole trajectory at once.
    """

    def __init__(
        self,
        renderer: VideoRenderer,
        task: RenderTask,
        n_poses: int,
        sim_fps: float,
        fps: float,
        target_markers: bool,
    ) -> None:
        self._renderer, self._task = renderer, task
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
        self._ahead = int(np.ceil(4.0 * renderer.cfg.smooth_s * fps)) + 1

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
        renderer, task = self._renderer, self._task
        if not renderer._layout_known.is_set():
            if not final:
                return  # the first worker is still starting: hand out later, don't wait
            while not renderer._layout_known.wait(0.2):
                if not task.running():
                    return  # the task failed; wait() raises its error
        layout = renderer._layout
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
            renderer._send(("end",))

    def _send_frames(self, known: int) -> None:
        """Hand out frames [sent, known): their poses and camera path are complete."""
        renderer, layout = self._renderer, self._renderer._layout
        assert layout is not None and self._qpos is not None
        frames = resample_qpos(
            layout, self._qpos, self.sim_fps, self._times_s[: known + self._ahead]
        )
        lookat = follow_lookat(layout, frames, self.fps, renderer.cfg)
        new = slice(self._sent, known)
        targets = None
        if self._targets is not None:
            # Step-hold, not interpolation: a marker shows the target of the sim step on screen.
            idx = np.minimum(
                (self._times_s[new] * self.sim_fps + 1e-9).astype(int), self.n_poses - 1
            )
            targets = self._targets[idx]
        renderer._send(("frames", self._sent, frames[new], lookat[new], targets))
        self._sent = known


class RenderTask:
    """A video being encoded by a `VideoRenderer` in a background thread."""

    def __init__(
        self,
        renderer: VideoRenderer,
        args: list[str],
        out_path: Path,
        n_frames: int,
        fps: float,
        progress: bool,
    ) -> None:
        self.renderer, self.args, self.out_path = renderer, args, out_path
        self.n_frames, self.fps, self.progress = n_frames, fps, progress
        self.total_start = time.perf_counter()
        self.poses_done: float | None = None  # when the last pose came in
        self._result: dict[str, Any] | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="quaddance-video", daemon=True)

    def begin(self) -> None:
        self._thread.start()

    def running(self) -> bool:
        return self._thread.is_alive()

    def join(self, timeout: float) -> None:
        self._thread.join(timeout)

    def _run(self) -> None:
        try:
            self._result = self.renderer._encode(self)
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
    nq: int, qpos_s: np.ndarray, sim_fps: float, targets: np.ndarray | None
) -> np.ndarray:
    qpos = np.asarray(qpos_s, dtype=float)
    if qpos.ndim != 2 or qpos.shape[1] != nq or qpos.shape[0] < 1:
        raise QuaddanceError(f"qpos_s must be (T, {nq}) with T >= 1, got {qpos.shape}")
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


def _ffmpeg_exe() -> str:
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


def _ffmpeg(args: list[str]) -> subprocess.CompletedProcess[str]:
    cmd = [_ffmpeg_exe(), "-hide_banner", "-nostdin", "-y", *args]
    return subprocess.run(cmd, capture_output=True, text=True, check=False)


def _check_audio(audio_path: Path) -> None:
    """Fail before rendering, not after, when ffmpeg cannot decode the song."""
    if not audio_path.is_file():
        raise InputFileError(audio_path, "audio file not found")
    probe = _ffmpeg(["-v", "error", "-i", str(audio_path), "-t", "0.1", "-vn", "-f", "null", "-"])
    if probe.returncode != 0:
        reason = probe.stderr.strip().splitlines()[-1] if probe.stderr.strip() else "unknown"
        raise InputFileError(audio_path, f"ffmpeg cannot decode this audio ({reason})")


def _encoder_args(
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
    _check_size(width, height, fps)
    if workers < 1:
        raise QuaddanceError(f"workers must be >= 1, got {workers}")
    if audio_offset_s < 0 or not np.isfinite(audio_offset_s):
        raise QuaddanceError(f"audio_offset_s must be >= 0, got {audio_offset_s}")
    if audio_path is not None:
        _check_audio(Path(audio_path))
    base_model = _load_model(model)
    _check_poses(base_model.nq, qpos_s, sim_fps, target_heights_m)
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
    layout = QposLayout.of(base_model)
    qpos = _check_poses(layout.nq, qpos_s, sim_fps, target_heights_m)
    times = np.asarray(times_s, dtype=float).reshape(-1)
    if len(times) == 0:
        return []
    frames_qpos = resample_qpos(layout, qpos, sim_fps, times)
    # The camera is smoothed over the whole trajectory, as in the video, then sampled.
    all_times = np.arange(max(1, round(qpos.shape[0] / sim_fps * VIDEO_FPS))) / VIDEO_FPS
    path_lookat = follow_lookat(
        layout, resample_qpos(layout, qpos, sim_fps, all_times), VIDEO_FPS, cfg
    )
    lookat = np.stack([np.interp(times, all_times, col) for col in path_lookat.T], axis=1)
    arrays = {"qpos": frames_qpos, "lookat": lookat}
    if target_heights_m is not None:
        src = np.asarray(target_heights_m, dtype=float)
        arrays["targets"] = src[np.clip((times * sim_fps + 1e-9).astype(int), 0, len(src) - 1)]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    pngs = [out_dir / f"frame_{i:03d}_{t:07.2f}s.png" for i, t in enumerate(times)]
    with VideoRenderer(base_model, width, height, workers=1, cfg=cfg) as renderer:
        renderer.stills(arrays, pngs)
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
    fps: float = VIDEO_FPS,
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
