"""`quaddance live`: dance to music as it plays.

Two processes besides the simulated robot's: the *listener* (`_listen`, its own process so
that audio analysis and choreography never hold up the control loop) reads the audio as it
arrives (`music.live.FileSource` at real-time pace or `MicSource`), tracks beats online
(`music.online_beats.OnlineBeatTracker`) and plans the dance a bar ahead
(`live.choreographer.LiveChoreographer`); it sends each audio block's results over a queue.
The *runner* is `quaddance deploy`'s (`deploy.runner.Runner`, same safety layer, 50 Hz on
the wall clock): at each dance tick it takes the new targets (`_LiveFeed.feed`), then the
policy acts. Song time 0 is dance time 0: the listener starts reading when the dance starts.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import queue
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.children import ignore_sigint, sigint_blocked_for_children
from quaddance.deploy.job import BackendOptions
from quaddance.errors import QuaddanceError
from quaddance.layout import BODY, N_BODY, N_PAWS, PAWS, row_width
from quaddance.pipeline import DanceSpec
from quaddance.robots import RobotCfg

#: Dance length for a microphone without --seconds, s.
MIC_DEFAULT_S = 60.0
#: How long the listener may take to open its input and load its analysis, s.
LISTENER_START_S = 60.0
#: Song-time spacing of the tempo curve in live.json, s.
TEMPO_EVERY_S = 0.5


@dataclass
class LiveJob:
    """What `quaddance live` was asked to do."""

    out_dir: Path
    from_file: Path | None = None  #: a song fed at real-time pace; None: the microphone
    start_s: float = 0.0  #: with from_file: play from this far into it (music already playing)
    device: str | None = None  #: microphone (sounddevice name or index); None: default
    backend: BackendOptions = field(default_factory=BackendOptions)
    policy: Path | None = None
    seconds: float | None = None  #: dance at most this long
    viewer: bool = False
    host: str = "127.0.0.1"
    port: int = 8080
    video: bool = False  #: with --from-file: dance.mp4 afterwards
    #: which dance, bar by bar (segment k: seed + k); its paw targets: the policy's range
    spec: DanceSpec = field(default_factory=DanceSpec)


OUTPUT_NAMES = ("live.json", "deploy.json", "log.npz", "rollout.npz", "dance.mp4")
"""What `run_live` writes (the video with ``--video`` only)."""


@dataclass
class _Update:
    """What the listener sends after one audio block."""

    arrival_s: float | None  #: time.monotonic() when the block was complete (None: rows only)
    t_end_s: float  #: song time of the block's end
    rows: np.ndarray  #: (K, 8) new final targets (paws, body)
    beats: list[tuple[float, bool, float]]  #: (time_s, downbeat, tempo_bpm) of new beats
    tempo_bpm: float
    locked: bool
    lock_s: float
    move: str


# --- the listener process ---------------------------------------------------------------------


def _listen(spec: dict, out: Any, go: Any, stop: Any) -> None:
    """Child process: audio -> beats -> choreography, one `_Update` per block."""
    # Ctrl-C is the runner's to handle (damping first); this process ends on `stop`.
    ignore_sigint()
    try:
        from quaddance.live.choreographer import LiveChoreographer
        from quaddance.music.live import FileSource, MicSource
        from quaddance.music.online_beats import OnlineBeatTracker

        if spec["from_file"] is not None:
            source: Any = FileSource(spec["from_file"], realtime=True, start_s=spec["start_s"])
            duration_s = source.duration_s
        else:
            source = MicSource(spec["device"])
            duration_s = None
        # A file played from its start starts with the song; a microphone, or a file started
        # part-way, may join music already playing.
        song_start = spec["from_file"] is not None and spec["start_s"] == 0
        tracker = OnlineBeatTracker(song_start=song_start)
        choreo = LiveChoreographer(spec["policy_hz"], spec["dance"])
    except QuaddanceError as err:
        out.put(("error", str(err)))
        return
    except Exception as err:  # a one-line report, never a traceback from the child
        out.put(("error", f"live input: {type(err).__name__}: {err}"))
        return
    out.put(("ready", duration_s))
    go.wait()
    sent = 1  # row 0 is the controller's first row (dance time 0, calm)
    try:
        for block in source:
            if stop.is_set():
                break
            arrival = time.monotonic()
            events = tracker.update(block.samples, block.t_end_s)
            state = tracker.state
            update = _Update(
                arrival_s=arrival,
                t_end_s=block.t_end_s,
                rows=np.zeros((0, row_width(body=True))),
                beats=[(e.time_s, e.downbeat, e.tempo_bpm) for e in events],
                tempo_bpm=float(state.tempo_bpm),
                locked=bool(state.locked),
                lock_s=float(state.lock_s),
                move=choreo.move_at(block.t_end_s),
            )
            # The beat goes out first: planning a bar (tens of ms) must not delay it. The
            # planned targets follow; they are needed only LOOKAHEAD_S ahead.
            out.put(update)
            n_final = choreo.update(state, block.t_end_s)
            if n_final > sent:
                rows = choreo.final_rows(sent).copy()
                sent = n_final
                out.put(dataclasses.replace(update, arrival_s=None, beats=[], rows=rows))
    except QuaddanceError as err:
        out.put(("error", str(err)))
    finally:
        if hasattr(source, "close"):
            source.close()
        out.put(("end", None))


# --- the runner side --------------------------------------------------------------------------


@dataclass
class _LiveFeed:
    """Takes the listener's updates into the dance controller, the viewer and the logs."""

    queue: Any
    viewer: Any = None
    standing_m: float = 0.0  #: the viewer's trunk height before the estimate is there
    beats_s: list[float] = field(default_factory=list)
    downbeats_s: list[float] = field(default_factory=list)
    tempo: list[tuple[float, float, bool]] = field(default_factory=list)
    latency_s: list[float] = field(default_factory=list)
    lock_s: float = float("nan")
    move: str = "calm"
    tempo_bpm: float = 0.0
    locked: bool = False
    error: str | None = None
    ended: bool = False
    ctrl: Any = None
    _newest_arrival: float | None = None

    def feed(self, t_dance: float) -> None:
        """At a dance tick: every update that arrived goes in (non-blocking)."""
        while True:
            try:
                msg = self.queue.get_nowait()
            except queue.Empty:
                return
            if isinstance(msg, tuple):
                kind, value = msg
                if kind == "error":
                    self.error = value
                self.ended = True
                continue
            if msg.rows.shape[0]:
                self.ctrl.extend(msg.rows[:, PAWS], msg.rows[:, BODY])
            for t_s, down, _bpm in msg.beats:
                self.beats_s.append(t_s)
                if down:
                    self.downbeats_s.append(t_s)
                if self.viewer is not None:
                    self.viewer.beat(t_s, down)
            if not self.tempo or msg.t_end_s - self.tempo[-1][0] >= TEMPO_EVERY_S:
                self.tempo.append((msg.t_end_s, msg.tempo_bpm, msg.locked))
            self.lock_s, self.move = msg.lock_s, msg.move
            self.tempo_bpm, self.locked = msg.tempo_bpm, msg.locked
            if msg.arrival_s is not None:
                self._newest_arrival = msg.arrival_s

    def on_tick(self, tick: Any) -> None:
        """After a command is sent: the audio-to-command latency, and the viewer."""
        if self._newest_arrival is not None and np.isfinite(tick.t_dance):
            self.latency_s.append(time.monotonic() - self._newest_arrival)
            self._newest_arrival = None
        if self.viewer is not None:
            r = tick.reading
            height = tick.trunk_m if np.isfinite(tick.trunk_m) else self.standing_m
            qpos = np.concatenate([[0.0, 0.0, height], r.quat_wxyz, r.joint_pos_rad])
            self.viewer.update(qpos)
            self.viewer.set_status(
                self.tempo_bpm if self.tempo_bpm > 0 else None,
                self.locked,
                self.move,
                tick.t_dance if np.isfinite(tick.t_dance) else 0.0,
            )


def run_live(job: LiveJob, status=lambda msg: None) -> tuple[dict, dict[str, Path]]:
    """Run `quaddance live`; returns (live.json contents, output paths)."""
    from quaddance.deploy.job import make_robot
    from quaddance.deploy.log import percentiles, rollout_from_log, write_outputs
    from quaddance.deploy.runner import DeployOptions, Runner
    from quaddance.fileio import check_output_file, ensure_dir, write_json
    from quaddance.play.dance import spec_for_policy
    from quaddance.play.metrics import whole_body_metrics
    from quaddance.play.policy import OnnxPolicy, shipped_policy_path
    from quaddance.play.rollout import save_rollout

    if job.from_file is not None and not Path(job.from_file).is_file():
        from quaddance.errors import not_a_file

        raise not_a_file(job.from_file)
    if job.video and job.from_file is None:
        raise QuaddanceError("--video needs --from-file (a microphone's sound is not kept)")
    if job.start_s != 0 and job.from_file is None:
        raise QuaddanceError("--start needs --from-file (a microphone hears what plays now)")
    if job.seconds is not None and not (np.isfinite(job.seconds) and job.seconds > 0):
        raise QuaddanceError(f"--seconds must be > 0, got {job.seconds}")
    job.backend.check()
    policy = OnnxPolicy.load(job.policy or shipped_policy_path(job.spec.robot))
    dance_spec = spec_for_policy(job.spec, policy)
    out = ensure_dir(job.out_dir)
    names = OUTPUT_NAMES if job.video else OUTPUT_NAMES[:-1]
    for name in names:
        check_output_file(out / name)

    ctx = mp.get_context("spawn")
    updates, go, stop = ctx.Queue(), ctx.Event(), ctx.Event()
    spec = {
        "from_file": None if job.from_file is None else str(job.from_file),
        "start_s": job.start_s,
        "device": job.device,
        "policy_hz": policy.task.policy_hz,
        "dance": dance_spec,
    }
    status("opening the audio input and loading the beat tracker")
    listener = ctx.Process(target=_listen, args=(spec, updates, go, stop), daemon=True)
    with sigint_blocked_for_children():
        listener.start()
    viewer = None
    try:
        kind, value = _first_message(updates, listener)
        if kind == "error":
            raise QuaddanceError(value)
        duration_s = value if value is not None else MIC_DEFAULT_S
        if job.seconds is not None:
            duration_s = min(duration_s, job.seconds)
        if job.viewer:
            from quaddance.live.viewer import LiveViewer
            from quaddance.sim.scene import build_model

            viewer = LiveViewer(
                build_model(policy.task.scene, visual=True), host=job.host, port=job.port
            )
            status(f"viewer: {', '.join(viewer.urls)}")
        feed = _LiveFeed(updates, viewer, policy.task.scene.robot.standing_height_m)
        options = DeployOptions(
            seconds=duration_s, auto_start=True, song=job.from_file, song_start_s=job.start_s
        )
        runner = Runner(
            make_robot(job.backend, policy.task.scene.robot),
            policy,
            np.zeros((1, N_PAWS)),
            options,
            status=status,
            body_targets=np.zeros((1, N_BODY)),
            feeder=_starter(feed, go),
            on_tick=feed.on_tick,
            dance_s=duration_s,
        )
        feed.ctrl = runner.ctrl
        result = runner.run()
    finally:
        stop.set()
        go.set()  # a listener still waiting must see the stop
        listener.join(timeout=5.0)
        if listener.is_alive():
            listener.kill()
        if viewer is not None:
            viewer.close()
    if feed.error is not None:
        raise QuaddanceError(feed.error)

    paths = write_outputs(out, result)
    rollout = rollout_from_log(result.log, policy.task.policy_hz)
    beats = np.asarray(feed.beats_s, dtype=float)
    summary: dict[str, Any] = {
        "source": str(job.from_file) if job.from_file is not None else "microphone",
        # Song time 0 is this far into the file (times below are from where it started).
        "start_s": job.start_s,
        "robot": job.backend.robot,
        "policy": str(policy.onnx_path),
        "duration_s": result.summary.get("duration_s"),
        "lock_s": None if not np.isfinite(feed.lock_s) else round(feed.lock_s, 3),
        "tempo_bpm": [
            {"t_s": round(t, 3), "bpm": round(b, 2), "locked": lk} for t, b, lk in feed.tempo
        ],
        "beats_s": [round(b, 4) for b in feed.beats_s],
        "downbeats_s": [round(b, 4) for b in feed.downbeats_s],
        "latency_ms": percentiles(np.asarray(feed.latency_s) * 1e3),
        "tracker_latency_ms": _tracker_latency_ms(),
        "loop_ms": result.summary.get("tick_ms"),
        "falls": result.summary.get("falls"),
        "final_state": result.summary.get("final_state"),
    }
    if rollout.time_s.size >= 2:
        paths["rollout"] = out / "rollout.npz"
        save_rollout(paths["rollout"], rollout, beats)
        standing_m = policy.task.base_height_target_m
        summary.update(whole_body_metrics(rollout, beats, standing_m))
        if job.video:
            paths["video"] = _video(
                out / "dance.mp4", rollout, result.log, job.from_file, job.start_s, policy.robot
            )
    paths["live"] = out / "live.json"
    write_json(paths["live"], summary)
    return summary, paths


def _starter(feed: _LiveFeed, go: Any):
    """The runner's feeder: the first dance tick starts the listener's clock (song time 0)."""

    def feeder(t_dance: float) -> None:
        if not go.is_set():
            go.set()
        feed.feed(t_dance)

    return feeder


def _first_message(updates: Any, listener: Any) -> tuple[str, Any]:
    deadline = time.monotonic() + LISTENER_START_S
    while time.monotonic() < deadline:
        try:
            msg = updates.get(timeout=0.2)
        except queue.Empty:
            if not listener.is_alive():
                return "error", "live input: the audio process ended before it was ready"
            continue
        if isinstance(msg, tuple):
            return msg
    return "error", f"live input: not ready after {LISTENER_START_S:g} s"


def _tracker_latency_ms() -> float:
    from quaddance.music.online_beats import LATENCY_S

    return round(LATENCY_S * 1e3, 1)


def _video(path: Path, rollout, log: dict, song: Path, start_s: float, robot: RobotCfg) -> Path:
    """dance.mp4 of ``robot`` from the danced poses (trunk from the simulator, joints from the
    encoders) with the song from ``start_s`` into it (where the dance heard it), afterwards."""
    from quaddance.deploy.states import DeployState
    from quaddance.play.video import RenderCfg, render_video

    dancing = log["state"] == DeployState.DANCE.code
    q = log["q"][dancing]
    r, p, y = rollout.base_rpy_rad.T
    cr, sr, cp, sp, cy, sy = (
        np.cos(r / 2),
        np.sin(r / 2),
        np.cos(p / 2),
        np.sin(p / 2),
        np.cos(y / 2),
        np.sin(y / 2),
    )
    quat = np.column_stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )
    n = q.shape[0]
    qpos = np.column_stack([np.zeros((n, 2)), rollout.base_height_m, quat, q])
    render_video(
        None,
        qpos,
        rollout.fps,
        path,
        audio_path=song,
        audio_offset_s=start_s,
        progress=False,
        cfg=RenderCfg(robot=robot),
    )
    return path


def summary_line(summary: dict) -> str:
    """One line for a person from live.json's contents: the time danced, falls, the beat
    lock, latency and loop time."""
    lock = summary["lock_s"]
    return (
        f"danced {summary['duration_s']:.1f} s, falls {summary['falls']}, "
        + (f"beat locked at {lock:.1f} s" if lock is not None else "no beat lock")
        + f", {len(summary['beats_s'])} beats, latency p50/p99 "
        f"{summary['latency_ms']['p50']} / {summary['latency_ms']['p99']} ms, "
        f"loop p99 {summary['loop_ms']['p99']} ms"
    )
