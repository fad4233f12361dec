"""Observation terms: the actor sees only what a real Go1 measures or knows.

The actor's input is built from a `Measurement` (IMU and joint encoders), the dance's targets
and the policy's previous action, by `ActorObservation`. Training (N envs, batched) and the
robot runner (one robot) use that same class, so the observation is defined once. Each term
is one `ObsTerm` entry of `PROPRIO_TERMS` (name, size, sensor source, function); the layout
written into the policy's JSON is read off the same table. The critic also sees privileged
simulator quantities (`privileged`), which never reach the actor.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch

from quaddance.robots import GO1
from quaddance.sim.config import DanceTaskCfg, DomainRandCfg
from quaddance.sim.kinematics import estimate_foot_height_m, leg_geometry
from quaddance.sim.state import RobotState, quat_rotate_inverse, wrap_angle_rad, yaw_from_quat

if TYPE_CHECKING:
    from quaddance.sim.task import DanceEnv

#: Where an actor term comes from on a real Go1 (the policy JSON's `obs.terms[].source`).
SOURCES: tuple[str, ...] = (
    "imu",
    "joint_encoders",
    "foot_contact",
    "kinematics",
    "dance",
    "previous_action",
)


@dataclass
class Measurement:
    """What a Go1 measures, N rows (torch): IMU and joint encoders, model joint order."""

    projected_gravity_b: torch.Tensor  # (N, 3) unit gravity direction in the trunk frame
    gyro_rad_s: torch.Tensor  # (N, 3) trunk angular velocity, trunk frame
    joint_pos_rad: torch.Tensor  # (N, 12) encoder readings (calibration offset included)
    joint_vel_rad_s: torch.Tensor  # (N, 12)
    heading_rad: torch.Tensor  # (N,) IMU yaw, relative to the heading at the dance's start

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
        down = torch.zeros(quat_wxyz.shape[0], 3, dtype=quat_wxyz.dtype, device=quat_wxyz.device)
        down[:, 2] = -1.0
        heading = wrap_angle_rad(yaw_from_quat(quat_wxyz) - heading_zero_rad)
        return cls(
            quat_rotate_inverse(quat_wxyz, down),
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
    """One proprioceptive actor term: `fn(measurement, last_action, builder) -> (N, size)`."""

    name: str
    size: int
    source: str
    fn: Callable[[Measurement, torch.Tensor, ActorObservation], torch.Tensor]


def _foot_height(m: Measurement, last_action: torch.Tensor, ob: ActorObservation) -> torch.Tensor:
    """Leg kinematics from the encoders, turned upright by the IMU (sim/kinematics.py)."""
    return estimate_foot_height_m(m.joint_pos_rad, m.projected_gravity_b, ob.geom)


PROPRIO_TERMS: tuple[ObsTerm, ...] = (
    ObsTerm("projected_gravity", 3, "imu", lambda m, a, ob: m.projected_gravity_b),
    ObsTerm("base_ang_vel_b", 3, "imu", lambda m, a, ob: m.gyro_rad_s),
    ObsTerm(
        "joint_pos_rel",
        GO1.num_joints,
        "joint_encoders",
        lambda m, a, ob: m.joint_pos_rad - ob.nominal_joint_pos,
    ),
    ObsTerm("joint_vel", GO1.num_joints, "joint_encoders", lambda m, a, ob: m.joint_vel_rad_s),
    ObsTerm("last_action", GO1.num_joints, "previous_action", lambda m, a, ob: a),
    ObsTerm("foot_height_m", 4, "kinematics", _foot_height),
)
PROPRIO_DIM = sum(t.size for t in PROPRIO_TERMS)


class ActorObservation:
    """The actor's input: [proprio now, proprio history, front targets now, preview].

    One object per batch of robots (N envs in training, 1 on the robot); it keeps the
    history of past proprio frames. Per policy step: `prop = proprio(meas, last_action)`,
    `obs = build(prop, targets_at)`, act, then `push(prop)`.
    """

    def __init__(self, cfg: DanceTaskCfg, num_envs: int, device: torch.device | str = "cpu"):
        self.device = torch.device(device)
        self.history_len = cfg.obs.history_len
        self.preview_steps = [round(s * cfg.policy_hz) for s in cfg.obs.preview_s]
        self.whole_body = cfg.whole_body
        self.heading = cfg.whole_body and cfg.obs.heading
        self._heading_rad = torch.zeros(num_envs, device=self.device)
        self.nominal_joint_pos = torch.tensor(
            cfg.scene.robot.nominal_joint_pos_rad, device=self.device
        )
        self.geom = leg_geometry(cfg.scene.robot)
        self.history = torch.zeros(num_envs, self.history_len, PROPRIO_DIM, device=self.device)

    def proprio(self, meas: Measurement, last_action: torch.Tensor) -> torch.Tensor:
        """(N, PROPRIO_DIM): the `PROPRIO_TERMS`, in order. The measurement's heading is
        kept for the next `build` (it is not part of the history)."""
        self._heading_rad = meas.heading_rad
        return torch.cat([t.fn(meas, last_action, self) for t in PROPRIO_TERMS], dim=1)

    def build(
        self,
        prop: torch.Tensor,
        targets_at: Callable[[int], torch.Tensor],
        body_targets_at: Callable[[int], torch.Tensor] | None = None,
    ) -> torch.Tensor:
        """(N, dim): ``targets_at(k)`` gives the (N, 4) paw targets k policy steps ahead, m;
        ``body_targets_at(k)`` the (N, 4) body targets (whole-body dance only)."""
        parts = [prop, self.history.flatten(1), targets_at(0)[:, :2]]
        parts += [targets_at(k)[:, :2] for k in self.preview_steps]
        if self.whole_body:
            if body_targets_at is None:
                raise ValueError("a whole-body policy needs the dance's body targets")
            parts.append(body_targets_at(0))
            parts += [body_targets_at(k) for k in self.preview_steps]
            if self.heading:
                error = wrap_angle_rad(self._heading_rad - body_targets_at(0)[:, 3])
                parts.append(error[:, None])
        return torch.cat(parts, dim=1)

    def push(self, prop: torch.Tensor) -> None:
        """Make ``prop`` (what the policy just saw) the newest history frame."""
        if self.history_len:
            self.history = torch.cat([prop.unsqueeze(1), self.history[:, :-1]], dim=1)

    def reset(self, ids: torch.Tensor, prop: torch.Tensor) -> None:
        """Fill the history of robots ``ids`` with their current frame ``prop`` (N, P)."""
        if self.history_len:
            self.history[ids] = prop[ids].unsqueeze(1)

    def layout(self) -> list[dict]:
        """Actor terms in order: name, size and sensor source (the policy JSON's `obs.terms`)."""
        return actor_terms(self.history_len, len(self.preview_steps), self.whole_body, self.heading)


def actor_terms(
    history_len: int, n_preview: int, whole_body: bool = False, heading: bool = False
) -> list[dict]:
    """The actor's terms in order, each `{"name", "size", "source"}` (``heading``: the
    whole-body heading error, `ObsCfg.heading`)."""
    terms = [
        {"name": f"proprio.{t.name}", "size": t.size, "source": t.source} for t in PROPRIO_TERMS
    ]
    history_source = "+".join(sorted({t.source for t in PROPRIO_TERMS}))
    terms += [
        {"name": f"history[{h}].proprio", "size": PROPRIO_DIM, "source": history_source}
        for h in range(1, history_len + 1)
    ]
    terms.append({"name": "front_targets_now_m", "size": 2, "source": "dance"})
    if n_preview:
        terms.append({"name": "front_targets_preview_m", "size": 2 * n_preview, "source": "dance"})
    if whole_body:
        terms.append({"name": "body_targets_now", "size": 4, "source": "dance"})
        if n_preview:
            terms.append({"name": "body_targets_preview", "size": 4 * n_preview, "source": "dance"})
        if heading:
            # IMU heading since the dance began minus the target yaw, wrapped to +-pi.
            terms.append({"name": "heading_error_rad", "size": 1, "source": "dance+imu"})
    return terms


#: Critic-only terms: simulator quantities no robot measures (name, size, function).
PRIVILEGED_TERMS: tuple[tuple[str, int, Callable[[DanceEnv], torch.Tensor]], ...] = (
    ("privileged.dynamics", 3, lambda env: env.dynamics),  # friction, added mass, strength
    ("privileged.base_lin_vel_b", 3, lambda env: env.robot.base_lin_vel_b),
    ("privileged.base_height_m", 1, lambda env: env.robot.base_pos_w[:, 2:3]),
)


def privileged(env: DanceEnv) -> torch.Tensor:
    """(N, 7) the `PRIVILEGED_TERMS`, in order."""
    return torch.cat([fn(env) for _, _, fn in PRIVILEGED_TERMS], dim=1)


def observation_layout(actor: ActorObservation, privileged_critic: bool) -> dict:
    """Names, sizes and sources of the actor's and critic's observation slices, in order."""
    actor_terms = actor.layout()
    critic = list(actor_terms)
    if privileged_critic:
        critic += [{"name": n, "size": k, "source": "privileged"} for n, k, _ in PRIVILEGED_TERMS]
    return {
        "actor": actor_terms,
        "critic": critic,
        "actor_dim": sum(t["size"] for t in actor_terms),
        "critic_dim": sum(t["size"] for t in critic),
    }
