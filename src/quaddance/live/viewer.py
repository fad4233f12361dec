"""Web viewer for `quaddance live`: the robot, the tempo, the beats and the current move.

A viser server (the library behind mjlab's viewer) serves a page that any browser can open,
also from another machine when bound to 0.0.0.0; the server itself needs no display. The robot
is put into the viser scene by mjviser, as mjlab does.

The control loop calls `update`, `set_status` and `beat` at up to 50 Hz. They only store the
newest values under a lock (microseconds); one worker thread pushes them to the browser at
`render_hz`, so rendering and the network never hold up the loop.

    python -m quaddance.live.viewer --demo      # the robot standing, a fake beat every 0.5 s
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import html
import io
import math
import os
import socket
import sys
import threading
import time
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.robots import GO1, ROBOTS, get_robot

if TYPE_CHECKING:  # viser takes seconds to import: only LiveViewer() imports it.
    import viser
    from mjviser.scene import ViserMujocoScene

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8080
DEFAULT_RENDER_HZ = 30.0
BEAT_FLASH_S = 0.12  # long enough to see at 30 Hz, short enough for 200 BPM
BEAT_LIST_LEN = 8
BEAT_PLOT_LEN = 32

_COLLISION_GROUP = 3  # mjlab's Go1: collision geoms; visual meshes are in group 2
_VISIBLE_GROUPS = (0, 1, 2)  # the groups mjviser shows by default
_DISC_RADIUS_M = 0.5
_DISC_HEIGHT_M = 0.004
_DISC_OFF_RGB = (120, 130, 150)
_BEAT_RGB = (255, 180, 0)
_DOWNBEAT_RGB = (230, 40, 40)
# Looking a little right of the robot puts it left of centre, clear of the control panel.
_CAMERA_POS_M = (1.08, -0.75, 0.5)
_CAMERA_LOOK_AT_M = (0.08, 0.1, 0.2)
_CAMERA_FOV_RAD = math.radians(55.0)


@dataclass(frozen=True)
class LiveStatus:
    """What the tracker and the choreographer say now."""

    tempo_bpm: float | None = None
    locked: bool = False
    move: str = "-"
    song_time_s: float = 0.0


@dataclass(frozen=True)
class DetectedBeat:
    """One beat as the online tracker reported it."""

    t_s: float
    downbeat: bool


def viewer_urls(host: str, port: int) -> list[str]:
    """The addresses to open in a browser; a wildcard host also gets this machine's name."""
    if host in ("0.0.0.0", "", "::"):
        return [f"http://127.0.0.1:{port}", f"http://{socket.gethostname()}:{port}"]
    shown = f"[{host}]" if ":" in host else host
    return [f"http://{shown}:{port}"]


def status_html(status: LiveStatus) -> str:
    """The status block: tempo, lock state, move and song time."""
    tempo = "-- BPM" if status.tempo_bpm is None else f"{status.tempo_bpm:.1f} BPM"
    lock_bg, lock_text = ("#2e7d32", "LOCKED") if status.locked else ("#616161", "searching")
    return (
        '<div id="qd-status" style="font-family:sans-serif;line-height:1.6;padding:4px 8px">'
        f'<div style="font-size:1.7em;font-weight:bold" id="qd-tempo">{tempo}</div>'
        f'<div>beat: <span id="qd-lock" style="background:{lock_bg};color:#fff;'
        f'padding:1px 8px;border-radius:4px">{lock_text}</span></div>'
        f'<div>move: <b id="qd-move">{html.escape(status.move)}</b></div>'
        f'<div>song time: <span id="qd-time">{status.song_time_s:.1f} s</span></div>'
        "</div>"
    )


def beat_indicator_html(beat: DetectedBeat | None, count: int, lit: bool) -> str:
    """A lamp that lights on each beat (red on a downbeat) and the number of beats so far."""
    rgb = _DISC_OFF_RGB
    if lit and beat is not None:
        rgb = _DOWNBEAT_RGB if beat.downbeat else _BEAT_RGB
    label = "no beat yet" if beat is None else f"beat {count} at {beat.t_s:.2f} s"
    return (
        '<div style="font-family:sans-serif;display:flex;align-items:center;gap:10px;'
        'padding:4px 8px">'
        f'<div id="qd-lamp" style="width:28px;height:28px;border-radius:50%;'
        f'background:rgb{rgb}"></div><span id="qd-beat-count">{label}</span></div>'
    )


def beat_list_markdown(beats: Sequence[DetectedBeat]) -> str:
    """The newest detected beats, newest first."""
    if not beats:
        return "**Detected beats**: none yet"
    rows = [
        f"- {b.t_s:7.2f} s{' **downbeat**' if b.downbeat else ''}"
        for b in reversed(list(beats)[-BEAT_LIST_LEN:])
    ]
    return "**Detected beats** (newest first)\n\n" + "\n".join(rows)


def beat_plot_data(beats: Sequence[DetectedBeat]) -> tuple[np.ndarray, np.ndarray]:
    """(beat time s, beat-to-beat tempo BPM) of the newest beats, from the second one on.

    Each point is a detected beat, placed at the tempo its interval to the previous beat
    implies: a steady grid is a flat line, a missed or extra beat stands out.
    """
    t_s = np.array([b.t_s for b in list(beats)[-BEAT_PLOT_LEN:]], dtype=np.float64)
    gaps_s = np.maximum(np.diff(t_s), 1e-3)  # a repeated time must not divide by zero
    return t_s[1:], 60.0 / gaps_s


def displayable_model(model: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of `model` whose robot mjviser shows by default.

    mjviser edits the model's visual settings, hence the copy. A physics model built with
    `visual=False` has only collision geoms (group 3, hidden by default): those are moved
    into a shown group so that the robot is still drawn, as boxes and capsules.
    """
    shown = copy.deepcopy(model)
    robot = shown.geom_bodyid > 0
    if not np.any(robot & np.isin(shown.geom_group, _VISIBLE_GROUPS)):
        shown.geom_group[robot & (shown.geom_group == _COLLISION_GROUP)] = _VISIBLE_GROUPS[-1]
    return shown


def check_listen_address(host: str, port: int) -> None:
    """Refuse a host or port this machine cannot listen on, with a one-line reason.

    viser would otherwise wait forever on an address that is not this machine's and move to
    another port on a privileged one.
    """
    if not 0 <= port <= 65535:
        raise QuaddanceError(f"viewer: port {port} is not in 0-65535")
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    try:
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.bind((host, 0))
    except (OSError, UnicodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise QuaddanceError(f"viewer: cannot listen on {host}: {reason}") from None
    if 0 < port < 1024 and hasattr(os, "geteuid") and os.geteuid() != 0:
        raise QuaddanceError(f"viewer: port {port} needs root; use 1024 or above")


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    # viser prints its own banner (with "localhost" for 0.0.0.0) and a stop notice; we print
    # the addresses that work from other machines instead.
    with contextlib.redirect_stdout(io.StringIO()):
        yield


class LiveViewer:
    """A web page showing the robot live, the tempo, the lock, the beats and the move.

    `model` is the scene model (`quaddance.sim.scene.build_model(scene, visual=True)`
    for the meshes; a `visual=False` model shows collision shapes). `host="0.0.0.0"` lets
    other machines watch; `port=0` takes a free port. If `port` is taken, viser moves to the
    next free one: `self.port` and `self.urls` say where it went.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        *,
        render_hz: float = DEFAULT_RENDER_HZ,
        announce: bool = True,
    ) -> None:
        if not render_hz > 0:
            raise ValueError(f"render_hz must be positive, not {render_hz}")
        check_listen_address(host, port)
        import viser
        from mjviser.scene import ViserMujocoScene

        self._model = displayable_model(model)
        self._data = mujoco.MjData(self._model)
        self._render_period_s = 1.0 / render_hz
        self._lock = threading.Lock()
        self._qpos = self.home_qpos()
        self._qpos_new = True
        self._status = LiveStatus()
        self._pending_beats: list[DetectedBeat] = []
        self._beats: deque[DetectedBeat] = deque(maxlen=max(BEAT_LIST_LEN, BEAT_PLOT_LEN))
        self._beat_count = 0
        self._flash_until_s: float | None = None
        self._shown_status = ""
        self._worker_error_reported = False
        self._closed = False

        with _quiet_stdout():
            self._server: viser.ViserServer = viser.ViserServer(
                host=host, port=port, label="quaddance live", verbose=False
            )
        try:
            self._scene: ViserMujocoScene = ViserMujocoScene(self._server, self._model, num_envs=1)
            # A fixed camera: mjviser's tracking would move the floor with the trunk's bounce.
            self._scene.camera_tracking_enabled = False
            self._build_page()
        except BaseException:
            with _quiet_stdout():
                self._server.stop()
            raise
        self.host = host
        self.port = self._server.get_port()
        self.urls = viewer_urls(host, self.port)
        self._stop = threading.Event()
        self._worker = threading.Thread(target=self._run, name="live-viewer", daemon=True)
        self._worker.start()
        if announce:
            others = f" (other machines: {self.urls[1]})" if len(self.urls) > 1 else ""
            print(f"quaddance: viewer at {self.urls[0]}{others}", flush=True)

    # -- called by the control loop: store and return -----------------------------------

    def update(self, qpos: np.ndarray) -> None:
        """Show the robot at `qpos` (the model's layout); shown at the next render tick."""
        qpos = np.asarray(qpos, dtype=np.float64)
        if qpos.shape != self._qpos.shape:
            raise ValueError(f"qpos has shape {qpos.shape}, the model needs {self._qpos.shape}")
        with self._lock:
            self._qpos[:] = qpos
            self._qpos_new = True

    def set_status(
        self, tempo_bpm: float | None, locked: bool, move: str, song_time_s: float
    ) -> None:
        """The tracker's tempo and lock, the current move and the song time."""
        status = LiveStatus(
            tempo_bpm=None if tempo_bpm is None else float(tempo_bpm),
            locked=bool(locked),
            move=str(move),
            song_time_s=float(song_time_s),
        )
        with self._lock:
            self._status = status

    def beat(self, t_s: float, downbeat: bool) -> None:
        """A beat was detected at song time `t_s`: flash the lamp, add it to the list."""
        detected = DetectedBeat(float(t_s), bool(downbeat))
        with self._lock:
            self._pending_beats.append(detected)

    def close(self) -> None:
        """Stop the worker and the server; a second call does nothing."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._worker.join(timeout=2.0)
        with _quiet_stdout():
            self._server.stop()

    def __enter__(self) -> LiveViewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- page ------------------------------------------------------------------------------

    def home_qpos(self) -> np.ndarray:
        """The model's first keyframe (the Go1 standing), or its default pose."""
        if self._model.nkey > 0:
            return self._model.key_qpos[0].copy()
        return self._model.qpos0.copy()

    def _build_page(self) -> None:
        import viser

        server = self._server
        server.initial_camera.position = _CAMERA_POS_M
        server.initial_camera.look_at = _CAMERA_LOOK_AT_M
        server.initial_camera.fov = _CAMERA_FOV_RAD
        # No environment map (mjviser sets one): without a GPU the browser spends tens of
        # seconds prefiltering it, and its light washes the dark Go1 out to the floor's grey.
        # Plain lights keep the page quick on any machine that watches.
        server.scene.configure_environment_map(hdri=None)
        server.scene.add_light_hemisphere(
            "/fill_light", sky_color=(255, 255, 255), ground_color=(90, 90, 100), intensity=1.2
        )
        # The beat disc under the robot flashes with the lamp in the panel.
        self._disc = server.scene.add_cylinder(
            "/beat_disc",
            radius=_DISC_RADIUS_M,
            height=_DISC_HEIGHT_M,
            color=_DISC_OFF_RGB,
            position=(0.0, 0.0, _DISC_HEIGHT_M),
            cast_shadow=False,
            receive_shadow=True,
        )
        self._status_html = server.gui.add_html(status_html(self._status))
        self._lamp_html = server.gui.add_html(beat_indicator_html(None, 0, lit=False))
        self._beat_plot = server.gui.add_uplot(
            data=beat_plot_data([]),
            series=(
                viser.uplot.Series(label="song time (s)"),
                viser.uplot.Series(
                    label="beat-to-beat BPM", stroke="#fb8c00", width=1, points={"size": 7}
                ),
            ),
            title="Detected beats",
            scales={"x": {"time": False}},  # song seconds, not a date
            aspect=1.6,
        )
        self._beat_list = server.gui.add_markdown(beat_list_markdown([]))

    # -- worker ----------------------------------------------------------------------------

    def _run(self) -> None:
        next_tick_s = time.perf_counter()
        while not self._stop.is_set():
            try:
                self._tick(time.perf_counter())
            except Exception as exc:  # the page may stall, the dance must go on
                if not self._worker_error_reported:
                    self._worker_error_reported = True
                    print(f"quaddance: viewer: {exc!r} (further errors not shown)", file=sys.stderr)
            next_tick_s = max(next_tick_s + self._render_period_s, time.perf_counter())
            self._stop.wait(next_tick_s - time.perf_counter())

    def _tick(self, now_s: float) -> None:
        with self._lock:
            qpos = self._qpos.copy() if self._qpos_new else None
            self._qpos_new = False
            status = self._status
            new_beats, self._pending_beats = self._pending_beats, []
        if qpos is not None and np.all(np.isfinite(qpos)):  # a NaN pose is skipped, not drawn
            self._show_pose(qpos)
        text = status_html(status)
        if text != self._shown_status:
            self._status_html.content = text
            self._shown_status = text
        if new_beats:
            self._show_beats(new_beats, now_s)
        elif self._flash_until_s is not None and now_s >= self._flash_until_s:
            self._flash_until_s = None
            self._set_lamp(lit=False)

    def _show_pose(self, qpos: np.ndarray) -> None:
        self._data.qpos[:] = qpos
        mujoco.mj_kinematics(self._model, self._data)
        self._scene.update_from_mjdata(self._data)
        self._disc.position = (float(qpos[0]), float(qpos[1]), _DISC_HEIGHT_M)

    def _show_beats(self, new_beats: list[DetectedBeat], now_s: float) -> None:
        self._beats.extend(new_beats)
        self._beat_count += len(new_beats)
        self._flash_until_s = now_s + BEAT_FLASH_S
        self._set_lamp(lit=True)
        self._beat_plot.data = beat_plot_data(self._beats)
        self._beat_list.content = beat_list_markdown(self._beats)

    def _set_lamp(self, lit: bool) -> None:
        last = self._beats[-1] if self._beats else None
        self._lamp_html.content = beat_indicator_html(last, self._beat_count, lit)
        rgb = _DISC_OFF_RGB
        if lit and last is not None:
            rgb = _DOWNBEAT_RGB if last.downbeat else _BEAT_RGB
        self._disc.color = rgb


# -- demo ------------------------------------------------------------------------------------


def _demo_pose(home_qpos: np.ndarray, t_s: float, beat_s: float) -> np.ndarray:
    """The standing pose with a small hop on each beat (down would push the feet into the
    floor: the joints stay as they are)."""
    qpos = home_qpos.copy()
    phase = (t_s % beat_s) / beat_s
    qpos[2] += 0.02 * math.exp(-6.0 * phase)
    return qpos


def run_demo(
    host: str, port: int, seconds: float | None, beat_s: float = 0.5, robot: str = GO1.name
) -> None:
    """``robot`` (`quaddance.robots.ROBOTS`) standing, a fake beat each `beat_s` (downbeat
    every 4th), until stopped."""
    from quaddance.sim.scene import SceneCfg, build_model

    model = build_model(SceneCfg(robot=get_robot(robot)), visual=True)
    with LiveViewer(model, host=host, port=port) as viewer:
        home_qpos = viewer.home_qpos()
        start_s = time.perf_counter()
        next_beat, control_period_s = 0, 0.02
        while seconds is None or time.perf_counter() - start_s < seconds:
            t_s = time.perf_counter() - start_s
            viewer.update(_demo_pose(home_qpos, t_s, beat_s))
            if t_s >= next_beat * beat_s:
                viewer.beat(next_beat * beat_s, downbeat=next_beat % 4 == 0)
                next_beat += 1
            locked = t_s > 2.0  # pretend the tracker needs two seconds to lock
            viewer.set_status(60.0 / beat_s if locked else None, locked, "demo bounce", t_s)
            time.sleep(control_period_s)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m quaddance.live.viewer", description="The live web viewer."
    )
    parser.add_argument("--demo", action="store_true", help="robot standing, fake beats")
    parser.add_argument("--host", default=DEFAULT_HOST, help="0.0.0.0: other machines too")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT)
    parser.add_argument("--seconds", type=float, default=None, help="stop after this long")
    parser.add_argument("--robot", default=GO1.name, choices=sorted(ROBOTS), help="robot shown")
    args = parser.parse_args(argv)
    if not args.demo:
        parser.error("only --demo is available here; `quaddance live --viewer` is the real use")
    try:
        run_demo(args.host, args.port, args.seconds, robot=args.robot)
    except QuaddanceError as exc:
        print(f"quaddance: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
