"""Observation terms: the actor sees only what a real Go1 measures or knows.

Each term is one `ObsTerm` entry (name, function, sensor source) of a table: `PROPRIO_TERMS`
(what the robot measures, one frame, also stacked as the history), the dance's targets
(`dance_terms`: `PAW_TARGET_TERMS`, `BODY_TARGET_TERMS`, `HEADING_TERMS`) and
`PRIVILEGED_TERMS` (simulator quantities, critic only). A term's size is
found by calling it once; the actor's layout, the critic's, the policy JSON's `obs.terms` and
the training log's column names are all read off these tables (`ObsLayout`).

The actor's input is built from a `Measurement` (IMU and joint encoders, with their sensor
noise in training), the dance's targets and the policy's previous action, by
`ActorObservation`. Training (N envs, batched) and the robot runner (one robot) use that same
class, so the observation is defined once.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import torch

from quaddance.layout import BODY, FRONT_PAWS, PAWS
from quaddance.sim.config import DanceTaskCfg, DomainRandCfg, ObsSlice
from quaddance.sim.kinematics import LegGeometry, foot_height_from_up, foot_up_m, leg_geometry
from quaddance.sim.state import (
    RobotState,
    gravity_from_sums,
    quat_sums,
    wrap_angle_rad,
    yaw_from_sums,
)


@dataclass
class Measurement:
    """What a Go1 measures, N rows (torch): IMU and joint encoders, model joint order."""

    projected_gravity_b: torch.Tensor  # (N, 3) unit gravity direction in the trunk frame
    gyro_rad_s: torch.Tensor  # (N, 3) trunk angular velocity, trunk frame
    joint_pos_rad: torch.Tensor  # (N, 12) encoder readings (calibration offset included)
    joint_vel_rad_s: torch.Tensor  # (N, 12)
    heading_rad: torch.Tensor  # (N,) IMU yaw, relative to the heading at the dance's start
    _foot_up: torch.Tensor | None = field(default=None, repr=False, compare=False)

    def foot_up_m(self, geom: LegGeometry) -> torch.Tensor:
        """(N, 4) `kinematics.foot_up_m` of these readings, made at the first call (the
        observation's foot heights and the runner's posture checks both read it)."""
        if self._foot_up is None:
            self._foot_up = foot_up_m(self.joint_pos_rad, self.projected_gravity_b, geom)
        return self._foot_up

    @classmethod
    def from_imu(
        cls,
        quat_wxyz: torch.Tensor,
        gyro_rad_s: torch.Tensor,
        joint_pos_rad: torch.Tensor,
        joint_vel_rad_s: torch.Tensor,
        heading_zero_rad: float = 0.0,
    ) -> Measurement:
        """From the IMU's orientation quaternion (N, 4; w, x, y, z) as a Go1 reports it;
        ``heading_zero_rad`` is the IMU yaw when the dance began."""
        sums = quat_sums(quat_wxyz)
        heading = wrap_angle_rad(yaw_from_sums(sums) - heading_zero_rad)
        return cls(
            gravity_from_sums(sums),
            gyro_rad_s,
            joint_pos_rad,
            joint_vel_rad_s,
            heading,
        )

    @classmethod
    def from_state(cls, state: RobotState, joint_offset_rad: torch.Tensor) -> Measurement:
        """What the simulated robot's sensors read (encoders carry their calibration offset;
        training episodes start facing yaw 0, so the heading is the yaw)."""
        return cls(
            state.projected_gravity_b,
            state.base_ang_vel_b,
            state.joint_pos + joint_offset_rad,
            state.joint_vel,
            state.base_yaw_rad,
        )

    def with_noise(self, dr: DomainRandCfg, gen: torch.Generator) -> Measurement:
        """The same readings plus uniform sensor noise (`DomainRandCfg`, training only)."""

        def noisy(x: torch.Tensor, scale: float) -> torch.Tensor:
            u = torch.rand(x.shape, generator=gen).to(x.device)
            return x + (2.0 * u - 1.0) * scale

        return Measurement(
            noisy(self.projected_gravity_b, dr.gravity_noise),
            noisy(self.gyro_rad_s, dr.gyro_noise_rad_s),
            noisy(self.joint_pos_rad, dr.joint_pos_noise_rad),
            noisy(self.joint_vel_rad_s, dr.joint_vel_noise_rad_s),
            noisy(self.heading_rad, dr.heading_noise_rad),
        )


@dataclass(frozen=True)
class ObsTerm:
    """One observation term: ``fn(x) -> (N, size)`` (``x``: the `ActorObservation` for actor
    terms, the `DanceEnv` for privileged ones), measured by ``source``."""

    name: str
    fn: Callable[[Any], torch.Tensor]
    source: str


def _preview(
    at: Callable[[int], torch.Tensor], steps: list[int], cols: slice | None = None
) -> torch.Tensor:
    """(N, k * len(steps)): ``at(step)`` (its columns ``cols``) for each preview step."""
    if not steps:
        return at(0)[:, :0]
    return torch.cat([at(k) if cols is None else at(k)[:, cols] for k in steps], dim=1)


def _heading_error(ob: ActorObservation) -> torch.Tensor:
    """IMU heading since the dance began minus the target yaw, wrapped to +-pi."""
    return wrap_angle_rad(ob.meas.heading_rad - ob.body_targets_at(0)[:, 3])[:, None]


#: One frame of what the robot measures, in order (the history stacks whole frames).
PROPRIO_TERMS: tuple[ObsTerm, ...] = (
    ObsTerm("projected_gravity", lambda ob: ob.meas.projected_gravity_b, "imu"),
    ObsTerm("base_ang_vel_b", lambda ob: ob.meas.gyro_rad_s, "imu"),
    ObsTerm(
        "joint_pos_rel", lambda ob: ob.meas.joint_pos_rad - ob.nominal_joint_pos, "joint_encoders"
    ),
    ObsTerm("joint_vel", lambda ob: ob.meas.joint_vel_rad_s, "joint_encoders"),
    ObsTerm("last_action", lambda ob: ob.last_action, "previous_action"),
    # Leg kinematics from the encoders, turned upright by the IMU (sim/kinematics.py).
    ObsTerm(
        "foot_height_m",
        lambda ob: foot_height_from_up(ob.meas.foot_up_m(ob.geom)),
        "kinematics",
    ),
)

#: The dance's targets, after the history: the front paws' targets now and ahead.
PAW_TARGET_TERMS: tuple[ObsTerm, ...] = (
    ObsTerm("front_targets_now_m", lambda ob: ob.targets_at(0)[:, FRONT_PAWS], "dance"),
    ObsTerm(
        "front_targets_preview_m",
        lambda ob: _preview(ob.targets_at, ob.preview_steps, FRONT_PAWS),
        "dance",
    ),
)
#: Whole-body dance: then the body targets now and ahead, and with `ObsCfg.heading` the
#: heading error (`HEADING_TERMS`).
BODY_TARGET_TERMS: tuple[ObsTerm, ...] = (
    ObsTerm("body_targets_now", lambda ob: ob.body_targets_at(0), "dance"),
    ObsTerm(
        "body_targets_preview",
        lambda ob: _preview(ob.body_targets_at, ob.preview_steps),
        "dance",
    ),
)
HEADING_TERMS: tuple[ObsTerm, ...] = (ObsTerm("heading_error_rad", _heading_error, "dance+imu"),)


def dance_terms(cfg: DanceTaskCfg) -> tuple[ObsTerm, ...]:
    """The dance's terms of this task, in order (they follow the proprio history)."""
    if not cfg.whole_body:
        return PAW_TARGET_TERMS
    return PAW_TARGET_TERMS + BODY_TARGET_TERMS + (HEADING_TERMS if cfg.obs.heading else ())


#: Critic-only terms: simulator quantities no robot measures.
PRIVILEGED_TERMS: tuple[ObsTerm, ...] = (
    # friction, added mass, motor strength
    ObsTerm("privileged.dynamics", lambda env: env.dynamics, "privileged"),
    ObsTerm("privileged.base_lin_vel_b", lambda env: env.robot.base_lin_vel_b, "privileged"),
    ObsTerm("privileged.base_height_m", lambda env: env.robot.base_pos_w[:, 2:3], "privileged"),
)


@dataclass(frozen=True)
class ObsLayout:
    """The actor's and the critic's observation, slice by slice, in order."""

    actor: tuple[ObsSlice, ...]
    critic: tuple[ObsSlice, ...]

    @property
    def actor_dim(self) -> int:
        return sum(s.size for s in self.actor)

    @property
    def critic_dim(self) -> int:
        return sum(s.size for s in self.critic)

    @classmethod
    def of(
        cls, actor: tuple[ObsSlice, ...], privileged: tuple[ObsSlice, ...], privileged_critic: bool
    ) -> ObsLayout:
        """The actor's slices (`ActorObservation.layout`); the critic sees them and, with
        `ObsCfg.privileged_critic`, the ``privileged`` ones (`DanceEnv.privileged_slices`)."""
        return cls(actor, actor + (privileged if privileged_critic else ()))

    def column_names(self) -> dict[str, list[str]]:
        """One name per column, ``term[i]``, for the actor and the critic."""
        return {
            group: [f"{s.name}[{i}]" for s in slices for i in range(s.size)]
            for group, slices in (("actor", self.actor), ("critic", self.critic))
        }


@dataclass(frozen=True)
class _RowView:
    """What the `ActorObservation.row_terms` read, for rows made ahead (`rows_part`)."""

    targets_at: Callable[[int], torch.Tensor]
    body_targets_at: Callable[[int], torch.Tensor]
    preview_steps: list[int]


class ActorObservation:
    """The actor's input: [proprio now, proprio history, dance terms].

    One object per batch of robots (N envs in training, 1 on the robot); it keeps the
    history of past proprio frames. Per policy step: `prop = proprio(meas, last_action)`,
    `obs = build(prop, targets_at)`, act, then `push(prop)`. The terms read what they need
    off this object (`meas`, `last_action`, `targets_at`, ...).
    """

    def __init__(self, cfg: DanceTaskCfg, num_envs: int, device: torch.device | str = "cpu"):
        self.device = torch.device(device)
        self.history_len = cfg.obs.history_len
        self.preview_steps = [round(s * cfg.policy_hz) for s in cfg.obs.preview_s]
        self.whole_body = cfg.whole_body
        robot = cfg.scene.robot
        self.nominal_joint_pos = torch.tensor(robot.nominal_joint_pos_rad, device=self.device)
        self.geom = leg_geometry(robot)
        # Sizes: each term called once on one robot at rest (mjlab's `_prepare_terms`).
        zeros = lambda *shape: torch.zeros(*shape, device=self.device)  # noqa: E731
        j = robot.num_joints
        self.meas = Measurement(zeros(1, 3), zeros(1, 3), zeros(1, j), zeros(1, j), zeros(1))
        self.last_action = zeros(1, j)
        self.targets_at: Callable[[int], torch.Tensor] = lambda k: zeros(1, 4)
        self.body_targets_at: Callable[[int], torch.Tensor] = lambda k: zeros(1, 4)
        proprio = [(t, t.fn(self).shape[1]) for t in PROPRIO_TERMS]
        dance = [(t, t.fn(self).shape[1]) for t in dance_terms(cfg)]
        self.dance_terms = tuple(t for t, size in dance if size)
        #: The dance terms made of the target rows alone (source "dance"), which come first: a
        #: task that knows its rows ahead makes them once per row (`rows_part`), the others
        #: (`step_terms`, which also read the sensors) at each step.
        self.row_terms = tuple(t for t in self.dance_terms if t.source == "dance")
        self.step_terms = self.dance_terms[len(self.row_terms) :]
        if any(t.source == "dance" for t in self.step_terms):
            raise ValueError("the dance terms made of the targets alone must come first")
        self.proprio_dim = sum(size for _, size in proprio)
        history_source = "+".join(sorted({t.source for t in PROPRIO_TERMS}))
        self.layout: tuple[ObsSlice, ...] = (
            *(ObsSlice(f"proprio.{t.name}", size, t.source) for t, size in proprio),
            *(
                ObsSlice(f"history[{h}].proprio", self.proprio_dim, history_source)
                for h in range(1, self.history_len + 1)
            ),
            *(ObsSlice(t.name, size, t.source) for t, size in dance if size),
        )
        self.history = zeros(num_envs, self.history_len, self.proprio_dim)

    def proprio(self, meas: Measurement, last_action: torch.Tensor) -> torch.Tensor:
        """(N, proprio_dim): the `PROPRIO_TERMS`, in order. The measurement is kept for the
        next `build` (its heading is not part of the history)."""
        self.meas, self.last_action = meas, last_action
        return torch.cat([t.fn(self) for t in PROPRIO_TERMS], dim=1)

    def rows_part(self, rows: torch.Tensor) -> torch.Tensor:
        """(..., L, k) the `row_terms` of each of L target rows [paws | body] (..., L, 8) in
        sequence: a row's previews read the rows after it (held at the sequence's end). What
        `build` makes of a step's rows when it is not given them."""
        n = rows.shape[-2]

        def later(k: int, cols: slice) -> torch.Tensor:
            idx = (torch.arange(n, device=rows.device) + k).clamp(max=n - 1)
            return rows.index_select(-2, idx)[..., cols].reshape(-1, cols.stop - cols.start)

        view = _RowView(lambda k: later(k, PAWS), lambda k: later(k, BODY), self.preview_steps)
        parts = [t.fn(view) for t in self.row_terms]
        part = torch.cat(parts, dim=1) if parts else later(0, PAWS)[:, :0]
        return part.view(*rows.shape[:-1], -1)

    def build(
        self,
        prop: torch.Tensor,
        targets_at: Callable[[int], torch.Tensor],
        body_targets_at: Callable[[int], torch.Tensor] | None = None,
        rows_part: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(N, dim): ``targets_at(k)`` gives the (N, 4) paw targets k policy steps ahead, m;
        ``body_targets_at(k)`` the (N, 4) body targets (whole-body dance only);
        ``rows_part``, the `rows_part` of this step's rows where they were made ahead."""
        if self.whole_body and body_targets_at is None:
            raise ValueError("a whole-body policy needs the dance's body targets")
        self.targets_at = targets_at
        if body_targets_at is not None:
            self.body_targets_at = body_targets_at
        rows = [rows_part] if rows_part is not None else [t.fn(self) for t in self.row_terms]
        parts = [prop, self.history.flatten(1), *rows, *(t.fn(self) for t in self.step_terms)]
        return torch.cat(parts, dim=1)

    def push(self, prop: torch.Tensor) -> None:
        """Make ``prop`` (what the policy just saw) the newest history frame."""
        if self.history_len:
            self.history = torch.cat([prop.unsqueeze(1), self.history[:, :-1]], dim=1)

    def reset(self, ids: torch.Tensor, prop: torch.Tensor) -> None:
        """Fill the history of robots ``ids`` with their current frame ``prop`` (N, P)."""
        if self.history_len:
            self.history[ids] = prop[ids].unsqueeze(1)
