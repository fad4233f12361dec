"""`quaddance deploy`: a dance, a robot backend, the runner, and the outputs in one call."""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from quaddance.errors import InputFileError, QuaddanceError
from quaddance.layout import FRONT_PAWS
from quaddance.pipeline import DanceSpec, make_dance
from quaddance.robots import RobotCfg
from quaddance.targets import TargetConfig

ROBOTS: tuple[str, ...] = ("sim", "go1")


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

    robot: str = "sim"  #: one of `ROBOTS`
    robot_ip: str = "192.168.123.10"  #: go1: the robot's low-level IP
    power_level: int = 1  #: go1: the SDK's PowerProtect level
    sim_latency_ms: tuple[float, float] = (5.0, 20.0)  #: sim: sensor-to-motor delay range

    def check(self) -> None:
        """Refuse options that name no robot or an impossible delay range."""
        if self.robot not in ROBOTS:
            raise QuaddanceError(f"--robot must be one of {', '.join(ROBOTS)}, got {self.robot!r}")
        lo, hi = self.sim_latency_ms
        if not 0 <= lo <= hi:
            raise QuaddanceError(f"--sim-latency-ms needs 0 <= LO <= HI, got {lo:g} {hi:g}")


def make_robot(backend: BackendOptions, robot: RobotCfg):
    """The robot of ``backend`` for the policy's ``robot``: simulated in another process (the
    simulator simulates that robot), or a real Go1."""
    backend.check()
    if backend.robot == "sim":
        from quaddance.deploy.sim_backend import sim_robot
        from quaddance.deploy.simulator import SimRobotCfg

        latency_ms = tuple(backend.sim_latency_ms)
        return sim_robot(SimRobotCfg(latency_ms=latency_ms, robot=robot.name))
    from quaddance.deploy.go1_backend import Go1Robot, load_sdk

    if robot != Go1Robot.robot_cfg:
        raise QuaddanceError(f"--robot go1 drives a Go1, but the policy is for {robot.name}")
    load_sdk()  # the missing-SDK error before anything else happens
    return Go1Robot(backend.robot_ip, backend.power_level)


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


def run_deploy(job: DeployJob, status: Callable[[str], None] = lambda m: None) -> tuple[dict, dict]:
    """Run the job; returns (deploy.json contents, output paths)."""
    from quaddance.dancefile import load_dance
    from quaddance.deploy.log import write_outputs
    from quaddance.deploy.runner import DeployOptions, Runner
    from quaddance.fileio import check_output_file, ensure_dir
    from quaddance.play.dance import spec_for_policy
    from quaddance.play.policy import OnnxPolicy, shipped_policy_path

    n_sources = (job.song is not None) + job.demo + (job.dance is not None)
    if n_sources > 1 or (job.dance and job.motion) or (n_sources == 0 and job.motion is None):
        raise QuaddanceError("give one of SONG, --demo, --dance FILE or --motion FILE")
    if job.dance is not None and job.spec != DanceSpec(targets=TargetConfig(robot=job.spec.robot)):
        raise QuaddanceError(
            "--dance FILE is a dance already: --mode, --style, --moves and "
            "--seed choose the dance of a SONG, --demo or --motion"
        )
    job.backend.check()
    if job.inject and job.backend.robot != "sim":
        raise QuaddanceError("--inject works with --robot sim only (never on a real robot)")
    if job.seconds is not None and not (math.isfinite(job.seconds) and job.seconds > 0):
        raise QuaddanceError(f"--seconds must be > 0, got {job.seconds}")
    for path in (job.song, job.motion, job.dance):
        if path is not None and not Path(path).is_file():
            raise InputFileError(path, "no such file")
    policy = OnnxPolicy.load(job.policy or shipped_policy_path(job.spec.robot))
    spec = spec_for_policy(job.spec, policy)
    out = ensure_dir(job.out_dir)
    for name in ("deploy.json", "log.npz", "rollout.npz"):
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
        if abs(dance.fps - policy.task.policy_hz) > 1e-6:
            raise InputFileError(
                job.dance or song or job.motion,
                f"dance is at {dance.fps:g} Hz but the policy runs at {policy.task.policy_hz:g} Hz",
            )
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
        runner = Runner(
            make_robot(job.backend, policy.task.scene.robot),
            policy,
            dance.targets_m,
            options,
            status=status,
            body_targets=dance.body_targets,
        )
        result = runner.run()
    paths = write_outputs(out, result, policy, dance.beats_s)
    return result.summary, paths


def summary_line(summary: dict) -> str:
    """One line for a person from deploy.json's contents: the final state, the time danced,
    falls, the front paws' tracking error and the tick time."""
    front = summary["front"] or {}
    mae = [front[f]["mae_m"] for f in ("fl", "fr") if f in front and front[f]["mae_m"] is not None]
    return (
        f"final state {summary['final_state']}, danced {summary['duration_s']:.1f} s, "
        f"falls {summary['falls']}, front MAE "
        + (f"{100 * sum(mae) / len(mae):.1f} cm" if mae else "n/a")
        + f", tick p99 {summary['tick_ms']['p99']} ms"
    )
