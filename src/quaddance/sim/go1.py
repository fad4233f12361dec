"""Unitree Go1 constants: names, nominal pose, gains and limits, in one place.

Numbers follow the paper's released code (FACTS.md section 2) unless noted; mjlab's Go1 model
(`mjlab/asset_zoo/robots/unitree_go1`) supplies geometry, masses and joint ranges.
"""

from __future__ import annotations

# Legs in the model's order (the MJCF lists FR, FL, RR, RL); each leg has hip, thigh, calf.
MODEL_LEGS: tuple[str, ...] = ("FR", "FL", "RR", "RL")
JOINT_NAMES: tuple[str, ...] = tuple(
    f"{leg}_{part}_joint" for leg in MODEL_LEGS for part in ("hip", "thigh", "calf")
)
NUM_JOINTS = len(JOINT_NAMES)

# The task's foot order everywhere in quaddance (targets, observations, metrics).
FEET: tuple[str, ...] = ("FL", "FR", "RL", "RR")
FOOT_RADIUS_M = 0.023  # sphere radius of `*_foot_collision` in go1.xml

# Nominal joint positions (released code): hips +-0.1 (left legs out), thighs 0.8 front /
# 1.0 rear, calves -1.5 rad.
_NOMINAL = {"hip": 0.1, "thigh_front": 0.8, "thigh_rear": 1.0, "calf": -1.5}


def nominal_joint_pos() -> list[float]:
    """Nominal joint positions in model order (rad)."""
    out: list[float] = []
    for leg in MODEL_LEGS:
        hip = _NOMINAL["hip"] if leg.endswith("L") else -_NOMINAL["hip"]
        thigh = _NOMINAL["thigh_front"] if leg.startswith("F") else _NOMINAL["thigh_rear"]
        out += [hip, thigh, _NOMINAL["calf"]]
    return out


# Effort limits and reflected rotor inertia (armature) as in mjlab's go1_constants.
ROTOR_INERTIA = 0.000111842
HIP_GEAR_RATIO = 6.0
KNEE_GEAR_RATIO = HIP_GEAR_RATIO * 1.5
HIP_EFFORT_NM = 23.7
KNEE_EFFORT_NM = 35.55
HIP_ARMATURE = ROTOR_INERTIA * HIP_GEAR_RATIO**2
KNEE_ARMATURE = ROTOR_INERTIA * KNEE_GEAR_RATIO**2


def effort_limit_nm(joint_name: str) -> float:
    """Motor torque limit of one joint, N m (knees geared 1.5x the hips)."""
    return KNEE_EFFORT_NM if joint_name.endswith("calf_joint") else HIP_EFFORT_NM


INIT_BASE_HEIGHT_M = 0.325  # spawn height with the feet on the floor; settles to 0.27 m
