"""The dance simulation: scene and sensors, robot state, rewards, terminations, domain
randomisation, and agreement of the cpu (native MuJoCo) and gpu (MuJoCo Warp) engines."""

from __future__ import annotations

import math
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from benchmarks.train import engine_gaps, noisy_home, random_controls
from quaddance.robots import GO1
from quaddance.sim import rewards, tasks, terminations
from quaddance.sim.config import DanceTaskCfg, RewardTerm
from quaddance.sim.engines import CpuEngine, apply_dynamics
from quaddance.sim.kinematics import estimate_foot_height_m, leg_geometry
from quaddance.sim.scene import SceneCfg, build_model
from quaddance.sim.state import (
    SensorLayout,
    gravity_from_sums,
    quat_rotate_inverse,
    quat_sums,
    rpy_from_sums,
    state_from_arrays,
    yaw_from_sums,
)
from quaddance.sim.task import DanceEnv, sample_dynamics

POLICY_HZ = 50
# Model joint order is FR, FL, RR, RL x (hip, thigh, calf); task foot order is FL, FR, RL, RR.
FR_THIGH, FR_CALF, FL_THIGH, FL_CALF = 1, 2, 4, 5
FL, FR, RL, RR = 0, 1, 2, 3


def task_cfg(num_envs: int, **kwargs) -> DanceTaskCfg:
    """The paws-only task without domain randomisation (nominal robot, no pushes, no lag)."""
    cfg = tasks.paws_only(num_envs=num_envs)
    for key, value in kwargs.items():
        setattr(cfg, key, value)
    cfg.domain_rand.enabled = False
    return cfg


def flat_bank(length: int = 200) -> np.ndarray:
    return np.zeros((1, length, 4), np.float32)


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return build_model()


# --- scene and state ------------------------------------------------------------------------


def test_model_joints_and_actuators_follow_go1_order(model):
    assert (model.nq, model.nv, model.nu) == (7 + 12, 6 + 12, 12)
    for i, name in enumerate(GO1.joint_names):
        joint = model.joint(name)
        # qpos[7 + i] is joint i, and actuator i drives it: the action layout relies on both.
        assert joint.qposadr[0] == 7 + i
        assert model.actuator_trnid[i, 0] == joint.id
    np.testing.assert_allclose(model.key("home").qpos[7:], GO1.nominal_joint_pos_rad)
    np.testing.assert_allclose(
        model.key("home").qpos[:7], [0, 0, GO1.init_base_height_m, 1, 0, 0, 0]
    )
    # Position actuators with the released code's gains: force = kp (ctrl - q) - kd qdot.
    np.testing.assert_allclose(model.actuator_gainprm[:, 0], 20.0)
    np.testing.assert_allclose(model.actuator_biasprm[:, 1:3], [[-20.0, -0.5]] * 12)


def test_sensor_layout_addresses_are_distinct_and_in_range(model):
    layout = SensorLayout.from_model(model, GO1)
    addresses = [
        *layout.foot_pos,
        *layout.foot_vel,
        *layout.joint_torque,
        layout.base_contact,
        *layout.leg_contact,
    ]
    assert len(layout.foot_pos) == len(layout.foot_vel) == 12
    assert len(layout.joint_torque) == 12 and len(layout.leg_contact) == 8
    assert len(set(addresses)) == len(addresses)
    assert min(addresses) >= 0 and max(addresses) < model.nsensordata
    assert len(addresses) == model.nsensordata  # every sensor value is read by the task


def test_state_reads_feet_torques_and_velocities_of_the_named_bodies(model):
    d = mujoco.MjData(model)
    qpos, qvel = noisy_home(model, 1, seed=3)
    d.qpos[:], d.qvel[:] = qpos[0].numpy(), qvel[0].numpy()
    d.ctrl[:] = np.asarray(GO1.nominal_joint_pos_rad) + 0.2
    mujoco.mj_forward(model, d)
    layout = SensorLayout.from_model(model, GO1)
    as_t = lambda a: torch.as_tensor(np.asarray(a)[None], dtype=torch.float64)  # noqa: E731
    s = state_from_arrays(as_t(d.qpos), as_t(d.qvel), as_t(d.sensordata), layout)
    for k, foot in enumerate(GO1.feet):
        np.testing.assert_allclose(s.foot_pos_w[0, k].numpy(), d.site(foot).xpos, atol=1e-9)
        vel = np.zeros(6)
        mujoco.mj_objectVelocity(model, d, mujoco.mjtObj.mjOBJ_SITE, model.site(foot).id, vel, 0)
        np.testing.assert_allclose(s.foot_vel_w[0, k].numpy(), vel[3:], atol=1e-9)
        # THE foot height: bottom of the foot sphere above the floor.
        assert s.foot_height_m[0, k].item() == pytest.approx(d.site(foot).xpos[2] - 0.023)
    np.testing.assert_allclose(s.joint_torque[0].numpy(), d.actuator_force, atol=1e-9)
    np.testing.assert_allclose(s.joint_pos[0].numpy(), d.qpos[7:])
    assert not bool(s.base_contact[0])


def test_quat_rotate_inverse_matches_scipy():
    rot = Rotation.random(64, random_state=7)
    vec = np.random.default_rng(7).normal(size=(64, 3))
    xyzw = rot.as_quat()
    wxyz = torch.tensor(np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1))
    got = quat_rotate_inverse(wxyz, torch.tensor(vec)).numpy()
    np.testing.assert_allclose(got, rot.inv().apply(vec), atol=1e-12)


def test_gravity_and_angles_from_one_pass_over_the_quaternion_match_scipy():
    rot = Rotation.random(64, random_state=11)
    xyzw = rot.as_quat()
    sums = quat_sums(torch.tensor(np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)))
    down_b = rot.inv().apply(np.array([0.0, 0.0, -1.0]))
    np.testing.assert_allclose(gravity_from_sums(sums).numpy(), down_b, atol=1e-12)
    # Extrinsic x-y-z (R = R_z R_y R_x): scipy's intrinsic "ZYX" read backwards.
    yaw_pitch_roll = rot.as_euler("ZYX")
    np.testing.assert_allclose(rpy_from_sums(sums).numpy(), yaw_pitch_roll[:, ::-1], atol=1e-9)
    assert torch.equal(yaw_from_sums(sums), rpy_from_sums(sums)[:, 2])  # the runner's heading


def test_projected_gravity_upright_pitched_and_upside_down():
    env = DanceEnv(task_cfg(3), flat_bank())
    qpos = env.home_qpos.repeat(3, 1)
    pitch = Rotation.from_euler("y", 30, degrees=True).as_quat()  # x, y, z, w
    qpos[1, 3:7] = torch.tensor([pitch[3], *pitch[:3]])
    qpos[2, 3:7] = torch.tensor([0.0, 1.0, 0.0, 0.0])  # 180 deg about x
    env.engine.reset(torch.arange(3), qpos, torch.zeros(3, env.engine.nv))
    g = env._read_state().projected_gravity_b.numpy()
    np.testing.assert_allclose(g[0], [0, 0, -1], atol=1e-6)
    # Nose down by 30 deg: gravity leans towards the body's +x.
    np.testing.assert_allclose(
        g[1], [math.sin(math.radians(30)), 0, -math.cos(math.radians(30))], atol=1e-6
    )
    np.testing.assert_allclose(g[2], [0, 0, 1], atol=1e-6)


def test_standing_with_zero_actions_keeps_base_up_and_feet_down():
    env = DanceEnv(task_cfg(2), flat_bank())
    for _ in range(2 * POLICY_HZ):
        _, _, done, _ = env.step(torch.zeros(2, 12))
        assert not done.any()
    s = env.robot
    assert torch.all((s.base_pos_w[:, 2] > 0.25) & (s.base_pos_w[:, 2] < 0.30))
    assert s.foot_height_m.abs().max().item() < 0.01
    assert torch.all(s.projected_gravity_b[:, 2] < -0.99)  # still level
    assert env.episode_length_buf.tolist() == [2 * POLICY_HZ] * 2


def test_front_leg_command_lifts_that_foot_only():
    """env 0 folds its FL leg, env 1 its FR leg: the measured height of that foot rises."""
    env = DanceEnv(task_cfg(2), flat_bank())
    for _ in range(25):
        env.step(torch.zeros(2, 12))
    action = torch.zeros(2, 12)
    action[0, [FL_THIGH, FL_CALF]] = -4.0  # thigh back by 1 rad, knee bent by 1 rad
    action[1, [FR_THIGH, FR_CALF]] = -4.0
    for _ in range(25):
        _, _, done, _ = env.step(action)
    assert not done.any()
    h = env.robot.foot_height_m
    assert h[0, FL] > 0.03 and h[1, FR] > 0.03
    assert h[0, [FR, RL, RR]].abs().max() < 0.01
    assert h[1, [FL, RL, RR]].abs().max() < 0.01


def layout_slices(items) -> dict[str, slice]:
    out, start = {}, 0
    for item in items:
        out[item.name] = slice(start, start + item.size)
        start += item.size
    return out


def test_observation_layout_names_what_the_policy_sees():
    bank = np.zeros((1, 40, 4), np.float32)
    bank[0, :, FL] = np.arange(40) * 0.01  # FL target = 0.01 m x step
    bank[0, :, FR] = 1.0 - np.arange(40) * 0.01
    env = DanceEnv(task_cfg(2), bank, random_start=False)
    layout = env.obs_layout
    actor, critic = layout_slices(layout.actor), layout_slices(layout.critic)
    before = env.get_observations()["actor"]
    proprio_before = before[:, : actor["proprio.foot_height_m"].stop]
    for _ in range(3):
        obs = env.step(torch.zeros(2, 12))[0]
    a, c = obs["actor"], obs["critic"]
    assert a.shape == (2, layout.actor_dim) and c.shape == (2, layout.critic_dim)
    torch.testing.assert_close(c[:, : layout.actor_dim], a)
    # Targets now (step 3) and 0.1, 0.2, 0.4 s ahead (steps 8, 13, 23), FL then FR.
    now = torch.tensor(bank[0, 3, :2]).repeat(2, 1)
    torch.testing.assert_close(a[:, actor["front_targets_now_m"]], now)
    preview = torch.tensor(bank[0, [8, 13, 23], :2].reshape(-1)).repeat(2, 1)
    torch.testing.assert_close(a[:, actor["front_targets_preview_m"]], preview)
    # Foot heights are the robot's own kinematic estimate, never the simulator's truth
    # (tests/test_observations.py compares the two).
    s = env.robot
    estimate = estimate_foot_height_m(s.joint_pos, s.projected_gravity_b, leg_geometry(GO1))
    torch.testing.assert_close(a[:, actor["proprio.foot_height_m"]], estimate)
    torch.testing.assert_close(
        a[:, actor["proprio.projected_gravity"]], env.robot.projected_gravity_b
    )
    torch.testing.assert_close(
        c[:, critic["privileged.base_height_m"]], env.robot.base_pos_w[:, 2:3]
    )
    # history[3] is what the policy saw three steps ago: the first observation's proprio.
    torch.testing.assert_close(a[:, actor["history[3].proprio"]], proprio_before)
    # Past the end of the sequence the last target is held.
    for _ in range(40):
        obs = env.step(torch.zeros(2, 12))[0]
    torch.testing.assert_close(
        obs["actor"][:, actor["front_targets_preview_m"]],
        torch.tensor(bank[0, [39, 39, 39], :2].reshape(-1)).repeat(2, 1),
    )


# --- rewards --------------------------------------------------------------------------------


def fake_env(feet_m: list[list[float]], targets_m: list[list[float]]) -> SimpleNamespace:
    """What the reward terms read: the robot's foot heights and the targets."""
    feet = torch.tensor(feet_m, dtype=torch.float64)
    targets = torch.tensor(targets_m, dtype=torch.float64)
    env = SimpleNamespace(robot=SimpleNamespace(foot_height_m=feet), targets_at=lambda k: targets)
    env.errors = rewards.TrackingErrors(env)
    return env


def reward_of(term: RewardTerm, env) -> torch.Tensor:
    """A term's value with its weight (before the policy step)."""
    return term.weight * term.fn(env, **term.params)


def test_eq2_is_zero_when_the_front_feet_are_on_target():
    env = fake_env(
        [[0.12, 0.05, 0.0, 0.0], [0.0, 0.0, 0.03, 0.0]],
        [[0.12, 0.05, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]],
    )
    # Rear-foot errors are eq. 3's business, not eq. 2's.
    assert reward_of(tasks.front_tracking(), env).tolist() == [0.0, 0.0]


def test_eq2_value_for_a_hand_set_state():
    env = fake_env([[0.10, 0.00, 0.02, 0.0]], [[0.15, 0.08, 0.0, 0.0]])
    expected = 30.0 * (math.exp(-10.0 * 0.05) - 1) + 30.0 * (math.exp(-10.0 * 0.08) - 1)
    assert reward_of(tasks.front_tracking(), env).item() == pytest.approx(expected, rel=1e-9)
    # Overshooting by the same amount costs the same (|e|).
    env = fake_env([[0.20, 0.16, 0.0, 0.0]], [[0.15, 0.08, 0.0, 0.0]])
    assert reward_of(tasks.front_tracking(), env).item() == pytest.approx(expected, rel=1e-9)


def test_l2_form_is_minus_c_times_squared_error():
    env = fake_env([[0.10, 0.00, 0.0, 0.0]], [[0.15, 0.08, 0.0, 0.0]])
    value = reward_of(tasks.front_tracking("l2"), env).item()
    assert value == pytest.approx(-30.0 * (0.05**2 + 0.08**2))


def test_foot_slide_is_the_speed_of_the_feet_on_the_ground():
    # FL lifted and moving (free), FR creeping 1 cm/s, RL sliding 3-4-5, RR still.
    vel = torch.tensor([[[0.5, 0.5, 0.1], [0.01, 0.0, 0.0], [0.03, 0.04, 0.0], [0.0, 0.0, 0.0]]])
    env = SimpleNamespace(
        robot=SimpleNamespace(foot_height_m=torch.tensor([[0.08, 0.0, 0.002, 0.0]]), foot_vel_w=vel)
    )
    assert rewards.foot_slide(env).item() == pytest.approx(0.01 + 0.05)
    # A slow creep costs in proportion to its speed, not its square (foot_slip's).
    assert rewards.foot_slide(env).item() / rewards.foot_slip(env).item() > 10


@pytest.mark.parametrize(
    ("name", "c_f", "lambda_f"),
    [
        ("paper", 30.0, 10.0),
        ("table1-1", 100.0, 100.0),
        ("table1-2", 100.0, 10.0),
        ("table1-3", 60.0, 100.0),
        ("table1-4", 30.0, 100.0),
        ("table1-5", 30.0, 10.0),
    ],
)
def test_named_reward_sets_follow_table1(name, c_f, lambda_f):
    term = tasks.front_tracking(name)
    assert (term.fn, term.weight) == (rewards.front_tracking, 1.0)
    assert term.params == {"c_f": c_f, "lambda_f": lambda_f}


def test_named_reward_l2_and_unknown_names():
    assert tasks.front_tracking("l2").fn is rewards.front_tracking_l2
    with pytest.raises(ValueError, match="table1-6"):
        tasks.front_tracking("table1-6")


def test_eq3_rear_lift_penalty():
    env = fake_env([[0.0, 0.0, 0.02, 0.03], [0.1, 0.1, -0.002, 0.0]], [[0.0] * 4] * 2)
    r = reward_of(tasks.dance_rewards()["rear_lift"], env)
    assert r[0].item() == pytest.approx(-30.0 * (0.02**2 + 0.03**2))
    assert r[1].item() == 0.0  # front lifts and feet pressed into the floor cost nothing
    assert rewards.rear_lift_l1(env).tolist() == pytest.approx([0.05, 0.0])


def test_env_pays_eq2_times_the_policy_step():
    bank = np.zeros((1, 200, 4), np.float32)
    bank[0, :, FL] = 0.08
    env = DanceEnv(task_cfg(2), bank)
    _, reward, _, extras = env.step(torch.zeros(2, 12))
    expected = reward_of(env.cfg.rewards["front_tracking"], env) / POLICY_HZ
    assert extras["log"]["/reward/front_tracking"].item() == pytest.approx(
        expected.mean().item(), rel=1e-5
    )
    assert expected.max().item() < -0.5 / POLICY_HZ  # the lifted target is missed: a cost
    assert torch.all(reward < 0)


def test_a_reward_terms_weight_scales_its_share_of_the_reward():
    bank = np.zeros((1, 200, 4), np.float32)
    bank[0, :, FL] = 0.08
    cfg = task_cfg(2)
    tripled = task_cfg(2)
    tripled.rewards["front_tracking"].weight *= 3.0
    env, env3 = DanceEnv(cfg, bank), DanceEnv(tripled, bank)
    _, reward, _, extras = env.step(torch.zeros(2, 12))
    _, reward3, _, extras3 = env3.step(torch.zeros(2, 12))
    share = reward_of(cfg.rewards["front_tracking"], env) / POLICY_HZ
    assert share.max().item() < -0.01
    torch.testing.assert_close(reward3 - reward, 2.0 * share)
    log, log3 = extras["log"], extras3["log"]
    assert log3["/reward/front_tracking"].item() == pytest.approx(
        3.0 * log["/reward/front_tracking"].item(), rel=1e-6
    )
    assert log3["/reward/rear_lift"] == log["/reward/rear_lift"]


# --- terminations ---------------------------------------------------------------------------


def test_upside_down_and_low_bases_fall():
    env = DanceEnv(task_cfg(3), flat_bank())
    qpos = env.home_qpos.repeat(3, 1)
    qpos[1, 3:7] = torch.tensor([0.0, 1.0, 0.0, 0.0])  # upside down at standing height
    qpos[2, 2] = 0.06  # trunk on the floor, legs folded under it
    qpos[2, 7:] = torch.tensor([0.0, 1.2, -2.7] * 4)
    env.engine.reset(torch.arange(3), qpos, torch.zeros(3, env.engine.nv))
    env.robot = env._read_state()
    assert terminations.fell(env).tolist() == [False, True, True]
    _, reward, done, extras = env.step(torch.zeros(3, 12))
    assert done.tolist() == [False, True, True]
    assert not extras["time_outs"].any()
    assert extras["log"]["/metrics/falls"].item() == 2
    assert torch.all(reward[1:] <= env.cfg.rewards["termination"].weight)
    assert extras["log"]["/reward/termination"].item() == pytest.approx(-200.0 * 2 / 3)
    # The fallen envs start again standing.
    assert env.episode_length_buf.tolist() == [1, 0, 0]
    np.testing.assert_allclose(env.robot.base_pos_w[1:, 2].numpy(), GO1.init_base_height_m)


def test_time_out_is_reported_and_is_not_a_fall():
    env = DanceEnv(task_cfg(2, episode_length_s=0.1), flat_bank())
    assert env.max_episode_length == 5
    for _ in range(4):
        _, _, done, extras = env.step(torch.zeros(2, 12))
        assert not done.any() and not extras["time_outs"].any()
    _, _, done, extras = env.step(torch.zeros(2, 12))
    assert done.all() and extras["time_outs"].all()
    assert extras["log"]["/metrics/falls"].item() == 0
    assert env.episode_length_buf.tolist() == [0, 0]


# --- domain randomisation -------------------------------------------------------------------


def test_dynamics_variants_change_the_per_env_models():
    rows = np.array([[1.0, 0.0, 1.0], [0.4, 2.5, 1.1], [2.5, -1.0, 0.9]])
    engine = CpuEngine(3, variants=rows)
    base = engine.model
    feet = [base.geom(f"{f}_foot_collision").id for f in GO1.feet]
    trunk = base.body("trunk").id
    for row, m in zip(rows, engine._variant_models, strict=True):
        np.testing.assert_allclose(m.geom_friction[feet, 0], row[0])
        assert m.body_mass[trunk] == pytest.approx(base.body_mass[trunk] + row[1])
        np.testing.assert_allclose(m.actuator_gainprm[:, 0], 20.0 * row[2])
        np.testing.assert_allclose(m.actuator_biasprm[:, 1], -20.0 * row[2])
        np.testing.assert_allclose(m.actuator_biasprm[:, 2], -0.5 * row[2])
    # The shared base model is left alone.
    assert base.body_mass[trunk] == pytest.approx(build_model().body_mass[trunk])
    engine.set_variants(np.array([0, 2]), np.array([1, 2]))
    assert engine._models[0] is engine._variant_models[1]
    assert engine._models[1] is engine._variant_models[0]
    assert engine._models[2] is engine._variant_models[2]
    assert engine.variant_idx.tolist() == [1, 0, 2]


def test_dynamics_variants_are_what_each_env_simulates():
    """Same pose and controls; the env with 3 kg more on the trunk sags lower."""
    rows = np.array([[1.0, 0.0, 1.0], [1.0, 3.0, 1.0], [1.0, 0.0, 0.9]])
    engine = CpuEngine(3, variants=rows)
    engine.set_variants(np.arange(3), np.arange(3))
    ctrl = torch.tensor(GO1.nominal_joint_pos_rad).repeat(3, 4, 1)
    for _ in range(50):
        out = engine.step(ctrl)
    height = out.qpos[:, 2]
    assert height[1] < height[0] - 0.01  # heavier
    assert height[2] < height[0] - 0.003  # weaker motors


def test_scene_foot_friction_reaches_the_simulated_model():
    engine = CpuEngine(1, SceneCfg(foot_friction=0.5))
    m = engine._models[0]
    feet = [m.geom(f"{f}_foot_collision").id for f in GO1.feet]
    np.testing.assert_allclose(m.geom_friction[feet, 0], 0.5)


def test_apply_dynamics_nominal_row_keeps_the_model():
    m = build_model()
    before = (m.geom_friction.copy(), m.body_mass.copy(), m.actuator_gainprm.copy())
    apply_dynamics(m, np.array([1.0, 0.0, 1.0]), "trunk")
    np.testing.assert_array_equal(m.geom_friction, before[0])
    np.testing.assert_array_equal(m.body_mass, before[1])
    np.testing.assert_array_equal(m.actuator_gainprm, before[2])


def test_sampled_variants_lie_in_the_configured_ranges():
    cfg = DanceTaskCfg()
    rows = sample_dynamics(cfg, np.random.default_rng(0))
    assert rows.shape == (cfg.domain_rand.num_variants, 3)
    np.testing.assert_array_equal(rows[0], [1.0, 0.0, 1.0])  # the nominal robot stays in
    for col, (lo, hi) in enumerate(
        [cfg.domain_rand.friction, cfg.domain_rand.added_mass_kg, cfg.domain_rand.motor_strength]
    ):
        assert np.all((rows[1:, col] >= lo) & (rows[1:, col] <= hi))
        assert np.ptp(rows[1:, col]) > 0.3 * (hi - lo)  # actually spread over the range
    cfg.domain_rand.enabled = False
    np.testing.assert_array_equal(sample_dynamics(cfg, np.random.default_rng(0)), [[1, 0, 1]])


def test_randomised_reset_is_consistent_with_the_engine():
    cfg = DanceTaskCfg(num_envs=8)
    env = DanceEnv(cfg, flat_bank(), seed=4)
    variants = torch.as_tensor(env.engine.variants, dtype=torch.float32)
    idx = torch.as_tensor(env.engine.variant_idx)
    # The critic's privileged dynamics are the ones the engine simulates.
    torch.testing.assert_close(env.dynamics, variants[idx])
    assert len(set(idx.tolist())) > 1
    assert env.action_lag.min() >= 0 and env.action_lag.max() <= 6
    assert len(set(env.action_lag.tolist())) > 1
    assert env.joint_offset.abs().max() <= 0.02 and env.joint_offset.abs().max() > 0
    offset = env.robot.joint_pos - env.nominal_joint_pos
    assert offset.abs().max() <= 0.1 + 1e-5 and offset.abs().max() > 0.02


def test_action_lag_picks_the_target_issued_lag_substeps_ago():
    env = DanceEnv(task_cfg(4), flat_bank())
    assert env.cfg.decimation == 4
    # Joint targets of this step (k=0), the last (k=1) and the one before (k=2): all joints = k.
    env._target_hist = torch.arange(3.0).view(1, 3, 1).expand(4, 3, 12).clone()
    env.set_action_lag(torch.tensor([0, 6, 4, 2]))
    ctrl = env._lagged_controls()
    assert ctrl.shape == (4, 4, 12)
    # Substep j of this step uses the newest target issued at least `lag` substeps before it.
    expected = [[0, 0, 0, 0], [2, 2, 1, 1], [1, 1, 1, 1], [1, 1, 0, 0]]
    assert ctrl[:, :, 0].tolist() == expected
    assert torch.all(ctrl == ctrl[:, :, :1])


# --- the two engines ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def warp_engine_cls():
    pytest.importorskip("mujoco_warp")
    from quaddance.sim.warp_engine import WarpEngine

    return WarpEngine


@pytest.mark.slow
def test_warp_engine_memory_grows_linearly_with_the_envs(warp_engine_cls):
    """mujoco_warp sizes contacts and constraint rows per world: a per-world count that
    grew with the env count made 4096 envs ask for 4096 x 4096 x 16 contacts."""
    from quaddance.sim.warp_engine import CONTACTS_PER_WORLD, ROWS_PER_WORLD

    small, large = (warp_engine_cls(n, device="cpu") for n in (2, 8))
    assert small.d.naconmax == 2 * CONTACTS_PER_WORLD
    assert large.d.naconmax == 8 * CONTACTS_PER_WORLD
    assert small.d.njmax == large.d.njmax == ROWS_PER_WORLD


@pytest.mark.slow
def test_warp_and_mujoco_engines_agree(warp_engine_cls):
    """Warp on the CPU (first run compiles its kernels, 1-2 min) vs mujoco.rollout, with
    added-mass and motor-strength variants."""
    rows = np.array([[1.0, 0.0, 1.0], [1.0, 2.0, 1.1], [1.0, -1.0, 0.9]])
    gap_qpos, gap_sensors = engine_gaps(rows, [0, 1, 2, 1])
    assert gap_qpos < 1e-4
    assert gap_sensors < 1e-3  # includes joint torques, N m


@pytest.mark.slow
def test_warp_and_mujoco_engines_agree_with_friction_variants(warp_engine_cls):
    rows = np.array([[1.0, 0.0, 1.0], [0.4, 0.0, 1.0]])
    gap_qpos, _ = engine_gaps(rows, [1, 1, 1, 1], steps=10)
    assert gap_qpos < 1e-4


@pytest.mark.slow
def test_dance_env_observations_agree_on_both_engines(warp_engine_cls):
    bank = np.zeros((1, 300, 4), np.float32)
    bank[0, 20:60, FL] = 0.1
    envs = [DanceEnv(task_cfg(2), bank, engine=name, seed=5) for name in ("cpu", "gpu")]
    assert type(envs[1].engine).__name__ == "WarpEngine"

    def observe(env):
        obs = env.get_observations()
        return obs["actor"].cpu(), obs["critic"].cpu()

    for a, b in zip(observe(envs[0]), observe(envs[1]), strict=True):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=0)
    gen = torch.Generator().manual_seed(6)
    for _ in range(15):
        action = (torch.rand(2, 12, generator=gen) * 2 - 1) * 0.5
        rewards_ = [env.step(action)[1] for env in envs]
    for a, b in zip(observe(envs[0]), observe(envs[1]), strict=True):
        torch.testing.assert_close(a, b, atol=1e-3, rtol=0)
    torch.testing.assert_close(rewards_[0], rewards_[1].cpu(), atol=1e-3, rtol=1e-3)


@pytest.mark.parametrize(
    "engine",
    [
        "cpu",
        pytest.param("gpu", marks=[pytest.mark.slow]),
    ],
)
def test_engine_output_is_a_snapshot(engine, request):
    """A state read from an engine does not change when the engine steps on."""
    if engine == "cpu":
        eng = CpuEngine(2)
    else:
        eng = request.getfixturevalue("warp_engine_cls")(2, device="cpu")
    ctrl = random_controls(2, 2, seed=1)
    first = eng.step(ctrl[0])
    kept = [first.qpos.clone(), first.qvel.clone(), first.sensordata.clone()]
    eng.step(ctrl[1])
    for now, then in zip([first.qpos, first.qvel, first.sensordata], kept, strict=True):
        assert torch.equal(now, then)


@pytest.mark.slow
def test_dance_env_reward_terms_agree_on_both_engines(warp_engine_cls):
    envs = [DanceEnv(task_cfg(2), flat_bank(), engine=name, seed=5) for name in ("cpu", "gpu")]
    gen = torch.Generator().manual_seed(6)
    for _ in range(5):
        action = (torch.rand(2, 12, generator=gen) * 2 - 1) * 0.5
        logs = [env.step(action)[3]["log"] for env in envs]
        for key, value in logs[0].items():
            other = logs[1][key].cpu()
            assert other.item() == pytest.approx(value.item(), rel=1e-2, abs=1e-6), key


# --- front-lift feed-forward -----------------------------------------------------------------


def test_lift_table_raises_the_front_foot_by_the_requested_height(model):
    from quaddance.sim.feedforward import lift_table

    table = lift_table(GO1)
    data = mujoco.MjData(model)
    site = model.site("FL").id
    ti = model.joint("FL_thigh_joint").qposadr[0]
    ci = model.joint("FL_calf_joint").qposadr[0]
    data.qpos[:] = model.key("home").qpos
    mujoco.mj_kinematics(model, data)
    z0 = data.site_xpos[site][2]
    for h, (d_thigh, d_calf) in zip(GO1.front_lift.heights_m, table, strict=True):
        if h > 0.3:
            break
        data.qpos[:] = model.key("home").qpos
        data.qpos[ti] += d_thigh
        data.qpos[ci] += d_calf
        mujoco.mj_kinematics(model, data)
        # Exact to 1 cm up to 0.2 m; above, the calf nears its joint limit (2 cm).
        assert data.site_xpos[site][2] - z0 == pytest.approx(h, abs=0.01 if h <= 0.2 else 0.02)
    np.testing.assert_allclose(table[0], 0.0, atol=1e-9)


def test_feedforward_moves_only_the_lifted_front_leg():
    cfg = task_cfg(2)
    bank = np.zeros((1, 200, 4), np.float32)
    bank[0, :, 0] = 0.2  # FL up all the time, FR down
    env = DanceEnv(cfg, bank, seed=0, random_start=False)
    env.bank_idx[:] = 0
    offset = env.joint_targets(torch.zeros(2, 12)) - env.nominal_joint_pos
    fl = 3 * GO1.legs.index("FL")
    moved = offset.abs().sum(0) > 1e-6
    assert moved[fl + 1] and moved[fl + 2]  # FL thigh and calf
    assert int(moved.sum()) == 2
    cfg_off = task_cfg(2, front_feedforward=False)
    env_off = DanceEnv(cfg_off, bank, seed=0, random_start=False)
    torch.testing.assert_close(
        env_off.joint_targets(torch.zeros(2, 12)), env_off.nominal_joint_pos.expand(2, -1)
    )
