"""A second robot joins through its `RobotCfg` alone: the Go1 with 3 cm longer calves.

The model is the Go1's MJCF edited with MjSpec (the foot site and the foot sphere moved down
the calf); everything else (kinematics, leg IK, the front-lift table, the scene and the task)
must follow from the config without another change.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from quaddance.errors import QuaddanceError
from quaddance.robots import GO1, ROBOTS, RobotCfg, get_robot
from quaddance.sim import tasks
from quaddance.sim.body import BodyFeedforward, leg_ik, rpy_matrix
from quaddance.sim.feedforward import lift_table
from quaddance.sim.kinematics import foot_pos_b, leg_geometry
from quaddance.sim.scene import SceneCfg, build_model
from quaddance.sim.task import DanceEnv

LONGER_M = 0.03


@pytest.fixture(scope="module")
def long_calves(tmp_path_factory) -> RobotCfg:
    """The Go1 with calves `LONGER_M` longer, as a MJCF file and a `RobotCfg`."""
    source = Path(GO1.model_file())
    spec = mujoco.MjSpec.from_file(str(source))
    spec.meshdir = str(source.parent / spec.meshdir)  # the meshes stay where they are
    for leg, site, geom in zip(GO1.feet, GO1.foot_sites, GO1.foot_geoms, strict=True):
        spec.site(site).pos[2] -= LONGER_M
        spec.geom(geom).pos[2] -= LONGER_M
        assert spec.geom(geom).parent.name == f"{leg}_calf"
    spec.compile()
    path = tmp_path_factory.mktemp("robot") / "go1_long_calves.xml"
    path.write_text(spec.to_xml())
    return dataclasses.replace(
        GO1,
        name="go1_long_calves",
        model_xml=str(path),
        model_package=None,
        init_base_height_m=GO1.init_base_height_m + LONGER_M,
    )


def _nominal(robot: RobotCfg, n: int = 1) -> torch.Tensor:
    return torch.tensor(robot.nominal_joint_pos_rad, dtype=torch.float64)[None].repeat(n, 1)


def test_leg_geometry_and_forward_kinematics_follow_the_model(long_calves):
    go1, long = leg_geometry(GO1), leg_geometry(long_calves)
    np.testing.assert_allclose(long.foot_offset[:, 2], go1.foot_offset[:, 2] - LONGER_M)
    for name in ("hip_pos_b", "thigh_offset", "calf_offset", "joint_cols"):
        np.testing.assert_array_equal(getattr(long, name), getattr(go1, name))
    # At the nominal pose every foot is lower in the trunk frame, by less than the extension
    # (the calves are not vertical), and where MuJoCo puts the new model's foot sites.
    feet_go1 = foot_pos_b(_nominal(GO1), go1)[0].numpy()
    feet_long = foot_pos_b(_nominal(long_calves), long)[0].numpy()
    drop = feet_go1[:, 2] - feet_long[:, 2]
    assert np.all(drop > 0.5 * LONGER_M) and np.all(drop < LONGER_M)
    model = build_model(SceneCfg(robot=long_calves))
    data = mujoco.MjData(model)
    data.qpos[:] = model.key("home").qpos
    mujoco.mj_kinematics(model, data)
    trunk = model.body(long_calves.trunk_body).id
    rot = data.xmat[trunk].reshape(3, 3)
    sites = [model.site(s).id for s in long_calves.foot_sites]
    truth = (data.site_xpos[sites] - data.xpos[trunk]) @ rot
    np.testing.assert_allclose(feet_long, truth, atol=1e-9)
    assert model.key("home").qpos[2] == pytest.approx(GO1.init_base_height_m + LONGER_M)


def test_leg_ik_round_trips_on_the_new_geometry(long_calves):
    geom = leg_geometry(long_calves)
    gen = torch.Generator().manual_seed(0)
    q = _nominal(long_calves, 300) + 0.3 * (torch.rand(300, 12, generator=gen) * 2 - 1)
    feet = foot_pos_b(q, geom)
    torch.testing.assert_close(leg_ik(feet, geom), q, atol=1e-6, rtol=0.0)
    # The Go1's geometry does not reach the same feet with the same angles.
    assert (leg_ik(feet, leg_geometry(GO1)) - q).abs().max() > 0.05


def test_body_feedforward_holds_the_longer_legs_feet(long_calves):
    ff = BodyFeedforward(long_calves)
    geom = leg_geometry(long_calves)
    body = torch.tensor([[0.0, 0.0, 0.0, 0.0], [-0.05, 0.1, -0.1, 0.15]])
    offsets = ff(body)
    assert offsets[0].abs().max() < 1e-6
    q = torch.tensor(long_calves.nominal_joint_pos_rad)[None] + offsets
    feet_w = torch.einsum("nij,nkj->nki", rpy_matrix(body[:, 1:]), foot_pos_b(q, geom))
    feet_w[..., 2] += body[:, :1]
    torch.testing.assert_close(feet_w, ff.feet0_b.expand_as(feet_w), atol=1e-5, rtol=0.0)
    # A crouch of the same depth bends the longer legs' knees less.
    go1_offsets = BodyFeedforward(GO1)(body)
    assert offsets[1, 2].abs() < go1_offsets[1, 2].abs()


def test_front_lift_table_follows_the_longer_calves(long_calves):
    go1, long = lift_table(GO1), lift_table(long_calves)
    assert long.shape == go1.shape == (long_calves.front_lift.rows, 2)
    np.testing.assert_allclose(long[0], 0.0, atol=1e-9)
    # A longer lever lifts the foot by the same height with less calf flexion.
    heights = long_calves.front_lift.heights_m
    mid = (heights >= 0.1) & (heights <= 0.25)
    assert np.all(np.abs(long[mid, 1]) <= np.abs(go1[mid, 1]))
    assert np.abs(long[mid, 1]).mean() < np.abs(go1[mid, 1]).mean() - 0.02
    # And the table lifts the new model's front foot by the height asked for.
    model = build_model(SceneCfg(robot=long_calves))
    data = mujoco.MjData(model)
    site = model.site(long_calves.foot_sites[0]).id
    _, thigh, calf = long_calves.leg_joint_cols(long_calves.feet[0])
    ti = model.joint(long_calves.joint_names[thigh]).qposadr[0]
    ci = model.joint(long_calves.joint_names[calf]).qposadr[0]
    data.qpos[:] = model.key("home").qpos
    mujoco.mj_kinematics(model, data)
    z0 = data.site_xpos[site][2]
    for h, (d_thigh, d_calf) in zip(heights[heights <= 0.2], long, strict=False):
        data.qpos[:] = model.key("home").qpos
        data.qpos[ti] += d_thigh
        data.qpos[ci] += d_calf
        mujoco.mj_kinematics(model, data)
        assert data.site_xpos[site][2] - z0 == pytest.approx(h, abs=0.01)


def test_the_task_runs_the_second_robot(long_calves):
    cfg = tasks.paws_only(num_envs=2, robot=long_calves)
    cfg.domain_rand.enabled = False
    assert cfg.scene.kp == long_calves.kp
    assert cfg.base_height_target_m == long_calves.standing_height_m
    bank = np.zeros((1, 100, 4), np.float32)
    bank[0, :, 0] = 0.1
    env = DanceEnv(cfg, bank, seed=0, random_start=False)
    torch.testing.assert_close(
        env.feedforward.table, torch.as_tensor(lift_table(long_calves), dtype=torch.float32)
    )
    for _ in range(5):
        env.step(torch.zeros(2, long_calves.num_joints))
    # Foot heights measured on the new model: the rear feet stand on the floor, the front-left
    # one rises towards its target through the new table.
    feet = env.robot.foot_height_m
    assert feet[:, 2:].abs().max() < 0.01 and feet[:, 0].min() > 0.05


def test_robots_by_name():
    assert get_robot(GO1.name) is GO1 and ROBOTS[GO1.name] is GO1
    with pytest.raises(QuaddanceError, match="unknown robot 'go7'; known: go1, go2"):
        get_robot("go7")
