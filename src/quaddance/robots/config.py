"""The robot config's dataclasses (`RobotCfg` and its parts); the robots are its siblings."""

from __future__ import annotations

import importlib.util
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quaddance.errors import QuaddanceError


def per_joint(legs: tuple[str, ...], hip: float, thigh: float, calf: float) -> tuple[float, ...]:
    """One value per joint in model order: hip, thigh, calf of each of ``legs``."""
    return (hip, thigh, calf) * len(legs)


def legged_gym_stand_rad(legs: tuple[str, ...]) -> tuple[float, ...]:
    """The nominal stand of legged_gym's Unitree quadrupeds (Go1 and Go2 alike): hips +-0.1
    (left legs out), thighs 0.8 front / 1.0 rear, calves -1.5 rad; model order."""
    out: list[float] = []
    for leg in legs:
        out += [0.1 if leg.endswith("L") else -0.1, 0.8 if leg.startswith("F") else 1.0, -1.5]
    return tuple(out)


@dataclass(frozen=True)
class BodyLimits:
    """The trunk pose range a robot holds while dancing, relative to standing.

    ``height_offset_m`` is (lowest, highest), m; the angles are symmetric maxima, rad.
    ``max_speed`` and ``max_accel`` are per column of `quaddance.layout.BODY_COLUMNS`
    (m/s or rad/s, and m/s^2 or rad/s^2).
    """

    height_offset_m: tuple[float, float]
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    max_speed: tuple[float, float, float, float] = (0.25, 1.5, 1.5, 1.5)
    max_accel: tuple[float, float, float, float] = (3.0, 20.0, 20.0, 20.0)

    def __post_init__(self) -> None:
        lo, hi = self.height_offset_m
        values = [lo, hi, self.roll_rad, self.pitch_rad, self.yaw_rad]
        values += list(self.max_speed) + list(self.max_accel)
        if not all(np.isfinite(v) for v in values) or len(self.max_speed) != 4:
            raise QuaddanceError("BodyLimits: every value must be finite, four speeds/accels")
        if not lo <= 0.0 <= hi:
            raise QuaddanceError(f"BodyLimits.height_offset_m must hold 0, got {(lo, hi)}")
        if min(values[2:]) < 0 or min(list(self.max_speed) + list(self.max_accel)) <= 0:
            raise QuaddanceError("BodyLimits: angles must be >= 0, speeds and accels > 0")

    @property
    def low(self) -> np.ndarray:
        """(4,) lowest value per column."""
        return np.array([self.height_offset_m[0], -self.roll_rad, -self.pitch_rad, -self.yaw_rad])

    @property
    def high(self) -> np.ndarray:
        """(4,) highest value per column."""
        return np.array([self.height_offset_m[1], self.roll_rad, self.pitch_rad, self.yaw_rad])


@dataclass(frozen=True)
class FrontLiftCfg:
    """Settings of the front-lift feed-forward table (`quaddance.sim.feedforward`): the joint
    offsets that raise a front foot by each height, found by a grid search over the thigh and
    the calf around the nominal pose."""

    max_height_m: float  #: the table's last height, m
    rows: int  #: heights evenly spaced from 0 to `max_height_m`
    forward_per_up: float  #: the foot moves forward this much per unit up
    #: Grid searched, rad from the nominal angle (clipped to the joint range), and its points.
    thigh_window_rad: tuple[float, float]
    calf_window_rad: tuple[float, float]
    thigh_points: int
    calf_points: int

    @property
    def heights_m(self) -> np.ndarray:
        """(rows,) the table's heights, m (rounded so that they print as written)."""
        return np.round(np.linspace(0.0, self.max_height_m, self.rows), 4)


@dataclass(frozen=True)
class SafetyLimits:
    """Limits of the robot runner's safety layer (`quaddance.deploy.safety`) that depend on
    the robot; the layer's timings are in `SafetyCfg`."""

    max_roll_pitch_rad: float  #: beyond: damp
    min_trunk_height_m: float  #: trunk above the lowest foot; lower: collapse, damp
    max_target_step_rad: float  #: largest change of a joint target per policy tick
    soft_limit_margin_rad: float  #: targets stay this far inside the joint range
    damp_kd: float  #: N m s / rad, joint damping of the damping mode


@dataclass(frozen=True)
class RobotCfg:
    """Everything quaddance knows about one robot. Joints are in the model's order (`legs`,
    each leg's joints hip, thigh, calf); feet are in the task's order (`feet`), which every
    target, observation and metric uses. Angles in rad, lengths in m."""

    name: str  #: as the policy JSON's ``robot`` names it
    #: The MJCF: a path inside `model_package` (found without importing it), or a file path
    #: when `model_package` is None.
    model_xml: str
    model_package: str | None
    legs: tuple[str, ...]  #: leg names in the model's order
    joint_names: tuple[str, ...]  #: hip, thigh, calf of each leg of `legs`
    #: Leg names in the task's foot order: front-left and front-right first (the paws that
    #: dance and the front-lift feed-forward moves), then the rear feet.
    feet: tuple[str, ...]
    foot_sites: tuple[str, ...]  #: per foot of `feet`: the site at the foot sphere's centre
    foot_geoms: tuple[str, ...]  #: per foot of `feet`: its collision sphere
    foot_radius_m: float
    trunk_body: str  #: the body carrying the free joint and the IMU
    thigh_bodies: tuple[str, ...]  #: per leg of `legs` (floor contacts: collision penalty)
    knee_geoms: tuple[str, ...]  #: per leg of `legs`: the calf capsule near the knee
    nominal_joint_pos_rad: tuple[float, ...]
    init_base_height_m: float  #: spawn height with the feet on the floor
    standing_height_m: float  #: where the trunk settles on the nominal pose
    kp: float  #: PD gains of every joint, N m / rad and N m s / rad
    kd: float
    effort_limit_nm: tuple[float, ...]  #: per joint
    armature: tuple[float, ...]  #: per joint: reflected rotor inertia, kg m^2
    #: Terminations of the task: trunk lower than this over the floor, m, or tilted more.
    min_base_height_m: float
    max_tilt_rad: float
    #: Reach that feasible targets keep to: the highest front paw target, m, and the trunk
    #: ranges with four feet down and with a front paw up.
    max_paw_height_m: float
    body_four_feet: BodyLimits
    body_paw_up: BodyLimits
    front_lift: FrontLiftCfg
    safety_limits: SafetyLimits
    #: The low-level SDK's motor index of each model joint, and the sign turning an SDK
    #: angle into ours; the SDK's foot index of each foot of `feet`.
    sdk_joint_index: tuple[int, ...]
    sdk_joint_sign: tuple[float, ...]
    sdk_foot_index: tuple[int, ...]
    policy: str  #: the shipped policy's ONNX file under quaddance/data/policies/

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        per_joint = {
            "nominal_joint_pos_rad": self.nominal_joint_pos_rad,
            "effort_limit_nm": self.effort_limit_nm,
            "armature": self.armature,
            "sdk_joint_index": self.sdk_joint_index,
            "sdk_joint_sign": self.sdk_joint_sign,
        }
        for field_name, values in per_joint.items():
            if len(values) != n:
                raise QuaddanceError(f"RobotCfg {self.name}: {field_name} needs {n} values")
        if n != 3 * len(self.legs) or sorted(self.feet) != sorted(self.legs):
            raise QuaddanceError(f"RobotCfg {self.name}: three joints per leg, one foot per leg")
        if sorted(self.sdk_joint_index) != list(range(n)) or sorted(self.sdk_foot_index) != list(
            range(len(self.feet))
        ):
            raise QuaddanceError(f"RobotCfg {self.name}: the SDK indices must be permutations")

    @property
    def short_name(self) -> str:
        """The name ``--robot`` takes: ``unitree_go2`` -> ``go2``."""
        return self.name.removeprefix("unitree_")

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    def to_sdk(self, values: Sequence[float], signed: bool = True) -> np.ndarray:
        """Model-order joint values in the SDK's motor order, turned into the SDK's angle
        convention where ``signed`` (angles, velocities, torques; not gains)."""
        out = np.empty(self.num_joints)
        out[list(self.sdk_joint_index)] = np.asarray(values) * self._signs(signed)
        return out

    def from_sdk(self, values: Sequence[float], signed: bool = True) -> np.ndarray:
        """The SDK's motor-order values (its first `num_joints` motors) in model order: the
        inverse of `to_sdk`."""
        return np.asarray(values, dtype=np.float64)[list(self.sdk_joint_index)] * self._signs(
            signed
        )

    def feet_to_sdk(self, values: Sequence[float]) -> np.ndarray:
        """Per-foot values in the task's order (`feet`) in the SDK's foot order."""
        out = np.empty(len(self.feet))
        out[list(self.sdk_foot_index)] = values
        return out

    def feet_from_sdk(self, values: Sequence[float]) -> np.ndarray:
        """The SDK's per-foot values in the task's foot order: the inverse of `feet_to_sdk`."""
        return np.asarray(values, dtype=np.float64)[list(self.sdk_foot_index)]

    def _signs(self, signed: bool) -> np.ndarray:
        return np.asarray(self.sdk_joint_sign) if signed else np.ones(self.num_joints)

    def leg_joint_cols(self, foot: str) -> tuple[int, int, int]:
        """Model-order indices of the hip, thigh and calf joints of ``foot``'s leg."""
        first = 3 * self.legs.index(foot)
        return first, first + 1, first + 2

    def model_file(self) -> str:
        """The MJCF's path; `model_package` is located without importing it (mjlab's import
        pulls in warp, which takes seconds)."""
        if self.model_package is None:
            return self.model_xml
        spec = importlib.util.find_spec(self.model_package)
        if spec is None or not spec.submodule_search_locations:
            raise ImportError(
                f"{self.model_package} is not installed; it ships the {self.name} model "
                f"(pip install {self.model_package})"
            )
        return str(Path(next(iter(spec.submodule_search_locations))) / self.model_xml)
