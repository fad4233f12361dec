"""The actor's observation contract: only what a Go1 measures, built by one class."""

from __future__ import annotations

import copy

import mujoco
import numpy as np
import pytest
import torch

from quaddance.robots import GO1
from quaddance.sim import tasks
from quaddance.sim.config import SOURCES, DanceTaskCfg
from quaddance.sim.kinematics import estimate_foot_height_m, foot_pos_b, leg_geometry
from quaddance.sim.observations import (
    PROPRIO_TERMS,
    ActorObservation,
    Measurement,
    ObsLayout,
    dance_terms,
)
from quaddance.sim.scene import SceneCfg, build_model
from quaddance.sim.task import DanceEnv


def nominal_cfg(num_envs: int) -> DanceTaskCfg:
    cfg = DanceTaskCfg(num_envs=num_envs)
    cfg.domain_rand.enabled = False
    return cfg


def test_leg_kinematics_match_mujoco_for_any_pose():
    model = build_model(SceneCfg())
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    geom = leg_geometry(GO1)
    for _ in range(20):
        data.qpos[:] = model.key("home").qpos
        data.qpos[7:] += rng.uniform(-0.6, 0.6, 12)
        quat = rng.normal(size=4)
        data.qpos[3:7] = quat / np.linalg.norm(quat)
        mujoco.mj_kinematics(model, data)
        rot = data.xmat[1].reshape(3, 3)
        truth = np.stack(
            [rot.T @ (data.site_xpos[model.site(f).id] - data.xpos[1]) for f in GO1.feet]
        )
        ours = foot_pos_b(torch.tensor(data.qpos[None, 7:]), geom)[0].numpy()
        np.testing.assert_allclose(ours, truth, atol=1e-9)


def test_foot_height_estimate_is_exact_relative_to_the_lowest_foot_at_any_tilt():
    model = build_model(SceneCfg())
    data = mujoco.MjData(model)
    rng = np.random.default_rng(2)
    for _ in range(20):
        data.qpos[:] = model.key("home").qpos
        data.qpos[7:] += rng.uniform(-0.4, 0.4, 12)
        roll, pitch, yaw = rng.uniform(-0.3, 0.3, 3)
        mujoco.mju_euler2Quat(data.qpos[3:7], [roll, pitch, yaw], "xyz")
        mujoco.mj_kinematics(model, data)
        z = np.array([data.site_xpos[model.site(f).id][2] for f in GO1.feet])
        quat = torch.tensor(data.qpos[None, 3:7])
        meas = Measurement.from_imu(
            quat, torch.zeros(1, 3), torch.tensor(data.qpos[None, 7:]), torch.zeros(1, 12)
        )
        est = estimate_foot_height_m(
            meas.joint_pos_rad, meas.projected_gravity_b, leg_geometry(GO1)
        )
        np.testing.assert_allclose(est[0].numpy(), z - z.min(), atol=1e-9)


def test_foot_height_estimate_tracks_the_truth_while_the_policy_dances():
    """The shipped policy lifts FL to 15 cm: the estimate stays within 1 cm of the truth."""
    from quaddance.play.policy import OnnxPolicy, shipped_policy_path

    policy = OnnxPolicy.load(shipped_policy_path())
    cfg = copy.deepcopy(policy.task)
    cfg.num_envs = 1
    cfg.domain_rand.enabled = False
    bank = np.zeros((1, 150, 4), np.float32)
    bank[0, 40:, 0] = np.minimum(np.arange(110) * 0.01, 0.15)  # FL up to 15 cm
    table = policy.meta["front_feedforward"]["thigh_calf_offsets_rad"]
    env = DanceEnv(cfg, bank, random_start=False, compute_rewards=False, feedforward_table=table)
    obs = env.get_observations()["actor"]
    err, lifted, landed = [], 0.0, None
    for step in range(140):
        obs = env.step(torch.from_numpy(policy.act(obs.numpy())))[0]["actor"]
        s = env.robot
        est = estimate_foot_height_m(s.joint_pos, s.projected_gravity_b, leg_geometry(GO1))
        err.append((est - s.foot_height_m).abs().max().item())
        lifted = max(lifted, s.foot_height_m[0, 0].item())
        if landed is None and (s.foot_height_m < 0.005).all():
            landed = step
    assert lifted > 0.12  # the foot really went up
    # From 0.1 s after all four feet are down: at the very start the robot drops from its
    # spawn height with its feet in the air, where no "lowest foot on the floor" holds, and
    # lands hard enough to press its feet into MuJoCo's soft floor unevenly for a moment.
    assert landed is not None and landed < 25
    assert max(err[landed + 5 :]) < 0.01


def test_actor_terms_come_only_from_robot_sensors():
    assert all(t.source in SOURCES for t in PROPRIO_TERMS)
    ob = ActorObservation(nominal_cfg(1), 1)
    assert ob.proprio_dim == 46
    assert sum(t.size for t in ob.layout) == ob.proprio_dim * 4 + 2 + 6
    for term in ob.layout:
        assert all(part in SOURCES for part in term.source.split("+")), term


@pytest.mark.parametrize("variant", ["paws-only", "whole-body"])
def test_the_layout_read_off_the_term_tables_is_what_the_builder_concatenates(variant):
    """Each slice of the layout holds its term's values, in order, for both task variants;
    the critic adds the privileged terms after the actor's."""
    cfg = tasks.TASKS[variant](num_envs=2)
    cfg.domain_rand.enabled = False
    bank = np.random.default_rng(0).uniform(0.0, 0.1, (1, 60, 8)).astype(np.float32)
    env = DanceEnv(cfg, bank if cfg.whole_body else bank[..., :4], random_start=False)
    for _ in range(3):
        obs = env.step(torch.rand(2, 12) - 0.5)[0]
    layout = env.obs_layout
    assert obs["actor"].shape[1] == layout.actor_dim
    assert obs["critic"].shape[1] == layout.critic_dim
    ob = env.actor_obs
    start = 0
    columns = {}
    for s in layout.critic:
        columns[s.name] = obs["critic"][:, start : start + s.size]
        start += s.size
    names = [s.name for s in layout.actor]
    n_proprio = len(PROPRIO_TERMS)
    assert names[:n_proprio] == [f"proprio.{t.name}" for t in PROPRIO_TERMS]
    for t in PROPRIO_TERMS:
        torch.testing.assert_close(columns[f"proprio.{t.name}"], t.fn(ob))
    dance = dance_terms(cfg)
    assert names[n_proprio + ob.history_len :] == [t.name for t in dance]
    assert ("heading_error_rad" in names) == cfg.whole_body
    for t in dance:
        torch.testing.assert_close(columns[t.name], t.fn(ob))
    privileged = [s.name for s in layout.critic[len(layout.actor) :]]
    assert privileged == [
        "privileged.dynamics",
        "privileged.base_lin_vel_b",
        "privileged.base_height_m",
    ]
    torch.testing.assert_close(columns["privileged.base_height_m"], env.robot.base_pos_w[:, 2:3])
    # The training log's column names are the layout's, one per column.
    names = layout.column_names()
    assert len(names["actor"]) == layout.actor_dim and len(names["critic"]) == layout.critic_dim
    assert names["critic"][-1] == "privileged.base_height_m[0]"


def test_a_critic_without_privileged_terms_sees_what_the_actor_sees():
    actor = ActorObservation(nominal_cfg(1), 1).layout
    assert ObsLayout.of(actor, (), privileged_critic=True).critic == actor
    env = DanceEnv(nominal_cfg(1), np.zeros((1, 60, 4), np.float32))
    assert ObsLayout.of(actor, env.privileged_slices, privileged_critic=False).critic == actor


def test_one_robot_builder_reproduces_the_training_observation():
    """The runner's path (IMU quaternion + encoders -> Measurement -> ActorObservation) gives
    the training env's observation, history included, to 1e-6."""
    bank = np.zeros((1, 100, 4), np.float32)
    bank[0, :, 0] = np.linspace(0.0, 0.2, 100)
    cfg = nominal_cfg(1)
    cfg.domain_rand.joint_offset_rad = 0.0
    env = DanceEnv(cfg, bank, random_start=False, compute_rewards=False)
    runner = ActorObservation(cfg, 1)
    rng = np.random.default_rng(1)
    last_action = torch.zeros(1, 12)
    for t in range(12):
        s = env.robot
        meas = Measurement.from_imu(s.base_quat_w, s.base_ang_vel_b, s.joint_pos, s.joint_vel)
        prop = runner.proprio(meas, last_action)
        if t == 0:
            runner.reset(torch.tensor([0]), prop)

        def targets_at(k: int, t: int = t) -> torch.Tensor:
            return torch.from_numpy(bank[0, min(t + k, 99)])[None]

        ours = runner.build(prop, targets_at)
        theirs = env.get_observations()["actor"]
        torch.testing.assert_close(ours, theirs, atol=1e-6, rtol=0)
        runner.push(prop)
        last_action = torch.from_numpy(rng.normal(0, 0.3, (1, 12)).astype(np.float32))
        env.step(last_action)


def test_sensor_noise_reaches_the_actor_only_when_randomising():
    bank = np.zeros((1, 100, 4), np.float32)
    cfg = DanceTaskCfg(num_envs=4)
    cfg.domain_rand.push_vel_m_s = 0.0
    env = DanceEnv(cfg, bank, random_start=False, compute_rewards=False)
    clean = Measurement.from_state(env.robot, env.joint_offset)
    noisy = env.measure()
    dr = cfg.domain_rand
    for name, scale in (
        ("projected_gravity_b", dr.gravity_noise),
        ("gyro_rad_s", dr.gyro_noise_rad_s),
        ("joint_pos_rad", dr.joint_pos_noise_rad),
        ("joint_vel_rad_s", dr.joint_vel_noise_rad_s),
    ):
        diff = (getattr(noisy, name) - getattr(clean, name)).abs()
        assert 0.3 * scale < diff.max() <= scale + 1e-6, name
    cfg.domain_rand.sensor_noise = False
    quiet = env.measure()
    torch.testing.assert_close(quiet.joint_pos_rad, clean.joint_pos_rad)
