"""`quaddance deploy`: a dance, a robot backend, the runner, and the outputs in one call."""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quaddance.errors import InputFileError, QuaddanceError, not_a_file
from quaddance.fileio import check_output_file
from quaddance.layout import FRONT_PAWS
from quaddance.pipeline import DanceSpec, make_dance
from quaddance.robots import RobotCfg
from quaddance.targets import TargetConfig

#: `deploy` / `live --robot`: each backend and the robot model it drives (None: the
#: policy's). The simulators speak each robot's own protocol through its vendor's SDK.
BACKENDS: dict[str, str | None] = {
    "sim": None,  # quaddance's own protocol: fast, the default (never a real robot)
    "go1-sim": "go1",  # Go1 low-level UDP wire format, through unitree_legged_sdk
    "go2-sim": "go2",  # Go2 DDS topics, through unitree_sdk2
    "go1": "go1",  # real robots
    "go2": "go2",
}
SIMULATED: tuple[str, ...] = ("sim", "go1-sim", "go2-sim")  #: the backends faults reach
OUTPUT_NAMES = ("deploy.json", "log.npz", "rollout.npz")  #: what `run_deploy` writes


def parse_inject(values: list[str] | None) -> list[tuple[str, float]]:
    """``["push@2.5", ...]`` -> ``[("push", 2.5), ...]`` (fault, dance time s)."""
    from quaddance.deploy.robot import FAULTS

    out = []
    for text in values or []:
        name, sep, at = text.partition("@")
        try:
            t_s = float(at)
        except ValueError:
            t_s = math.nan
        if not sep or name not in FAULTS or not (math.isfinite(t_s) and t_s >= 0):
            raise QuaddanceError(
                f"--inject {text!r}: use FAULT@T with FAULT one of {', '.join(FAULTS)} and T "
                "the dance time in seconds (>= 0)"
            )
        out.append((name, t_s))
    return out


@dataclass(frozen=True)
class BackendOptions:
    """Which robot to run on, and how to reach it (`quaddance deploy` and `live`)."""

    robot: str = "sim"  #: one of `BACKENDS`
    robot_ip: str = "192.168.123.10"  #: go1: the robot's low-level IP
    power_level: int = 1  #: go1: the SDK's PowerProtect level
    sim_latency_ms: tuple[float, float] = (5.0, 20.0)  #: simulators: sensor-to-motor delay
    network: str | None = None  #: go2: the network interface wired to the robot
    dds_domain: int = 0  #: go2: the DDS domain (the robot's is 0)

    def check(self) -> None:
        """Refuse options that name no robot or an impossible delay range."""
        if self.robot not in BACKENDS:
            raise QuaddanceError(
                f"--robot must be one of {', '.join(BACKENDS)}, got {self.robot!r}"
            )
        lo, hi = self.sim_latency_ms
        if not 0 <= lo <= hi:
            raise QuaddanceError(f"--sim-latency-ms needs 0 <= LO <= HI, got {lo:g} {hi:g}")
        if self.robot == "go2" and not self.network:
            raise QuaddanceError("--robot go2 needs --network IFACE: the interface wired to it")


def make_robot(backend: BackendOptions, robot: RobotCfg):
    """The robot of ``backend`` for the policy's ``robot``: simulated in another process (the
    simulator simulates that robot), or a real one."""
    backend.check()
    model = BACKENDS[backend.robot]
    if model is not None and model != robot.short_name:
        raise QuaddanceError(
            f"--robot {backend.robot} drives a {model.capitalize()}, but the policy is for "
            f"{robot.name}"
        )
    if backend.robot == "sim":
        from quaddance.deploy.sim_backend import sim_robot

        return sim_robot(_sim_cfg(backend, robot))
    if backend.robot in ("go1", "go1-sim"):
        from quaddance.deploy.go1_backend import Go1Robot, load_sdk

        load_sdk()  # the missing-SDK error before anything else happens
        if backend.robot == "go1":
            return Go1Robot(backend.robot_ip, backend.power_level)
        from quaddance.deploy.go1_sim import go1_sim_robot

        return go1_sim_robot(_sim_cfg(backend, robot), backend.power_level)
    from quaddance.deploy.go2_backend import Go2Robot, load_sdk2

    load_sdk2()
    if backend.robot == "go2":
        return Go2Robot(backend.dds_domain, backend.network)
    from quaddance.deploy.go2_sim import go2_sim_robot

    return go2_sim_robot(_sim_cfg(backend, robot))


def _sim_cfg(backend: BackendOptions, robot: RobotCfg):
    from quaddance.deploy.simulator import SimRobotCfg

    return SimRobotCfg(latency_ms=tuple(backend.sim_latency_ms), robot=robot.name)


@dataclass
class DeployJob:
    """What `quaddance deploy` was asked to do."""

    out_dir: Path
    song: Path | None = None
    motion: Path | None = None
    dance: Path | None = None  #: a ready dance.npz
    demo: bool = False
    #: which dance to make of the song or motion (for the policy's robot); its paw
    #: targets: the policy's range
    spec: DanceSpec = field(default_factory=DanceSpec)
    policy: Path | None = None  #: None: the shipped policy of the spec's robot
    seconds: float | None = None
    auto_start: bool = False
    inject: list[tuple[str, float]] = field(default_factory=list)
    backend: BackendOptions = field(default_factory=BackendOptions)
    dry_run: bool = False  #: read and check the robot's state, send nothing, no dance


def run_dry(job: DeployJob, status: Callable[[str], None]) -> tuple[dict, dict]:
    """`deploy --dry-run`: deploy.json (the checks) and log.npz (the states read)."""
    from quaddance.deploy.dry_run import dry_run
    from quaddance.fileio import atomic_path, ensure_dir, write_json
    from quaddance.play.policy import OnnxPolicy, shipped_policy_path

    if job.song or job.demo or job.dance or job.motion or job.inject:
        raise QuaddanceError(
            "--dry-run dances nothing: no SONG, --demo, --dance, --motion or --inject"
        )
    policy = OnnxPolicy.load(job.policy or shipped_policy_path(job.spec.robot))
    out = ensure_dir(job.out_dir)
    paths = {"summary": out / "deploy.json", "log": out / "log.npz"}
    for path in paths.values():
        check_output_file(path)
    robot_cfg = policy.task.scene.robot
    summary, log = dry_run(make_robot(job.backend, robot_cfg), robot_cfg, status=status)
    with atomic_path(paths["log"]) as tmp:
        np.savez_compressed(tmp, **log)
    write_json(paths["summary"], summary)
    return summary, paths


def run_deploy(job: DeployJob, status: Callable[[str], None] = lambda m: None) -> tuple[dict, dict]:
    """Run the job; returns (deploy.json contents, output paths)."""
    from quaddance.dancefile import load_dance
    from quaddance.deploy.console import StopSignals
    from quaddance.deploy.log import write_outputs
    from quaddance.deploy.runner import DeployOptions, Runner
    from quaddance.fileio import ensure_dir
    from quaddance.play.dance import spec_for_policy
    from quaddance.play.policy import OnnxPolicy, shipped_policy_path

    if job.dry_run:
        return run_dry(job, status)

    n_sources = (job.song is not None) + job.demo + (job.dance is not None)
    if n_sources > 1 or (job.dance and job.motion) or (n_sources == 0 and job.motion is None):
        raise QuaddanceError("give one of SONG, --demo, --dance FILE or --motion FILE")
    if job.dance is not None and job.spec != DanceSpec(targets=TargetConfig(robot=job.spec.robot)):
        raise QuaddanceError(
            "--dance FILE is a dance already: --mode, --style, --moves and "
            "--seed choose the dance of a SONG, --demo or --motion"
        )
    job.backend.check()
    if job.inject and job.backend.robot not in SIMULATED:
        raise QuaddanceError(
            f"--inject works with the simulated robots ({', '.join(SIMULATED)}), never on a "
            "real one"
        )
    if job.seconds is not None and not (math.isfinite(job.seconds) and job.seconds > 0):
        raise QuaddanceError(f"--seconds must be > 0, got {job.seconds}")
    if job.seconds is not None:
        _check_inject_times(job.inject, job.seconds)
    for path in (job.song, job.motion, job.dance):
        if path is not None and not Path(path).is_file():
            raise not_a_file(path)
    policy = OnnxPolicy.load(job.policy or shipped_policy_path(job.spec.robot))
    spec = spec_for_policy(job.spec, policy)
    out = ensure_dir(job.out_dir)
    for name in OUTPUT_NAMES:
        check_output_file(out / name)  # refuse a FIFO or a folder before the robot moves

    with tempfile.TemporaryDirectory(prefix="quaddance-deploy-") as tmp:
        song = job.song
        if job.demo:
            from quaddance.music.synth import write_demo_song

            song = Path(tmp) / "demo_song.wav"
            write_demo_song(song)
        if job.dance is not None:
            dance = load_dance(job.dance, policy.robot)
        else:
            status("analysing the music and choreographing")
            dance, _ = make_dance(song, job.motion, spec)
            for note in dance.notes:
                status(f"note: {note}")
        if abs(dance.fps - policy.task.policy_hz) > 1e-6:
            raise InputFileError(
                job.dance or song or job.motion,
                f"dance is at {dance.fps:g} Hz but the policy runs at {policy.task.policy_hz:g} Hz",
            )
        _check_inject_times(job.inject, dance.targets_m.shape[0] / dance.fps)
        max_h = (policy.meta.get("targets") or {}).get("max_height_m")
        highest_m = float(dance.targets_m[:, FRONT_PAWS].max())
        if max_h is not None and highest_m > max_h + 1e-6:
            status(
                f"warning: targets up to {highest_m:.2f} m; the policy was "
                f"trained up to {max_h:.2f} m (quaddance choreograph --mode feasible)"
            )
        options = DeployOptions(
            seconds=job.seconds, auto_start=job.auto_start, inject=job.inject, song=song
        )
        # Ctrl-C stops the dance (the robot damps), and from then until the log is written
        # every further Ctrl-C is only the same request: a second press loses nothing.
        stop = StopSignals()
        with stop:
            runner = Runner(
                make_robot(job.backend, policy.task.scene.robot),
                policy,
                dance.targets_m,
                options,
                status=status,
                body_targets=dance.body_targets,
                stop=stop,
            )
            result = runner.run()
            paths = write_outputs(out, result, policy, dance.beats_s)
    return result.summary, paths


def _check_inject_times(inject: list[tuple[str, float]], end_s: float) -> None:
    """A fault at or after the end of the dance would never happen, and the run would look
    like a pass of the safety layer: one line instead."""
    for fault, t_s in inject:
        if t_s >= end_s:
            raise QuaddanceError(
                f"--inject {fault}@{t_s:g}: the dance ends at {end_s:.1f} s; pick a time before it"
            )


def summary_line(summary: dict) -> str:
    """One line for a person from deploy.json's contents: the final state, the time danced,
    falls, the front paws' tracking error and the tick time (a dry run: each check)."""
    if summary.get("dry_run"):
        checks = summary["checks"]
        verdict = "passed" if summary["ok"] else "FAILED"
        return f"dry run {verdict}: " + "; ".join(
            f"{name} {'ok' if c['ok'] else 'FAILED'} ({c['detail']})" for name, c in checks.items()
        )
    front = summary["front"] or {}
    mae = [front[f]["mae_m"] for f in ("fl", "fr") if f in front and front[f]["mae_m"] is not None]
    events = summary.get("events") or []
    # Why the run ended, where it was not the dance's end: a signal, a fault, stdin closed.
    why = events[-1].get("reason", "") if events else ""
    why = f" ({why})" if why and why != "dance finished" else ""
    return (
        f"final state {summary['final_state']}{why}, danced {summary['duration_s']:.1f} s, "
        f"falls {summary['falls']}, front MAE "
        + (f"{100 * sum(mae) / len(mae):.1f} cm" if mae else "n/a")
        + f", tick p99 {summary['tick_ms']['p99']} ms"
    )
