"""Whole-body dance in the simulator: leg IK, the body feed-forward, the task's body terms,
and what playback writes (rollout.npz, metrics.json's body section)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from quaddance.robots import GO1
from quaddance.sim import rewards, tasks
from quaddance.sim.body import BodyFeedforward, leg_ik, rpy_matrix
from quaddance.sim.config import DanceTaskCfg
from quaddance.sim.kinematics import foot_pos_b, leg_geometry
from quaddance.sim.observations import ActorObservation


def test_leg_ik_inverts_forward_kinematics():
    geom = leg_geometry(GO1)
    gen = torch.Generator().manual_seed(0)
    q = torch.tensor(GO1.nominal_joint_pos_rad)[None] + 0.3 * (
        torch.rand(500, 12, generator=gen) * 2 - 1
    )
    feet = foot_pos_b(q, geom)
    assert torch.allclose(leg_ik(feet, geom), q, atol=1e-4)


def test_body_feedforward_keeps_the_feet_where_they_stand():
    ff = BodyFeedforward(GO1)
    geom = leg_geometry(GO1)
    body = torch.tensor(
        [[0.0, 0.0, 0.0, 0.0], [-0.05, 0.0, 0.0, 0.0], [0.02, 0.2, -0.1, 0.15], [0, 0, 0.2, -0.2]]
    )
    offsets = ff(body)
    assert offsets[0].abs().max() < 1e-6  # the standing pose needs no offset
    assert offsets[1:].abs().amax(dim=1).min() > 0.05  # every other pose moves joints
    q = torch.tensor(GO1.nominal_joint_pos_rad)[None] + offsets
    # Feet in the world: trunk rotated by the target's rpy and raised by its height offset.
    feet_w = torch.einsum("nij,nkj->nki", rpy_matrix(body[:, 1:]), foot_pos_b(q, geom))
    feet_w[..., 2] += body[:, :1]
    assert torch.allclose(feet_w, ff.feet0_b.expand_as(feet_w), atol=1e-5)


def test_whole_body_actor_sees_body_targets_now_and_ahead():
    paws = ActorObservation(DanceTaskCfg(), 1).layout
    whole = ActorObservation(DanceTaskCfg(whole_body=True), 1).layout
    assert whole[: len(paws)] == paws
    assert [(t.name, t.size, t.source) for t in whole[len(paws) :]] == [
        ("body_targets_now", 4, "dance"),
        ("body_targets_preview", 12, "dance"),
    ]
    cfg = DanceTaskCfg(whole_body=True)
    ob = ActorObservation(cfg, 2)
    body = torch.tensor([[0.01, 0.1, 0.2, 0.3], [0.0, 0.0, 0.0, 0.0]])
    prop = torch.zeros(2, ob.history.shape[2])
    obs = ob.build(prop, lambda k: torch.zeros(2, 4), lambda k: body * (k + 1))
    assert obs.shape[1] == sum(t.size for t in whole)
    assert torch.equal(obs[:, -16:-12], body)  # now
    assert torch.equal(obs[:, -4:], body * (ob.preview_steps[-1] + 1))  # furthest preview
    with pytest.raises(ValueError, match="body targets"):
        ob.build(prop, lambda k: torch.zeros(2, 4))


def test_heading_error_is_imu_yaw_since_the_start_minus_the_target_wrapped():
    from quaddance.sim.config import ObsCfg
    from quaddance.sim.observations import Measurement

    ob = ActorObservation(tasks.whole_body(), 2)
    terms = ob.layout
    assert terms[:-1] == ActorObservation(DanceTaskCfg(whole_body=True), 1).layout
    assert (terms[-1].name, terms[-1].size, terms[-1].source) == (
        "heading_error_rad",
        1,
        "dance+imu",
    )
    # heading is a whole-body input only
    paws = ActorObservation(DanceTaskCfg(obs=ObsCfg(heading=True)), 1).layout
    assert paws == ActorObservation(DanceTaskCfg(), 1).layout

    def quat_yaw(yaw: float) -> list[float]:
        return [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]

    # The IMU reads 3.0 rad; the dance began at -3.0 rad: the robot turned 6.0 rad, which is
    # -0.283 rad once wrapped. The targets ask for +0.1 and -0.1 rad.
    quat = torch.tensor([quat_yaw(3.0), quat_yaw(3.0)])
    meas = Measurement.from_imu(
        quat,
        torch.zeros(2, 3),
        torch.tensor([GO1.nominal_joint_pos_rad] * 2),
        torch.zeros(2, 12),
        heading_zero_rad=-3.0,
    )
    turned = 6.0 - 2 * np.pi
    assert meas.heading_rad.numpy() == pytest.approx([turned] * 2, abs=1e-5)
    prop = ob.proprio(meas, torch.zeros(2, 12))
    body = torch.tensor([[0.0, 0.0, 0.0, 0.1], [0.0, 0.0, 0.0, -0.1]])
    obs = ob.build(prop, lambda k: torch.zeros(2, 4), lambda k: body)
    assert obs.shape[1] == sum(t.size for t in terms)
    assert obs[:, -1].numpy() == pytest.approx([turned - 0.1, turned + 0.1], abs=1e-5)


def test_the_robot_runner_measures_heading_from_the_dance_start():
    from quaddance.deploy.controller import DanceController
    from quaddance.deploy.robot import Reading
    from quaddance.play.policy import OnnxPolicy, shipped_policy_path

    def reading(yaw: float) -> Reading:
        return Reading(
            seq=1,
            stamp_s=0.0,
            quat_wxyz=np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]),
            gyro_rad_s=np.zeros(3),
            joint_pos_rad=np.array(GO1.nominal_joint_pos_rad),
            joint_vel_rad_s=np.zeros(12),
        )

    ctrl = DanceController(
        OnnxPolicy.load(shipped_policy_path()), np.zeros((10, 4)), np.zeros((10, 4))
    )
    ctrl.reset(reading(1.2))
    assert float(ctrl.measurement(reading(1.25)).heading_rad[0]) == pytest.approx(0.05, abs=1e-5)


def _hold_env(
    poses: list[tuple[float, float, float, float]], whole_body: bool, curriculum: float = 1.0
):
    from quaddance.sim.task import DanceEnv

    cfg = tasks.TASKS["whole-body" if whole_body else "paws-only"](num_envs=len(poses))
    cfg.domain_rand.enabled = False
    n = 125
    bank = np.zeros((len(poses), n, 8), np.float32)
    ramp = np.clip((np.arange(n) - 25) / 50, 0, 1)[:, None]
    bank[:, :, 4:] = ramp * np.asarray(poses, np.float32)[:, None, :]
    env = DanceEnv(cfg, bank, random_start=False, seed=0)
    env.curriculum_scale = curriculum
    env.bank_idx[:] = torch.arange(len(poses))
    for _ in range(n - 1):
        _, _, _, extras = env.step(torch.zeros(len(poses), 12))
    return env, extras


def test_body_feedforward_moves_the_simulated_trunk_and_rewards_track_it():
    poses = [(0.0, 0, 0, 0), (-0.04, 0, 0, 0), (0, 0.15, 0, 0), (0, 0, 0, 0.15)]
    env, extras = _hold_env(poses, whole_body=True)
    r = env.robot
    height = r.base_pos_w[:, 2] - r.base_pos_w[0, 2]
    rpy = r.base_rpy_rad - r.base_rpy_rad[0]
    assert height[1] == pytest.approx(-0.04, abs=0.015)
    assert rpy[2, 0] == pytest.approx(0.15, abs=0.04)
    assert rpy[3, 2] == pytest.approx(0.15, abs=0.06)
    body_terms = ("body_height_tracking", "body_tilt_tracking", "body_yaw_tracking")
    for name in body_terms:
        assert f"/reward/{name}" in extras["log"]
    # Without the whole-body task the same targets leave the trunk standing.
    env0, extras0 = _hold_env(poses, whole_body=False)
    assert (env0.robot.base_rpy_rad[:, 0] - env0.robot.base_rpy_rad[0, 0]).abs().max() < 0.03
    assert not any(f"/reward/{name}" in extras0["log"] for name in body_terms)


def test_curriculum_scale_zero_is_the_paws_only_task_and_half_halves_it():
    poses = [(0.0, 0, 0, 0), (0, 0.15, 0, 0), (0, 0, 0, 0.15)]
    env0, extras0 = _hold_env(poses, whole_body=True, curriculum=0.0)
    assert env0.body_targets_at(0).abs().max() == 0.0  # the bank's trunk motion is scaled away
    assert (env0.robot.base_rpy_rad - env0.robot.base_rpy_rad[0]).abs().max() < 0.03
    ramped = [name for name, term in env0.cfg.rewards.items() if term.curriculum]
    assert sorted(ramped) == [
        "body_height_tracking",
        "body_tilt_tracking",
        "body_yaw_tracking",
        "foot_slide",
    ]
    for name in ramped:  # and these terms are off
        assert f"/reward/{name}" not in extras0["log"]
    assert "/reward/front_tracking" in extras0["log"]
    env, extras = _hold_env(poses, whole_body=True, curriculum=0.5)
    assert torch.allclose(env.body_targets_at(0), 0.5 * env.bank[env.bank_idx, -1, 4:])
    assert env.robot.base_rpy_rad[1, 0] - env.robot.base_rpy_rad[0, 0] == pytest.approx(
        0.075, abs=0.03
    )
    for name in ramped:
        assert f"/reward/{name}" in extras["log"]


def test_curriculum_scale_grows_linearly_between_its_env_steps():
    from quaddance.train import curriculum_scale_at

    ramp = (1_000, 3_000)
    assert curriculum_scale_at(None, 0) == 1.0
    assert [curriculum_scale_at(ramp, n) for n in (0, 1_000, 2_000, 2_500, 3_000, 9_000)] == [
        0.0,
        0.0,
        0.5,
        0.75,
        1.0,
        1.0,
    ]


def test_relative_terms_equal_the_old_ones_without_body_targets():
    env, _ = _hold_env([(0.0, 0, 0, 0)] * 2, whole_body=False)
    g = env.robot.projected_gravity_b
    assert torch.allclose(rewards.base_orientation(env), (g[:, :2] ** 2).sum(1))
    want = (env.robot.base_pos_w[:, 2] - env.cfg.base_height_target_m) ** 2
    assert torch.allclose(rewards.base_height(env), want)
    assert torch.allclose(rewards.yaw_rate(env), env.robot.base_ang_vel_b[:, 2] ** 2)


def test_body_metrics_units_and_errors():
    from quaddance.errors import QuaddanceError
    from quaddance.play.metrics import body_metrics

    t = np.linspace(0, 2 * np.pi, 200)
    target = np.column_stack([0.02 * np.sin(t), 0.1 * np.sin(t), 0.0 * t, 0.05 * np.cos(t)])
    measured = target + np.array([0.01, np.deg2rad(2.0), 0.0, 0.0])
    m = body_metrics(target, measured)
    assert m["height"]["mae_m"] == pytest.approx(0.01)
    assert m["roll"]["mae_deg"] == pytest.approx(2.0)
    assert m["roll"]["corr"] == pytest.approx(1.0)
    assert m["height"]["target_range_m"] == pytest.approx(0.04, abs=1e-3)
    assert m["angle_mae_deg"] == pytest.approx(2.0 / 3)
    with pytest.raises(QuaddanceError, match=r"\(T, 4\)"):
        body_metrics(target[:, :3], measured[:, :3])


def check_rollout_and_body_metrics(out_dir, duration_s: float) -> None:
    """What `dance` writes for whole-body analysis: rollout.npz (`ROLLOUT_KEYS`) and the
    ``body`` and ``beat_coverage`` sections of metrics.json (called by test_dance)."""
    from quaddance.play.rollout import ROLLOUT_KEYS

    with np.load(out_dir / "rollout.npz") as z:
        data = {k: z[k] for k in z.files}
    assert set(data) == set(ROLLOUT_KEYS)
    n = data["time_s"].size
    assert n == pytest.approx(duration_s * 50, abs=2)
    assert data["foot_heights_m"].shape == (n, 4) and data["targets_m"].shape == (n, 4)
    assert data["base_rpy_rad"].shape == (n, 3) and data["body_targets"].shape == (n, 4)
    assert 0.2 < float(np.median(data["base_height_m"])) < 0.35  # a standing Go1's trunk
    assert data["beats_s"].size >= 3
    metrics = json.loads((out_dir / "metrics.json").read_text())
    assert set(metrics["body"]) >= {"height", "roll", "pitch", "yaw", "angle_mae_deg"}
    assert 0.0 <= metrics["beat_coverage"] <= 1.0


def test_dance_takes_style_and_moves_files(tmp_path):
    """`dance --style S --moves FILE`: the choice reaches the dance; a bad file is one line."""
    import subprocess
    import sys

    import soundfile as sf

    from quaddance.music.synth import render_song

    song = tmp_path / "song.wav"
    y, _ = render_song(120.0, 4.0, seed=2)
    sf.write(song, y, 22050)
    moves = tmp_path / "moves.toml"
    moves.write_text(
        "[moves.wiggle]\nn_beats = 2\nweight_loud = 5.0\n"
        'gestures = [{ column = "roll_rad", amplitude = 0.1, shape = "swing" }]\n'
        "[styles.party]\nwiggle = 10.0\n"
    )
    cmd = [sys.executable, "-m", "quaddance.cli", "dance", str(song), "--no-video"]
    out = tmp_path / "out"
    proc = subprocess.run(
        [*cmd, "--style", "party", "--moves", str(moves), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    source = json.loads((out / "metrics.json").read_text())["source"]
    assert "style party" in source and "moves.toml" in source
    with np.load(out / "dance.npz") as z:
        assert np.ptp(z["body_targets"][:, 1]) > 0.05  # the wiggle's roll is danced
    moves.write_text('[moves.bad]\ngestures = [{ column = "elbow", amplitude = 0.1 }]\n')
    proc = subprocess.run(
        [*cmd, "--moves", str(moves), "--out", str(tmp_path / "bad")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and "moves.toml" in proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_bench_body_reach_measures_what_the_feedforward_holds(tmp_path):
    """`bench body-reach`: four feet down the feed-forward alone holds the trunk's height and
    roll over a range; on three legs it cannot balance (that is the policy's job); a paws-only
    policy is refused by --policy."""
    import subprocess
    import sys

    out = tmp_path / "body_reach.json"
    cmd = [sys.executable, "-m", "quaddance.cli", "bench", "body-reach", "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    res = json.loads(out.read_text())
    lo, hi = res["four_feet"]["height_offset_m"]
    assert lo <= -0.03 and hi >= 0.03
    assert res["four_feet"]["roll_rad"][1] >= 0.2
    assert res["paw_up"]["roll_rad"] == [0.0, 0.0]
    held = [t for t in res["trials"]["four_feet"] if t["held"]]
    assert all(abs(t["achieved"] - t["amplitude"]) <= 0.35 * abs(t["amplitude"]) for t in held)
    assert all(t["failed"] == [] and t["max_slide_m"] < 0.05 for t in held)
    # Every trial not held says why; on three legs without a policy the robot falls.
    for t in res["trials"]["four_feet"] + res["trials"]["paw_up"]:
        assert t["held"] or t["failed"]
    assert any("fell" in t["failed"] for t in res["trials"]["paw_up"])
    policy = _shipped_policy()
    proc = subprocess.run(
        [*cmd, "--policy", str(policy.onnx_path)], capture_output=True, text=True, timeout=900
    )
    if policy.task.whole_body:  # the policy balances on top of the feed-forward
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert policy.onnx_path.name in json.loads(out.read_text())["what"]
    else:
        assert proc.returncode == 2 and "not a whole-body policy" in proc.stderr


def _shipped_policy():
    from quaddance.play.policy import OnnxPolicy, shipped_policy_path

    return OnnxPolicy.load(shipped_policy_path())


@pytest.mark.parametrize("curriculum", [1.0, 0.5])
def test_the_feedforward_looked_up_is_the_one_of_the_rows_targets(curriculum):
    """The task makes each bank row's feed-forward once; what a step looks up equals the
    feed-forward of the row it reads (the body scaled by the curriculum), made there."""
    from quaddance.sim.task import row_feedforward

    poses = [(0.0, 0, 0, 0), (-0.04, 0.1, 0, 0), (0.02, 0, -0.12, 0.2)]
    env, _ = _hold_env(poses, whole_body=True, curriculum=curriculum)
    row = env.target_row(1)
    assert torch.allclose(env.body_targets_at(1), curriculum * env.bank[env.bank_idx, -1, 4:])
    want = row_feedforward(row, env.feedforward, env.body_feedforward)
    assert want[1:].abs().amax(dim=1).min() > 0.02  # each pose moves joints
    assert torch.allclose(env.feedforward_at(1), want, atol=1e-6, rtol=0)
    assert torch.allclose(
        env.joint_targets(torch.zeros(3, 12)), env.nominal_joint_pos + want, atol=1e-6, rtol=0
    )
