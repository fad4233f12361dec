"""The Unitree Go1: names, nominal pose, gains, limits, reach and SDK map, in one place.

Numbers follow the paper's released code (FACTS.md section 2) unless noted; mjlab's Go1 model
(`mjlab/asset_zoo/robots/unitree_go1`) supplies geometry, masses and joint ranges, and its
`go1_constants.py` the effort limits and rotor inertia.
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

# Legs in the model's order (the MJCF lists FR, FL, RR, RL); each leg has hip, thigh, calf.
_LEGS = ("FR", "FL", "RR", "RL")
# The task's foot order everywhere in quaddance (targets, observations, metrics).
_FEET = ("FL", "FR", "RL", "RR")

# Effort limits and reflected rotor inertia (armature) as in mjlab's go1_constants: the knees
# are geared 1.5x the hips.
_ROTOR_INERTIA = 0.000111842
_HIP_GEAR_RATIO = 6.0
_KNEE_GEAR_RATIO = _HIP_GEAR_RATIO * 1.5
_HIP_EFFORT_NM = 23.7
_KNEE_EFFORT_NM = 35.55
_HIP_ARMATURE = _ROTOR_INERTIA * _HIP_GEAR_RATIO**2
_KNEE_ARMATURE = _ROTOR_INERTIA * _KNEE_GEAR_RATIO**2

GO1 = RobotCfg(
    name="unitree_go1",
    model_xml="asset_zoo/robots/unitree_go1/xmls/go1.xml",
    model_package="mjlab",
    legs=_LEGS,
    joint_names=tuple(f"{leg}_{part}_joint" for leg in _LEGS for part in ("hip", "thigh", "calf")),
    feet=_FEET,
    foot_sites=_FEET,  # go1.xml's site at each foot sphere's centre is named after its leg
    foot_geoms=tuple(f"{foot}_foot_collision" for foot in _FEET),
    foot_radius_m=0.023,  # sphere radius of `*_foot_collision` in go1.xml
    trunk_body="trunk",
    thigh_bodies=tuple(f"{leg}_thigh" for leg in _LEGS),
    knee_geoms=tuple(f"{leg}_calf_collision1" for leg in _LEGS),
    nominal_joint_pos_rad=legged_gym_stand_rad(_LEGS),  # the released code's stand
    init_base_height_m=0.325,  # spawn height with the feet on the floor; settles to 0.27 m
    standing_height_m=0.27,  # the trunk on the nominal pose (target of the base-height reward)
    kp=20.0,  # released code (the paper's text says kp 20)
    kd=0.5,  # released code (the paper's text says 5)
    effort_limit_nm=per_joint(_LEGS, _HIP_EFFORT_NM, _HIP_EFFORT_NM, _KNEE_EFFORT_NM),
    armature=per_joint(_LEGS, _HIP_ARMATURE, _HIP_ARMATURE, _KNEE_ARMATURE),
    min_base_height_m=0.12,
    max_tilt_rad=1.0,
    # Highest front-foot target while standing on three legs: 80 % of the 0.38 m that the
    # Go1 held in our simulator (`quaddance bench reach`, quasi-static, trunk at 0.32 m);
    # the margin is for balancing dynamically on the beat. A policy declares the range it
    # was trained on in its JSON, and `quaddance dance` uses that instead.
    max_paw_height_m=0.30,
    # Inside the trunk range the shipped policy holds (`quaddance bench body-reach --policy
    # P`, benchmarks/results/body_reach.json): four feet down, height -10..+8 cm, roll
    # +-0.5, pitch -0.15..+0.35, yaw +-0.35 rad; front-left paw 15 cm up, height -6..+9 cm,
    # roll +-0.5, pitch -0.35..+0.4, yaw +-0.5 rad. One bound goes past it: four feet down,
    # a nose-up pitch of -0.20 rad is reached but a foot slides 13 cm (-0.15 rad held).
    body_four_feet=BodyLimits(
        height_offset_m=(-0.06, 0.03), roll_rad=0.25, pitch_rad=0.20, yaw_rad=0.25
    ),
    # While a front paw target is above `TargetConfig.min_lift_m` three legs carry the
    # robot, so it leans and twists less.
    body_paw_up=BodyLimits(
        height_offset_m=(-0.04, 0.02), roll_rad=0.12, pitch_rad=0.12, yaw_rad=0.15
    ),
    front_lift=FrontLiftCfg(
        max_height_m=0.45,
        rows=46,  # a row every 1 cm
        forward_per_up=0.25,  # the foot moves forward 2.5 cm per 10 cm up: clears the elbow
        thigh_window_rad=(-1.4, 0.6),
        calf_window_rad=(-1.2, 0.6),
        thigh_points=101,  # 0.02 rad apart
        calf_points=91,  # 0.02 rad apart
    ),
    safety_limits=SafetyLimits(
        max_roll_pitch_rad=0.8,  # WTW crouches at 1.6; we stop earlier
        min_trunk_height_m=0.15,  # nominal 0.27
        max_target_step_rad=0.35,
        soft_limit_margin_rad=0.03,
        damp_kd=1.0,
    ),
    # unitree_legged_sdk 3.8: its motors are FR_0, FR_1, FR_2, FL_0, ... RL_2 (hip, thigh,
    # calf per leg, legs FR, FL, RR, RL; the SDK's quadruped.h), which is the model's order,
    # and the angles follow the same URDF conventions (mjlab's go1.xml comes from Unitree's
    # model): the nominal stand in Unitree's examples (0, 0.85, -1.75 per front leg) reads as
    # ours does. So the map is the identity with signs +1. Its foot forces come in leg order
    # FR, FL, RR, RL.
    sdk_joint_index=tuple(range(3 * len(_LEGS))),
    sdk_joint_sign=(1.0,) * (3 * len(_LEGS)),
    sdk_foot_index=tuple(_LEGS.index(foot) for foot in _FEET),
    policy="go1_dance.onnx",
)
