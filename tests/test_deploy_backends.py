"""deploy's backends (`--robot sim|go1-sim|go2-sim|go1|go2`): the robot model each drives,
what a first real run needs (the dry run, the remote's damping buttons, a low battery), and
real-time dances through each robot's own protocol against its simulator on 127.0.0.1.

Deadlines are measured in dance time from the run's own log, not by timing this test.
"""

from __future__ import annotations

import dataclasses
import json
import os

import numpy as np
import pytest
from realtime import skip_if_stalled_before, skip_if_starved

from quaddance.deploy.job import BACKENDS, BackendOptions, DeployJob, make_robot, run_deploy
from quaddance.deploy.remote import DAMP_KEYS, KEY_B, KEY_L2, decode_remote, encode_remote
from quaddance.deploy.runner import DeployOptions, Runner
from quaddance.errors import QuaddanceError
from quaddance.pipeline import DanceSpec, target_bank
from quaddance.play.dance import spec_for_policy
from quaddance.play.policy import OnnxPolicy, shipped_policy_path
from quaddance.robots import GO1, GO2, get_robot
from quaddance.targets import TargetConfig


def targets_for(policy: OnnxPolicy, seconds: float, seed: int = 3) -> np.ndarray:
    robot_spec = DanceSpec(targets=TargetConfig(robot=policy.task.scene.robot))
    cfg = spec_for_policy(robot_spec, policy).targets
    return target_bank(1, seconds, seed=seed, cfg=cfg)[0].astype(np.float64)


def test_the_remote_layout_round_trips_the_vendors_button_bits():
    raw = encode_remote(DAMP_KEYS)
    assert len(raw) == 40 and raw[:2] == b"\0\0"
    # unitree_sdk2's joystick reads L2 as bit 5 of byte 2 and B as bit 1 of byte 3.
    assert raw[2] == 1 << 5 and raw[3] == 1 << 1
    assert decode_remote(raw) == KEY_L2 | KEY_B
    assert decode_remote(b"") == 0 and decode_remote(list(raw)) == DAMP_KEYS


@pytest.mark.parametrize(
    ("backend", "policy_robot", "message"),
    [
        ("go2-sim", GO1, "--robot go2-sim drives a Go2, but the policy is for unitree_go1"),
        ("go1", GO2, "--robot go1 drives a Go1"),
        ("go2", GO2, "--robot go2 needs --network IFACE"),
        ("go3", GO1, "--robot must be one of sim, go1-sim, go2-sim, go1, go2"),
    ],
)
def test_each_backend_drives_its_robot_model(backend, policy_robot, message):
    with pytest.raises(QuaddanceError, match=message):
        make_robot(BackendOptions(robot=backend), policy_robot)


def test_dry_run_checks_the_state_and_sends_nothing(tmp_path, monkeypatch):
    from quaddance.deploy import job as job_module

    made = []

    def recording(backend, robot_cfg):
        made.append(make_robot(backend, robot_cfg))
        return made[-1]

    monkeypatch.setattr(job_module, "make_robot", recording)
    summary, paths = run_deploy(DeployJob(out_dir=tmp_path, dry_run=True))
    assert summary["dry_run"] and summary["ok"], summary["checks"]
    assert set(summary["checks"]) == {
        "states",
        "finite",
        "joints_in_range",
        "imu_upright",
        "battery",
    }
    assert made[0].received()["commands"] == 0  # the simulator saw no command at all
    assert json.loads(paths["summary"].read_text())["checks"]["battery"]["detail"].startswith(
        "90 %"
    )
    with np.load(paths["log"]) as z:
        assert z["q"].shape[1] == 12 and len(z["seq"]) >= 100  # 3 s at 50 Hz


# --- real-time runs through the robots' own protocols and their vendors' SDKs ---------------

#: The backends that reach a simulator through a vendor SDK and that robot's protocol.
PROTOCOL_SIMS = ["go1-sim", "go2-sim"]


@pytest.fixture(scope="module")
def policies() -> dict[str, OnnxPolicy]:
    """The shipped policy of each simulated backend's robot (`sim`: the Go1's)."""
    return {
        b: OnnxPolicy.load(shipped_policy_path(get_robot(BACKENDS[b] or "go1")))
        for b in ("sim", *PROTOCOL_SIMS)
    }


def run_backend(backend: str, policy: OnnxPolicy, seconds: float, inject=()) -> tuple[dict, dict]:
    robot = make_robot(BackendOptions(robot=backend), policy.task.scene.robot)
    opts = DeployOptions(seconds=seconds, auto_start=True, inject=list(inject))
    result = Runner(robot, policy, targets_for(policy, seconds, seed=5), opts).run()
    return result.summary, robot.received()


@pytest.mark.parametrize("backend", PROTOCOL_SIMS)
def test_a_dance_through_the_vendor_sdk_rides_out_lag(backend, policies):
    summary, received = run_backend(backend, policies[backend], 6.0, [("lag", 4.0)])
    if summary["final_state"] != "done":
        skip_if_starved(summary)
        skip_if_stalled_before(summary, 4.0)
    assert summary["final_state"] == "done", summary["events"]
    assert summary["falls"] == 0 and summary["duration_s"] == pytest.approx(6.0, abs=0.05)
    maes = [summary["front"][f]["mae_m"] for f in ("fl", "fr")]
    assert max(maes) <= 0.02, maes
    # Every command the runner sent reached the motors intact (CRC checked by the simulator).
    assert received["rejected"] == 0 and received["torque_commands"] > 0.9 * 50 * 12
    assert summary["sim"]["physics_dt_s"] == 0.001 and summary["sim"]["sdk"]


@pytest.mark.parametrize("backend", PROTOCOL_SIMS)
@pytest.mark.parametrize(("fault", "deadline_s"), [("push", 1.5), ("freeze", 0.1), ("nan", 0.06)])
def test_faults_reach_the_protocol_simulators_and_end_in_damp(backend, fault, deadline_s, policies):
    summary, _ = run_backend(backend, policies[backend], 3.0, [(fault, 1.0)])
    skip_if_stalled_before(summary, 1.0)
    assert summary["final_state"] == "damp", summary["events"]
    (inj,) = summary["injected"]
    damp = [e for e in summary["events"] if e["to"] == "damp"]
    t = damp[0]["t_s"] - inj["t_s"]
    if t > deadline_s:
        skip_if_starved(summary)
    assert 0 <= t <= deadline_s, (fault, t, summary["events"])


@pytest.mark.parametrize("backend", PROTOCOL_SIMS)
def test_the_dry_run_sends_no_torque_through_the_sdk(backend, policies, tmp_path):
    from quaddance.deploy.dry_run import dry_run

    robot = make_robot(BackendOptions(robot=backend), policies[backend].task.scene.robot)
    summary, _ = dry_run(robot, policies[backend].task.scene.robot)
    assert summary["ok"], summary["checks"]
    received = robot.received()
    # A Go1's SDK link answers only to commands: it exchanges idle (zero-gain) frames.
    assert received["torque_commands"] == 0 and received["rejected"] == 0, received


@pytest.mark.parametrize("command", ["deploy", "live"])
def test_the_backend_options_reach_the_job_and_the_go2_backend(monkeypatch, command):
    from test_dance_options import _job

    from quaddance.deploy.go2_backend import Go2Robot

    flags = ["--robot", "go2", "--network", "eth7", "--dds-domain", "7"]
    job = _job(monkeypatch, command, *flags, *(["--dry-run"] if command == "deploy" else []))
    assert (job.backend.robot, job.backend.network, job.backend.dds_domain) == ("go2", "eth7", 7)
    assert job.spec.robot == GO2  # the robot model follows the backend
    assert command == "live" or job.dry_run
    robot = make_robot(job.backend, GO2)  # made, not started: nothing on the network
    assert isinstance(robot, Go2Robot) and (robot.network, robot.domain_id) == ("eth7", 7)


def test_dry_run_checks_fail_on_what_a_bad_set_up_reads(monkeypatch):
    from typer.testing import CliRunner

    from quaddance.cli import app
    from quaddance.deploy import job as job_module
    from quaddance.deploy.dry_run import check_readings
    from quaddance.deploy.robot import Reading

    def reading(seq: int, q: np.ndarray, quat, battery: float) -> Reading:
        z = np.zeros(3)
        return Reading(seq, seq * 0.02, np.asarray(quat, float), z, q, np.zeros(12), np.zeros(4),
                       battery_pct=battery)  # fmt: skip

    good_q = np.asarray(GO1.nominal_joint_pos_rad)
    swapped = good_q.copy()
    swapped[2] = -swapped[2]  # a calf read with the wrong sign: out of its range
    tilted = [np.cos(0.3), np.sin(0.3), 0.0, 0.0]  # rolled 0.6 rad: not upright
    rs = [reading(k, swapped, tilted, 20.0) for k in range(40)]
    checks = check_readings(rs, reads=100, robot=GO1)
    assert {k for k, c in checks.items() if not c["ok"]} == {
        "states", "joints_in_range", "imu_upright", "battery",
    }  # fmt: skip
    assert checks["joints_in_range"]["detail"] == "out of range: FR_calf_joint"
    ok = check_readings([reading(k, good_q, [1, 0, 0, 0], 80.0) for k in range(50)], 50, GO1)
    assert all(c["ok"] for c in ok.values()), ok

    failed = {"dry_run": True, "ok": False, "checks": checks}
    monkeypatch.setattr(job_module, "run_deploy", lambda job, status: (failed, {}))
    result = CliRunner().invoke(app, ["deploy", "--dry-run"])
    assert result.exit_code == 1 and "dry run FAILED" in result.output, result.output


@pytest.mark.parametrize("backend", ["sim", *PROTOCOL_SIMS])
def test_a_low_battery_refuses_the_start_before_any_command(backend, policies):
    policy = policies[backend]
    robot = make_robot(BackendOptions(robot=backend), policy.task.scene.robot)
    robot.cfg = dataclasses.replace(robot.cfg, battery_pct=12.0)  # before it starts
    runner = Runner(robot, policy, targets_for(policy, 2.0), DeployOptions())
    with pytest.raises(QuaddanceError, match="battery at 12 %, below 25 %"):
        runner.run()
    assert robot.received()["torque_commands"] == 0


@pytest.mark.parametrize("backend", ["sim", *PROTOCOL_SIMS])
def test_the_remotes_damping_buttons_damp_at_once(backend, policies):
    """L2 + B held on the remote reaches the runner in the robot's own state message."""
    policy = policies[backend]
    robot = make_robot(BackendOptions(robot=backend), policy.task.scene.robot)
    pressed: list[float] = []

    def press_at_1s(tick) -> None:
        if tick.t_dance >= 1.0 and not pressed:
            pressed.append(tick.t_dance)
            robot.press(DAMP_KEYS)

    opts = DeployOptions(seconds=3.0, auto_start=True)
    targets = targets_for(policy, 3.0)
    summary = Runner(robot, policy, targets, opts, on_tick=press_at_1s).run().summary
    skip_if_stalled_before(summary, pressed[0] if pressed else float("inf"))
    damp = [e for e in summary["events"] if e["to"] == "damp"]
    assert damp and damp[0]["reason"] == "the remote's L2 + B", summary["events"]
    # The press travels the state stream's latency (<= 10 ms each way) to the next tick.
    assert 0 <= damp[0]["t_s"] - pressed[0] <= 0.1, (damp, pressed)


def test_bench_deploy_robot_runs_that_backend_with_its_robots_policy(tmp_path, monkeypatch):
    """`bench deploy --robot go2-sim`: the Go2 policy, every run on go2-sim, its own file."""
    from typer.testing import CliRunner

    from benchmarks import deploy as bench
    from quaddance.cli import app

    ran: list[tuple[str, str]] = []
    mae = {f: {"mae_m": 0.002} for f in ("fl", "fr")}

    def compare(policy, song, seconds, backend, log):
        ran.append((policy.robot.name, backend))
        run = {"front_mae_mean_m": 0.002, "falls": 0, "tick_ms": {}, "final_state": "done"}
        return {"dance": run, "deploy_sim": run}, "the demo's dance"

    def deploy(policy, dance, seconds, backend, inject=()):
        assert dance == "the demo's dance"  # the faults are run on the demo song's dance
        ran.append((policy.robot.name, backend))
        (fault, at_s), t_damp = inject[0], inject[0][1] + 0.05
        events = [] if fault == "lag" else [{"to": "damp", "t_s": t_damp, "reason": fault}]
        return {"injected": [{"fault": fault, "t_s": at_s}], "events": events, "falls": 0,
                "final_state": "done" if fault == "lag" else "damp", "front": mae,
                "sim": {"late_ms": {"max": 1.0}}}  # fmt: skip

    monkeypatch.setattr(bench, "_compare", compare)
    monkeypatch.setattr(bench, "_deploy", deploy)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(app, ["bench", "deploy", "--robot", "go2-sim", "--seconds", "1"])
    assert result.exit_code == 0, result.output
    assert set(ran) == {(GO2.name, "go2-sim")} and len(ran) == 3 + 4
    report = json.loads((tmp_path / "benchmarks/results/deploy_go2-sim.json").read_text())
    assert report["backend"] == "go2-sim" and report["policy"] == "go2_dance.onnx"
    bad = CliRunner().invoke(app, ["bench", "deploy", "--robot", "go2"])  # never a real one
    assert isinstance(bad.exception, QuaddanceError)
    assert "--robot must be one of sim, go1-sim, go2-sim" in str(bad.exception)


def test_a_dry_run_names_the_rollout_an_earlier_run_left(tmp_path):
    """A dry run writes deploy.json and log.npz; an earlier dance's rollout.npz in the folder
    is kept and named as not this run's."""
    import subprocess
    import sys

    older = tmp_path / "rollout.npz"
    older.write_bytes(b"an earlier dance")
    done = subprocess.run(
        [sys.executable, "-m", "quaddance.cli", "deploy", "--dry-run", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=120, env={**os.environ, "COLUMNS": "200"},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    notes = [line for line in done.stderr.splitlines() if line.startswith("note:")]
    assert notes == [f"note: {older} is from an earlier run (this one did not write it)"]
    assert older.read_bytes() == b"an earlier dance" and (tmp_path / "deploy.json").is_file()
