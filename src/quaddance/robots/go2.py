"""The Unitree Go2: names, nominal pose, gains, limits, reach and SDK map, in one place.

The model is Unitree's own MuJoCo Go2 (github.com/unitreerobotics/unitree_mujoco,
`unitree_robots/go2`, BSD-3-Clause, the same model as MuJoCo Menagerie's `unitree_go2`),
vendored under `quaddance/data/robots/unitree_go2` by `scripts/vendor_go2.py` with its legs
in the Go1's order. The nominal pose and the PD gains are Unitree's for this robot
(unitree_rl_gym `legged_gym/envs/go2/go2_config.py`), which are the Go1's numbers too.
"""

from __future__ import annotations

from quaddance.robots.config import (
    BodyLimits,
    FrontLiftCfg,
    RobotCfg,
    SafetyLimits,
    legged_gym_stand_rad,
    per_joint,
)

# Legs in the model's order (the vendored MJCF lists FR, FL, RR, RL); hip, thigh, calf each.
_LEGS = ("FR", "FL", "RR", "RL")
_FEET = ("FL", "FR", "RL", "RR")

# The model's motor ctrlrange (unitree_mujoco go2.xml): 23.7 N m at hip and thigh, 45.43 N m
# at the knee; its joints' armature 0.01 kg m^2.
_HIP_EFFORT_NM = 23.7
_KNEE_EFFORT_NM = 45.43
_ARMATURE = 0.01

GO2 = RobotCfg(
    name="unitree_go2",
    model_xml="data/robots/unitree_go2/go2.xml",
    model_package="quaddance",
    legs=_LEGS,
    joint_names=tuple(f"{leg}_{part}_joint" for leg in _LEGS for part in ("hip", "thigh", "calf")),
    feet=_FEET,
    foot_sites=_FEET,  # vendored: a site at each foot sphere's centre, named after its leg
    foot_geoms=tuple(f"{foot}_foot_collision" for foot in _FEET),
    foot_radius_m=0.022,  # the foot sphere's radius in go2.xml
    trunk_body="base",
    thigh_bodies=tuple(f"{leg}_thigh" for leg in _LEGS),
    knee_geoms=tuple(f"{leg}_calf_collision1" for leg in _LEGS),
    nominal_joint_pos_rad=legged_gym_stand_rad(_LEGS),  # unitree_rl_gym go2_config's stand
    init_base_height_m=0.325,  # spawn with the feet just above the floor (legs as the Go1's)
    standing_height_m=0.25,  # where the trunk settles on the nominal pose (15.2 kg on kp 20)
    kp=20.0,  # unitree_rl_gym go2_config: stiffness 20 N m/rad
    kd=0.5,  # damping 0.5 N m s/rad
    effort_limit_nm=per_joint(_LEGS, _HIP_EFFORT_NM, _HIP_EFFORT_NM, _KNEE_EFFORT_NM),
    armature=per_joint(_LEGS, _ARMATURE, _ARMATURE, _ARMATURE),
    min_base_height_m=0.12,
    max_tilt_rad=1.0,
    # Highest front-foot target while standing on three legs: 80 % of the 0.515 m that the
    # Go2 held in our simulator (`quaddance bench reach --robot go2`, quasi-static, trunk at
    # 0.32 m; benchmarks/results/go2/reach.json), where its front thigh's range (to -90 deg,
    # the Go1's to -39 deg) is the limit. A policy declares the range it was trained on in
    # its JSON, and `quaddance dance` uses that instead.
    max_paw_height_m=0.41,
    # The Go1's trunk ranges, which the shipped Go2 policy was trained on, lie inside what it
    # holds (`quaddance bench body-reach --policy go2_dance.onnx`,
    # benchmarks/results/go2/body_reach.json): four feet down, height -10..+9 cm, roll
    # -0.35..+0.5, pitch -0.4..+0.5, yaw +-0.5 rad; front-left paw 15 cm up, height
    # -10..+9 cm, roll +-0.5, pitch -0.5..+0.4, yaw -0.2..+0.35 rad.
    body_four_feet=BodyLimits(
        height_offset_m=(-0.06, 0.03), roll_rad=0.25, pitch_rad=0.20, yaw_rad=0.25
    ),
    body_paw_up=BodyLimits(
        height_offset_m=(-0.04, 0.02), roll_rad=0.12, pitch_rad=0.12, yaw_rad=0.15
    ),
    front_lift=FrontLiftCfg(
        max_height_m=0.45,
        rows=46,
        forward_per_up=0.25,
        thigh_window_rad=(-1.4, 0.6),
        calf_window_rad=(-1.2, 0.6),
        thigh_points=101,
        calf_points=91,
    ),
    safety_limits=SafetyLimits(
        max_roll_pitch_rad=0.8,
        min_trunk_height_m=0.15,
        max_target_step_rad=0.35,
        soft_limit_margin_rad=0.03,
        damp_kd=1.0,
    ),
    # unitree_sdk2 (go2): motors FR_0..2, FL_0..2, RR_0..2, RL_0..2 (hip, thigh, calf), the
    # model's order, with the same URDF angle conventions; foot forces in leg order.
    sdk_joint_index=tuple(range(3 * len(_LEGS))),
    sdk_joint_sign=(1.0,) * (3 * len(_LEGS)),
    sdk_foot_index=tuple(_LEGS.index(foot) for foot in _FEET),
    policy="go2_dance.onnx",
)
