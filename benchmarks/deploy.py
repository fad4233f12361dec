"""bench deploy: sim-to-sim. The same dance by `quaddance dance` (training simulator, no
latency) and by `quaddance deploy --robot BACKEND` (another simulator in real time, with
noise, latency and the safety layer, reached through quaddance's own protocol (`sim`) or
through a vendor SDK and that robot's protocol (`go1-sim`, `go2-sim`)); then each fault's
time to damping. Results as JSON."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from quaddance.dancefile import Dance

#: Faults, when they are injected (dance s) and how long the dance is (s).
FAULT_RUNS: tuple[tuple[str, float, float], ...] = (
    ("push", 1.0, 3.0),
    ("freeze", 1.0, 3.0),
    ("nan", 1.0, 3.0),
    ("lag", 3.0, 6.0),
)
DEADLINES_S = {"push": 1.5, "freeze": 0.1, "nan": 0.06}


def _deploy(policy, dance, seconds, backend: str, inject=()) -> dict:
    """`deploy` of ``dance``'s first ``seconds`` (paw and body targets, as `dance` plays)."""
    from quaddance.deploy.job import BackendOptions, make_robot
    from quaddance.deploy.runner import DeployOptions, Runner

    robot = make_robot(BackendOptions(robot=backend), policy.task.scene.robot)
    opts = DeployOptions(seconds=seconds, auto_start=True, inject=list(inject))
    runner = Runner(robot, policy, dance.targets_m, opts, body_targets=dance.body_targets)
    return runner.run().summary


def _mean_mae(front: dict | None) -> float | None:
    if not front:
        return None
    vals = [front[f]["mae_m"] for f in ("fl", "fr") if front[f]["mae_m"] is not None]
    return float(np.mean(vals)) if vals else None


#: Songs made by code (music.synth), besides the demo song: (name, tempo BPM, render args).
EXTRA_SONGS: tuple[tuple[str, float, dict], ...] = (
    ("96 BPM swing", 96.0, {"seed": 7, "swing": 0.3}),
    ("140 BPM syncopated", 140.0, {"seed": 11, "syncopation": True}),
)


def _songs(tmp: Path, seconds: float) -> list[tuple[str, Path]]:
    import soundfile as sf

    from quaddance.music.synth import render_song, write_demo_song

    demo = tmp / "demo_song.wav"
    write_demo_song(demo)
    songs = [("demo song (118 BPM)", demo)]
    for name, bpm, kwargs in EXTRA_SONGS:
        y, _ = render_song(bpm, seconds + 1.0, **kwargs)
        path = tmp / f"song_{round(bpm)}.wav"
        sf.write(path, y, 22050)
        songs.append((name, path))
    return songs


def _compare(policy, song: Path, seconds: float, backend: str, log) -> tuple[dict, Dance]:
    """The song's first ``seconds`` by `dance` and by `deploy --robot BACKEND`."""
    from quaddance.pipeline import DanceSpec, make_dance
    from quaddance.play.dance import feasible_max_height_m, spec_for_policy
    from quaddance.play.metrics import feasible_mask, tracking_metrics
    from quaddance.play.rollout import rollout
    from quaddance.targets import TargetConfig

    spec = DanceSpec(targets=TargetConfig(robot=policy.robot))
    dance, _ = make_dance(song, None, spec_for_policy(spec, policy))
    n = min(dance.targets_m.shape[0], round(seconds * policy.task.policy_hz))
    feasible_max = feasible_max_height_m(policy)
    played = rollout(dance, policy)
    tgt, feet = played.targets_m[:n], played.feet_m[:n]
    front = tracking_metrics(tgt, feet, feasible_mask(tgt, feasible_max))
    dance_res = {
        "front": front,
        "front_mae_mean_m": _mean_mae(front),
        "rear_lift_mean_m": float(np.clip(feet[:, 2:], 0, None).mean()),
        "falls": sum(1 for t in played.falls_s if t < n / policy.task.policy_hz),
    }
    log(f"  deploy --robot {backend}, {n / policy.task.policy_hz:.0f} s in real time")
    dep = _deploy(policy, dance, n / policy.task.policy_hz, backend)
    deploy_res = {
        k: dep[k]
        for k in (
            "final_state",
            "duration_s",
            "falls",
            "front",
            "rear_lift_mean_m",
            "tick_ms",
            "period_ms",
            "guards",
            "overrun_ticks",
            "priority",
            "sim",
        )
    }
    deploy_res["front_mae_mean_m"] = _mean_mae(dep["front"])
    # Why the run ended where it did not finish the dance (the first damping's reason).
    damp = [e for e in dep["events"] if e["to"] == "damp"]
    deploy_res["why"] = f"{damp[0]['reason']} at {damp[0]['t_s']:.2f} s" if damp else None
    return {
        "seconds": n / policy.task.policy_hz,
        "dance": dance_res,
        "deploy_sim": deploy_res,
    }, dance


def run(seconds: float = 20.0, log: Callable[[str], None] = print, backend: str = "sim") -> dict:
    """Sim-to-sim on ``backend`` with the shipped policy of the robot it simulates (`sim`:
    the Go1's)."""
    from quaddance.deploy.job import BACKENDS
    from quaddance.play.policy import OnnxPolicy, shipped_policy_path
    from quaddance.robots import get_robot

    policy_path = shipped_policy_path(get_robot(BACKENDS[backend] or "go1"))
    policy = OnnxPolicy.load(policy_path)
    songs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, path) in enumerate(_songs(Path(tmp), seconds)):
            log(f"{name}: dance, then deploy")
            songs[name], dance = _compare(policy, path, seconds, backend, log)
            if i == 0:
                demo = dance

    faults = {}
    for fault, at_s, dance_s in FAULT_RUNS:
        log(f"fault {fault}@{at_s:g}")
        s = _deploy(policy, demo, dance_s, backend, [(fault, at_s)])
        (inj,) = s["injected"]
        damp = [e for e in s["events"] if e["to"] == "damp"]
        faults[fault] = {
            "final_state": s["final_state"],
            "damp_reason": damp[0]["reason"] if damp else None,
            "time_to_damp_s": round(damp[0]["t_s"] - inj["t_s"], 4) if damp else None,
            "deadline_s": DEADLINES_S.get(fault),
            "falls": s["falls"],
            "front_mae_mean_m": _mean_mae(s["front"]),
            "sim_late_ms_max": s["sim"]["late_ms"]["max"],
        }
    return {
        "what": "feasible targets; dance = training simulator, deploy_sim = real-time sim robot",
        "backend": backend,
        "policy": policy_path.name,
        "songs": songs,
        "faults": faults,
        "machine": {"cpus": os.cpu_count(), "load_avg_1min": round(os.getloadavg()[0], 2)},
    }
