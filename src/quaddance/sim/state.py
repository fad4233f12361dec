"""The robot's state as batched torch tensors: the only thing the task code sees.

Both engines produce a `RobotState` from the same three arrays (qpos, qvel, sensordata), by
the same function, so the task cannot tell which engine ran the physics.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, NamedTuple, TypeVar

import mujoco
import torch

from quaddance.robots import RobotCfg

T = TypeVar("T")


@dataclass(frozen=True)
class SensorLayout:
    """Where each quantity lies in MuJoCo's sensordata vector (addresses by sensor name)."""

    foot_pos: tuple[int, ...]  # 4 x 3, task foot order
    foot_vel: tuple[int, ...]  # 4 x 3
    joint_torque: tuple[int, ...]  # 12, model joint order
    base_contact: int  # trunk touching the floor (number of contacts)
    leg_contact: tuple[int, ...]  # thighs and calves touching the floor (8)
    foot_radius_m: float  # the foot sensors read the sphere's centre; its bottom is this lower

    @classmethod
    def from_model(cls, model: mujoco.MjModel, robot: RobotCfg) -> SensorLayout:
        """The layout of a scene built for ``robot`` (`quaddance.sim.scene.build_spec`)."""

        def adr(name: str, dim: int) -> list[int]:
            start = int(model.sensor(name).adr[0])
            return list(range(start, start + dim))

        legs = [f"{leg}_{p}" for leg in robot.legs for p in ("thigh", "knee")]
        return cls(
            foot_pos=tuple(i for f in robot.feet for i in adr(f"{f}_pos", 3)),
            foot_vel=tuple(i for f in robot.feet for i in adr(f"{f}_vel", 3)),
            joint_torque=tuple(i for j in robot.joint_names for i in adr(f"{j}_torque", 1)),
            base_contact=adr("trunk_contact", 1)[0],
            leg_contact=tuple(adr(f"{b}_contact", 1)[0] for b in legs),
            foot_radius_m=robot.foot_radius_m,
        )


class _once(Generic[T]):  # noqa: N801 - a decorator, as functools.cached_property
    """`functools.cached_property` without its lock (Python 3.11 takes it at every first
    read, a dozen times per policy step): the value computed at the first read is stored on
    the instance, where later reads find it."""

    def __init__(self, fn: Callable[[Any], T]) -> None:
        self.fn, self.name = fn, fn.__name__
        self.__doc__ = fn.__doc__

    def __get__(self, obj: Any, cls: type | None = None) -> T:
        if obj is None:
            return self  # type: ignore[return-value]  # read on the class: the descriptor
        value = obj.__dict__[self.name] = self.fn(obj)
        return value


class _view:  # noqa: N801 - a field of RobotState, as `_once`
    """A quantity that is a range of columns of one of the state's arrays (a view, made at
    its first read)."""

    def __init__(self, array: str, start: int, stop: int | None, doc: str) -> None:
        self.array, self.cols, self.__doc__ = array, slice(start, stop), doc

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: Any, cls: type | None = None) -> torch.Tensor:
        if obj is None:
            return self  # type: ignore[return-value]  # read on the class: the descriptor
        value = obj.__dict__[self.name] = getattr(obj, self.array)[:, self.cols]
        return value


class RobotState:
    """Batched robot state; N environments, world frame `_w`, body frame `_b`.

    Made by `state_from_arrays`. Each quantity is computed from MuJoCo's arrays when it is
    first read: playback reads a few of them per step, training most.
    """

    def __init__(
        self, qpos: torch.Tensor, qvel: torch.Tensor, sensordata: torch.Tensor, layout: SensorLayout
    ) -> None:
        self._qpos, self._qvel, self._sensordata, self._layout = qpos, qvel, sensordata, layout
        self.foot_radius_m = layout.foot_radius_m

    @property
    def qpos(self) -> torch.Tensor:
        """(N, nq) MuJoCo's qpos as read: the pose a video draws."""
        return self._qpos

    def _sensors(self, idx: tuple[int, ...]) -> torch.Tensor:
        return self._sensordata.index_select(1, _index(idx, self._sensordata.device))

    base_pos_w = _view("_qpos", 0, 3, "(N, 3) m.")
    base_quat_w = _view("_qpos", 3, 7, "(N, 4) w, x, y, z.")
    base_lin_vel_w = _view("_qvel", 0, 3, "(N, 3) m/s.")
    base_ang_vel_b = _view("_qvel", 3, 6, "(N, 3) rad/s (MuJoCo: the free joint's, body frame).")
    joint_pos = _view("_qpos", 7, None, "(N, 12) rad, model joint order.")
    joint_vel = _view("_qvel", 6, None, "(N, 12) rad/s.")

    @_once
    def joint_torque(self) -> torch.Tensor:
        """(N, 12) N m."""
        return self._sensors(self._layout.joint_torque)

    @_once
    def foot_pos_w(self) -> torch.Tensor:
        """(N, 4, 3) m, foot sphere centres, task foot order."""
        return self._sensors(self._layout.foot_pos).view(-1, 4, 3)

    @_once
    def foot_vel_w(self) -> torch.Tensor:
        """(N, 4, 3) m/s."""
        return self._sensors(self._layout.foot_vel).view(-1, 4, 3)

    @_once
    def base_contact(self) -> torch.Tensor:
        """(N,) bool: the trunk touches the floor."""
        contacts = self._sensordata[:, self._layout.base_contact]
        return contacts > scalar_tensor(0.5, contacts)

    @_once
    def leg_contacts(self) -> torch.Tensor:
        """(N,) number of thighs/calves touching the floor."""
        return (self._sensors(self._layout.leg_contact) > 0.5).sum(dim=1)

    @_once
    def foot_height_m(self) -> torch.Tensor:
        """(N, 4) height of each foot's bottom above the floor: THE foot height of quaddance."""
        z = self._sensors(self._layout.foot_pos[2::3])
        return z - scalar_tensor(self.foot_radius_m, z)

    @_once
    def _quat_sums(self) -> torch.Tensor:
        """`quat_sums` of the trunk's quaternion: what its gravity and angles are made of."""
        return quat_sums(self.base_quat_w)

    @_once
    def projected_gravity_b(self) -> torch.Tensor:
        """(N, 3) unit gravity direction in the body frame."""
        return gravity_from_sums(self._quat_sums)

    @_once
    def base_rpy_rad(self) -> torch.Tensor:
        """(N, 3) roll, pitch, yaw of the trunk (extrinsic x-y-z, as `sim.body.rpy_matrix`)."""
        return rpy_from_sums(self._quat_sums)

    @property
    def base_yaw_rad(self) -> torch.Tensor:
        """(N,) heading of the trunk about the world vertical, rad."""
        return self.base_rpy_rad[:, 2]

    @_once
    def base_lin_vel_b(self) -> torch.Tensor:
        return quat_rotate_inverse(self.base_quat_w, self.base_lin_vel_w)


_W, _X, _Y, _Z = range(4)
#: `quat_sums`' columns, each a sum of two quaternion products (first, second, sign of the
#: second), doubled: the roll, pitch and yaw numerators, then 2 (x x + y y) twice (roll's
#: denominator; in the pitch column, unused) and 2 (y y + z z) (yaw's denominator).
_QUAT_SUMS = (
    ((_W, _X), (_Y, _Z), 1.0),
    ((_W, _Y), (_Z, _X), -1.0),
    ((_W, _Z), (_X, _Y), 1.0),
    ((_X, _X), (_Y, _Y), 1.0),
    ((_X, _X), (_Y, _Y), 1.0),
    ((_Y, _Y), (_Z, _Z), 1.0),
)
#: Gravity in the body frame from `quat_sums`: R^T (0, 0, -1) = (2 (w y - z x),
#: -2 (w x + y z), 2 (x x + y y) - 1), as (column, sign, offset) each.
_GRAVITY = ((1, 1.0, 0.0), (0, -1.0, 0.0), (3, 1.0, -1.0))


class _QuatConsts(NamedTuple):
    left: torch.Tensor  # the products' left factors: all first products, then all second
    right: torch.Tensor
    sign: torch.Tensor
    is_pitch: torch.Tensor  # (3,) bool: the column read with asin
    gravity_cols: torch.Tensor  # `_GRAVITY`
    gravity_sign: torch.Tensor
    gravity_offset: torch.Tensor


@functools.lru_cache(maxsize=8)
def _quat_consts(device: torch.device, dtype: torch.dtype) -> _QuatConsts:
    products = [row[0] for row in _QUAT_SUMS] + [row[1] for row in _QUAT_SUMS]
    f = lambda values: torch.tensor(values, device=device, dtype=dtype)  # noqa: E731
    with torch.inference_mode(False):  # usable in and out of inference mode
        return _QuatConsts(
            left=torch.tensor([a for a, _ in products], device=device),
            right=torch.tensor([b for _, b in products], device=device),
            sign=f([row[2] for row in _QUAT_SUMS]),
            is_pitch=torch.tensor([False, True, False], device=device),
            gravity_cols=torch.tensor([g[0] for g in _GRAVITY], device=device),
            gravity_sign=f([g[1] for g in _GRAVITY]),
            gravity_offset=f([g[2] for g in _GRAVITY]),
        )


def quat_sums(quat_wxyz: torch.Tensor) -> torch.Tensor:
    """(N, 6) the `_QUAT_SUMS` of unit quaternions (N, 4; w, x, y, z), in one pass: the
    products that both the gravity direction and the roll-pitch-yaw angles are made of."""
    c = _quat_consts(quat_wxyz.device, quat_wxyz.dtype)
    # (N, 2, 6): the two products of each sum, column by column.
    prod = (quat_wxyz.index_select(1, c.left) * quat_wxyz.index_select(1, c.right)).view(-1, 2, 6)
    first, second = prod.unbind(1)
    sums = first + second * c.sign
    return sums + sums


def gravity_from_sums(sums: torch.Tensor) -> torch.Tensor:
    """(N, 3) unit gravity direction in the body frame, from `quat_sums`."""
    c = _quat_consts(sums.device, sums.dtype)
    return torch.addcmul(c.gravity_offset, sums.index_select(1, c.gravity_cols), c.gravity_sign)


def rpy_from_sums(sums: torch.Tensor) -> torch.Tensor:
    """(N, 3) roll, pitch, yaw (extrinsic x-y-z, as `sim.body.rpy_matrix`) from `quat_sums`:
    roll = atan2(2 (w x + y z), 1 - 2 (x x + y y)), pitch = asin(2 (w y - z x)) and
    yaw = atan2(2 (w z + x y), 1 - 2 (y y + z z))."""
    c = _quat_consts(sums.device, sums.dtype)
    num, den = sums[:, 0:3], scalar_tensor(1.0, sums) - sums[:, 3:6]  # [1]: unused
    return torch.where(c.is_pitch, num.clamp(-1.0, 1.0).asin(), torch.atan2(num, den))


def yaw_from_sums(sums: torch.Tensor) -> torch.Tensor:
    """(N,) `rpy_from_sums`' yaw alone (the robot runner's heading needs no more)."""
    return torch.atan2(sums[:, 2], scalar_tensor(1.0, sums) - sums[:, 5])


def yaw_from_quat(quat_wxyz: torch.Tensor) -> torch.Tensor:
    """(N,) yaw (heading about the world vertical, rad) of (N, 4) w x y z quaternions."""
    return yaw_from_sums(quat_sums(quat_wxyz))


def wrap_angle_rad(angle: torch.Tensor) -> torch.Tensor:
    """Angles wrapped to [-pi, pi)."""
    pi = scalar_tensor(torch.pi, angle)
    return torch.remainder(angle + pi, scalar_tensor(2 * torch.pi, angle)) - pi


def scalar_tensor(value: float, like: torch.Tensor) -> torch.Tensor:
    """``value`` as a 0-dim tensor of ``like``'s dtype and device, made once: an operator
    given a Python number wraps it into a new tensor at every call (a few us at batch 1)."""
    return _scalar_tensor(value, like.dtype, like.device)


@functools.lru_cache(maxsize=64)
def _scalar_tensor(value: float, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    with torch.inference_mode(False):  # usable in and out of inference mode
        return torch.tensor(value, dtype=dtype, device=device)


def quat_rotate_inverse(quat_wxyz: torch.Tensor, vec: torch.Tensor) -> torch.Tensor:
    """Rotate world vectors (N, 3) into the frame of unit quaternions (N, 4)."""
    w = quat_wxyz[:, :1]
    xyz = quat_wxyz[:, 1:]
    t = torch.cross(xyz, vec, dim=1)
    t = t + t  # 2 (xyz x vec)
    return vec - w * t + torch.cross(xyz, t, dim=1)


def state_from_arrays(
    qpos: torch.Tensor, qvel: torch.Tensor, sensordata: torch.Tensor, layout: SensorLayout
) -> RobotState:
    """The state of MuJoCo's arrays (N, nq), (N, nv), (N, nsensordata).

    The free joint's qvel holds the linear velocity in the world frame and the angular
    velocity in the body frame (MuJoCo convention).
    """
    return RobotState(qpos, qvel, sensordata, layout)


@functools.lru_cache(maxsize=64)
def _index(idx: tuple[int, ...], device: torch.device) -> torch.Tensor:
    # Index tensors are built once, not on every step.
    return torch.as_tensor(idx, device=device)
