"""The main job: a song (or a motion file) in, the robot (`DanceSpec.robot`) dancing to it out.

song -> analysis -> choreography -> targets -> closed-loop rollout of the ONNX policy on the
cpu engine -> dance.mp4 (with the song), feet.png (the paper's Fig. 4), metrics.json.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from quaddance.dancefile import Dance, save_dance
from quaddance.errors import QuaddanceError, not_a_file
from quaddance.fileio import check_outputs, ensure_dir, remove_empty_dir, write_json
from quaddance.pipeline import DanceSpec, dance_inputs, make_dance

if TYPE_CHECKING:
    from quaddance.choreo.motion import HumanMotion
    from quaddance.play.policy import OnnxPolicy
    from quaddance.play.rollout import PinnedDynamics
    from quaddance.play.video import VideoRenderer
    from quaddance.robots import RobotCfg


OUTPUT_NAMES = ("dance.npz", "rollout.npz", "feet.png", "metrics.json", "dance.mp4")
"""The files `run_dance` writes in its folder."""


@dataclass
class DanceJob:
    """What `quaddance dance` was asked to do."""

    out_dir: Path
    song: Path | None = None
    motion: Path | None = None
    human: HumanMotion | None = None  # ``motion`` already read (eval reads each file once)
    policy: Path | None = None  # None: the shipped policy of the spec's robot
    # Which dance; its paw targets are put in the policy's range (`spec_for_policy`).
    spec: DanceSpec = field(default_factory=DanceSpec)
    video: bool = True
    randomize: bool = False
    sim_seed: int | None = None  # seed of the randomised dynamics; None: the dance's seed
    policy_output: str = "policy"  # "zero": the front-lift feed-forward alone (baseline)
    pinned: PinnedDynamics | None = None  # fixed dynamics and pushes (robustness envelope)
    width: int = 640
    height: int = 480
    target_markers: bool = True
    # Analyse the song (then choreograph, and compute the beat metrics) in a second process
    # while this one loads torch and the policy: for a one-off command (`quaddance dance`) in
    # a fresh process, where the imports are start-up cost; not for loops over many songs
    # (eval), which import librosa once.
    analysis_process: bool = False


@dataclass
class DanceOutputs:
    dance: Dance
    metrics: dict[str, Any]
    paths: dict[str, Path] = field(default_factory=dict)
    timings_s: dict[str, float] = field(default_factory=dict)


def trained_max_height_m(policy: OnnxPolicy) -> float | None:
    """The highest paw target of the range the policy was trained on (its JSON), if known."""
    return policy.meta.get("targets", {}).get("max_height_m")


def shipped_max_height_m(robot: RobotCfg) -> float | None:
    """The highest paw target of the range ``robot``'s shipped policy was trained on, the
    one `dance` keeps to without ``--policy``; None where no policy ships or it gives none."""
    from quaddance.play.policy import shipped_policy_path
    from quaddance.play.policy_spec import PolicySpec

    try:
        path = shipped_policy_path(robot)
    except QuaddanceError:
        return None
    return PolicySpec.load(path.with_suffix(".json")).targets_max_height_m


def spec_for_policy(spec: DanceSpec, policy: OnnxPolicy) -> DanceSpec:
    """``spec`` with its paw targets in the range the policy was trained on (its JSON); a
    policy trained on eq. 4 targets dances eq. 4 targets with its h0, the only kind it saw.
    One line if the dance is for another robot than the policy."""
    policy.require_robot(spec.robot, "the dance's robot")
    trained = policy.meta.get("targets", {})
    changes: dict[str, Any] = {}
    if trained.get("max_height_m") is not None:
        changes["max_height_m"] = trained["max_height_m"]
    if trained.get("mode") == "paper":
        changes |= {"mode": "paper", "h0_m": trained["h0_m"]}
    if not changes:
        return spec
    return dataclasses.replace(spec, targets=dataclasses.replace(spec.targets, **changes))


def feasible_max_height_m(policy: OnnxPolicy) -> float:
    """The paw height up to which the policy's feasible targets reach: its trained range, or
    its robot's (`RobotCfg.max_paw_height_m`)."""
    max_h = trained_max_height_m(policy)
    return policy.robot.max_paw_height_m if max_h is None else max_h


def run_dance(
    job: DanceJob,
    status: Callable[[str], None] = lambda msg: None,
    sim_progress: Callable[[int, int], None] | None = None,
    show_render_progress: bool = True,
) -> DanceOutputs:
    """Run the whole pipeline; every output is written atomically into `job.out_dir`.

    Helpers start first, before the heavy imports: with ``job.analysis_process`` a second
    process (`_Helper`) analyses the song and then choreographs while this one loads torch
    and the policy, and with video the render workers, whose start-up (model, EGL context)
    overlaps the analysis and the simulation; feet.png is drawn while the video renders.
    """
    t_start = time.perf_counter()
    made_out_dir = not Path(job.out_dir).exists()
    pending = _Helper.start(job)
    try:
        if not job.video:
            return _run_dance(
                job, None, pending, t_start, status, sim_progress, show_render_progress
            )
        from quaddance.play.video import RenderCfg, VideoRenderer

        cfg = RenderCfg(robot=job.spec.robot)
        with VideoRenderer(None, job.width, job.height, cfg=cfg) as renderer:
            return _run_dance(
                job, renderer, pending, t_start, status, sim_progress, show_render_progress
            )
    except BaseException:
        if made_out_dir:  # a bad input leaves no empty folder behind
            remove_empty_dir(job.out_dir)
        raise
    finally:
        if pending is not None:
            pending.close()


class _Helper:
    """A second process for the numpy/scipy work of `dance` (see
    `DanceJob.analysis_process`): the song's analysis starts at once, before this process
    imports torch; then it loads what the choreography needs (scipy.signal), and the
    choreography (which needs the policy's target range) and the beat metrics follow there,
    not in this process (importing scipy.signal costs 1.2 s CPU, measured)."""

    def __init__(self, song: Path) -> None:
        from quaddance.children import HelperProcess
        from quaddance.music.analysis import analyze_file

        self.proc = HelperProcess()
        self.proc.submit(analyze_file, path=song)
        # Then, while this process still loads torch, the choreography's imports (scipy.signal:
        # 1.2 s CPU, measured), so that choreographing need not wait for them.
        self.proc.submit(_load_choreography)

    @classmethod
    def start(cls, job: DanceJob) -> _Helper | None:
        if not (job.analysis_process and job.song is not None and job.motion is None):
            return None
        if not Path(job.song).is_file():
            return None  # reported by `_run_dance`
        return cls(Path(job.song))

    def ready(self) -> bool:
        """Whether the analysis has finished (`analysis` will not wait)."""
        return self.proc.ready()

    def analysis(self) -> Any:
        """The song's `Analysis`; None where it failed there (see `run`)."""
        analysis = self._answer(self.proc.result)
        self._answer(self.proc.result)  # `_load_choreography`'s None, read to keep the order
        return analysis

    def run(self, fn: Callable[..., Any], **kwargs: Any) -> Any:
        """``fn(**kwargs)`` in the helper; None where it failed there or the helper died:
        the caller then does the work itself, where a bad file gets its usual one-line
        error."""
        return self._answer(lambda: self.proc.call(fn, **kwargs))

    @staticmethod
    def _answer(get: Callable[[], Any]) -> Any:
        from quaddance.children import HelperError

        try:
            return get()
        except HelperError:
            return None

    def close(self) -> None:
        self.proc.close()


def _load_choreography() -> None:
    import scipy.signal  # noqa: F401 - what the targets' lift detection uses


def _make_dance(**kwargs: Any) -> Dance:
    return make_dance(**kwargs)[0]


def _run_dance(
    job: DanceJob,
    renderer: VideoRenderer | None,
    pending: _Helper | None,
    t_start: float,
    status: Callable[[str], None],
    sim_progress: Callable[[int, int], None] | None,
    show_render_progress: bool,
) -> DanceOutputs:
    from quaddance.play.metrics import body_and_coverage, dance_metrics
    from quaddance.play.plots import plot_feet
    from quaddance.play.policy import OnnxPolicy, shipped_policy_path

    for path in (job.song, job.motion):
        if path is not None and not Path(path).is_file():
            raise not_a_file(path)
    policy_path = job.policy or shipped_policy_path(job.spec.robot)
    policy = OnnxPolicy.load(policy_path)
    spec = spec_for_policy(job.spec, policy)
    out = ensure_dir(job.out_dir)
    # A FIFO, a device or an input where an output goes: refused before the work, not after.
    check_outputs(
        {name: out / name for name in OUTPUT_NAMES}, dance_inputs(job.song, job.motion, job.spec)
    )
    timings: dict[str, float] = {}

    status("analysing the music and choreographing")
    t0 = time.perf_counter()
    if pending is not None:
        import quaddance.play.rollout  # noqa: F401 - torch loads while the song is analysed

        if not pending.ready():
            # Still analysing: matplotlib loads in this wait instead of after the dance,
            # when the render workers need the cores.
            from quaddance.play.plots import preload

            preload()
    how = dict(song=job.song, motion=job.motion, spec=spec, human=job.human)
    dance = None
    if pending is not None and (analysis := pending.analysis()) is not None:
        dance = pending.run(_make_dance, analysis=analysis, **how)
    if dance is None:
        dance, _ = make_dance(**how)
    timings["choreography_s"] = time.perf_counter() - t0
    # torch only now: imported before librosa it makes librosa's import slower (lazy_loader
    # walks the stack with `inspect`, whose cost grows with the modules loaded).
    from quaddance.play.rollout import rollout, save_rollout

    paths = {"dance": out / "dance.npz"}
    save_dance(paths["dance"], dance)

    stream, on_pose = None, None
    if renderer is not None:
        # The video is filmed while the dance is simulated: each pose goes to the renderer.
        status("dancing and filming")
        paths["video"] = out / "dance.mp4"
        stream = renderer.stream(
            dance.targets_m.shape[0],
            dance.fps,
            paths["video"],
            audio_path=job.song,
            target_markers=job.target_markers,
            progress=show_render_progress,
        )

        def on_pose(step: int, qpos: Any, targets_m: Any) -> None:
            stream.add(qpos, targets_m if job.target_markers else None)

    else:
        status("dancing (simulation)")
    sim_seed = job.spec.seed if job.sim_seed is None else job.sim_seed
    result = rollout(
        dance,
        policy,
        randomize=job.randomize,
        seed=sim_seed,
        progress=sim_progress,
        policy_output=job.policy_output,
        pinned=job.pinned,
        on_pose=on_pose,
    )
    timings["simulation_s"] = result.sim_wall_s
    paths["rollout"] = out / "rollout.npz"
    save_rollout(paths["rollout"], result, dance.beats_s)
    render = stream.finish() if stream is not None else None

    t0 = time.perf_counter()
    title = f"{dance.source} - {policy_path.name}"  # sources name files, not paths
    measured = result.body_measured(policy.task.base_height_target_m)
    paths["plot"] = plot_feet(
        out / "feet.png",
        result.time_s,
        result.targets_m,
        result.feet_m,
        dance.beats_s,
        title,
        body_targets=result.body_targets,
        body_measured=measured,
    )
    timings["plot_s"] = time.perf_counter() - t0
    render_s = None
    if render is not None:
        video = render.wait()
        render_s = video["total_s"]
        timings["render_s"] = render_s
        # The part after the simulation; the render workers' start-up, from their spawn at
        # the start, and its CPU seconds.
        timings["render_after_sim_s"] = video["tail_s"]
        timings["render_workers_ready_s"] = video["workers_ready_s"]
        timings["render_worker_startup_cpu_s"] = video["worker_startup_cpu_s"]
    metrics = dance_metrics(
        result.time_s,
        result.targets_m,
        result.feet_m,
        dance.beats_s,
        result.falls_s,
        sim_time_s=result.sim_wall_s,
        render_time_s=render_s,
        feasible_max_m=feasible_max_height_m(policy),
    )
    arrays = dict(
        time_s=result.time_s,
        feet_m=result.feet_m,
        body_targets=result.body_targets,
        body_measured=measured,
        beats_s=dance.beats_s,
    )
    beat_metrics = pending.run(body_and_coverage, **arrays) if pending is not None else None
    metrics.update(beat_metrics or body_and_coverage(**arrays))
    if dance.clamp_report is not None:
        metrics["clamped"] = dance.clamp_report
    if dance.notes:
        metrics["notes"] = list(dance.notes)
    timings["total_s"] = time.perf_counter() - t_start
    metrics["source"] = dance.source
    metrics["policy"] = str(policy_path)
    metrics["mode"] = dance.mode
    metrics["timings_s"] = {k: round(v, 3) for k, v in timings.items()}
    paths["metrics"] = out / "metrics.json"
    write_json(paths["metrics"], metrics)
    return DanceOutputs(dance=dance, metrics=metrics, paths=paths, timings_s=timings)
