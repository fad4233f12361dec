"""The render workers: processes that draw frames into shared memory (`WorkerPool`).

Rendering always runs in worker processes started with the 'spawn' method, never in the
caller: MuJoCo picks its GL backend once, when it is first imported, so only a fresh process
whose environment says ``MUJOCO_GL=egl`` is sure to get EGL. The pool starts the workers
before the poses exist (``dance`` creates its `VideoRenderer` before the music analysis), so
their start-up (model, EGL context, a warm-up frame) overlaps the caller's work, at a lower
scheduling priority (`WORKER_NICE`). The workers then draw the frames round robin into a
ring of shared-memory slots (`FrameSlots`) and report each slot on a bounded queue. A script
that renders needs the usual ``if __name__ == "__main__":`` guard, because 'spawn' re-imports
the main module in each worker (a worker that dies that way is reported).
"""

from __future__ import annotations

import contextlib
import errno
import multiprocessing as mp
import os
import queue as queue_module
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from quaddance.children import ignore_sigint, sigint_blocked_for_children
from quaddance.errors import QuaddanceError
from quaddance.fileio import atomic_path
from quaddance.play.video.config import EGL_PACKAGES, RenderCfg, RenderError, check_size
from quaddance.play.video.poses import QposLayout
from quaddance.play.video.scene import FrameRenderer, ModelSource, default_model, load_model

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
    frames_path: Path  # the `FrameSlots` file the worker draws into


#: Frames a worker may render ahead of the encoder (0.9 MB each at 640x480): slack for
#: the workers' uneven speed without holding the song in memory.
_FRAMES_AHEAD = 8

#: Frame slots per worker. A worker's frame messages wait in a queue of ``_FRAMES_AHEAD``,
#: so when it draws frame k, the encoder has taken frame k - 1 - _FRAMES_AHEAD off the queue
#: and finished writing frame k - 2 - _FRAMES_AHEAD: frame k's slot, shared with k - SLOTS,
#: is free.
SLOTS = _FRAMES_AHEAD + 2


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


class FrameSlots:
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
        return (n_workers, SLOTS, height, width, 3)

    @classmethod
    def attach(cls, path: Path, worker: int, n_workers: int, width: int, height: int) -> np.ndarray:
        """A worker's (``SLOTS``, height, width, 3) slots in the file at ``path``."""
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
                model = default_model(spec.cfg.robot)
                if spec.built_model_path is not None and spec.n_workers > 1:
                    with atomic_path(spec.built_model_path) as tmp:
                        mujoco.mj_saveModel(model, str(tmp), None)
            layout = QposLayout.of(model)
            frames = FrameRenderer(model, spec.width, spec.height, spec.cfg)
            frames.render(model.qpos0)
        finally:
            startup.release()
        slots = FrameSlots.attach(
            spec.frames_path, spec.worker, spec.n_workers, spec.width, spec.height
        )
        drawn = 0  # frames drawn: frame j goes into slot j % SLOTS
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
                slot = drawn % SLOTS
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


def children_cpu_s() -> float:
    """CPU seconds of finished child processes (and the children they waited for)."""
    import resource

    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


class WorkerPool:
    """Rendering processes, started at once, and the frame slots they draw into.

    Each worker builds (or loads) the model, makes its EGL context and draws a warm-up frame
    while the caller goes on with its work; then it draws the jobs `send` gives it. Its
    messages are read with `receive` by one thread of the caller. `close` always ends them.
    """

    def __init__(
        self,
        model: ModelSource,
        width: int,
        height: int,
        workers: int,
        cfg: RenderCfg,
    ) -> None:
        """
        Args:
            model: as in `render_video`; None (the dance scene) is built in the workers, not
                here, so the caller does not wait for the compilation.
            width, height: frame size in pixels (even).
            workers: rendering processes; one per core is fastest.
            cfg: look and camera settings.
        """
        check_size(width, height, 1.0)
        if workers < 1:
            raise QuaddanceError(f"workers must be >= 1, got {workers}")
        self.width, self.height, self.n_workers, self.cfg = width, height, workers, cfg
        self.created = time.time()
        self.ready_at: list[float] = []  # time.time() at which each worker was ready
        self.startup_cpu_s: list[float] = []
        self._tmp = tempfile.TemporaryDirectory(prefix="quaddance-video-")
        self.tmp_dir = Path(self._tmp.name)
        #: The model's qpos layout: known at once when the caller gives the model, else when
        #: the first worker has built it (``layout_known`` is set then).
        self.layout: QposLayout | None = None
        self.layout_known = threading.Event()
        model_path = None
        if model is not None:
            base = load_model(model, cfg.robot)
            self.layout = QposLayout.of(base)
            self.layout_known.set()
            model_path = self.tmp_dir / "model.mjb"
            mujoco.mj_saveModel(base, str(model_path), None)
        self.cpu_before = children_cpu_s()
        self._ready: list[bool] = [False] * workers
        self._jobs: list[Any] = []
        self._outs: list[Any] = []
        self.procs: list[Any] = []
        # The workers inherit this environment; MuJoCo reads MUJOCO_GL when they import it.
        # A user's backend wins; "disable" is what the command line sets for itself.
        if os.environ.get("MUJOCO_GL", "").strip().lower() in ("", "disable"):
            os.environ["MUJOCO_GL"] = "egl"
        ctx = mp.get_context("spawn")
        # Kept on self: the workers open it by name after __init__ has returned.
        self._startup = startup = ctx.Semaphore(1)
        built = self.tmp_dir / "scene.mjb" if model_path is None else None
        self.slots: FrameSlots | None = None
        try:
            self.slots = FrameSlots(self.tmp_dir, workers, width, height)
            for i in range(workers):
                spec = _WorkerSpec(
                    i, workers, model_path, built, width, height, self.cfg, self.slots.path
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
                self.procs.append(proc)
        except BaseException:
            self.close()
            raise

    def stop(self, grace_s: float) -> None:
        """Tell the workers to stop; those still running after ``grace_s`` are terminated."""
        for jobs, proc in zip(self._jobs, self.procs, strict=False):
            if proc.is_alive():
                with contextlib.suppress(OSError, ValueError):  # it died meanwhile
                    jobs.put(None)
        for proc in self.procs:
            proc.join(timeout=grace_s)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=5.0)

    def close(self, grace_s: float = 0.1) -> None:
        """Stop the workers (if still running; see `stop`) and remove the temporary files.
        The default grace is short: a worker with no job need not finish starting up."""
        self.stop(grace_s)
        for q in self._jobs + self._outs:
            q.cancel_join_thread()  # messages nobody will read must not block our exit
            q.close()
        self._jobs, self._outs, self.procs = [], [], []
        if self.slots is not None:
            self.slots.close()
        self._tmp.cleanup()

    def send(self, job: tuple[Any, ...]) -> None:
        """Give every worker the same job (each takes its own share of the frames)."""
        for jobs in self._jobs:
            jobs.put(job)

    def receive(self, worker: int) -> tuple[str, Any]:
        """The next message of one worker; raises RenderError if it failed or died."""
        out, proc = self._outs[worker], self.procs[worker]
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

    def wait_ready(self) -> None:
        """Wait until every worker has started up (its first message)."""
        for worker in range(self.n_workers):
            if not self._ready[worker]:
                kind, (layout, ready_at, cpu_s) = self.receive(worker)
                assert kind == "ready", kind
                self._ready[worker] = True
                if self.layout is None:
                    self.layout = layout
                    self.layout_known.set()
                self.ready_at.append(ready_at)
                self.startup_cpu_s.append(cpu_s)
