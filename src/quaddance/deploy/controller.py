"""The policy side of the robot runner (`DanceController`): reading -> observation -> action
-> joint targets, for one robot.

It builds the actor's observation with the training code's own `ActorObservation` and the
joint targets with the task's own `sim.task.joint_targets`, so what the policy sees and
commands on a robot is what it saw and commanded in training.
"""

from __future__ import annotations

import numpy as np
import torch

from quaddance.deploy.robot import Reading
from quaddance.errors import QuaddanceError
from quaddance.layout import BODY, PAWS
from quaddance.play.policy import OnnxPolicy
from quaddance.sim.body import BodyFeedforward
from quaddance.sim.feedforward import FrontLiftFeedforward
from quaddance.sim.observations import ActorObservation, Measurement
from quaddance.sim.state import yaw_from_quat
from quaddance.sim.task import joint_targets, row_feedforward


class DanceController:
    """One robot's policy step: reading -> observation -> action -> joint targets.

    Joint targets come from the task's own `sim.task.joint_targets` (one definition of the
    law), fed with the policy JSON's nominal pose, action scale and feed-forward table.
    """

    def __init__(
        self, policy: OnnxPolicy, targets_m: np.ndarray, body_targets: np.ndarray | None = None
    ) -> None:
        cfg = policy.task
        self.policy = policy
        self.cfg = cfg
        self.dev = torch.device("cpu")
        paws = torch.as_tensor(np.asarray(targets_m), dtype=torch.float32)
        if paws.ndim != 2 or paws.shape[1] != 4 or paws.shape[0] < 1:
            raise QuaddanceError(f"dance targets must be (T, 4), got {tuple(paws.shape)}")
        body = torch.zeros(paws.shape[0], 4)
        if body_targets is not None:
            body = torch.as_tensor(np.asarray(body_targets), dtype=torch.float32)
            if body.shape != paws.shape:
                raise QuaddanceError(
                    f"body targets must be (T, 4) like the paw targets {tuple(paws.shape)}, "
                    f"got {tuple(body.shape)}"
                )
        self.rows = torch.cat([paws, body], dim=1)  # (T, 8): paw targets, then body targets
        self.actor_obs = ActorObservation(cfg, 1, self.dev)
        spec = policy.spec  # the policy's JSON contract
        self.nominal_joint_pos = torch.tensor(spec.nominal_joint_pos_rad, dtype=torch.float32)
        self.action_scale = torch.tensor(spec.action_scale, dtype=torch.float32)
        ff = spec.front_feedforward
        self.feedforward = (
            FrontLiftFeedforward(cfg.scene.robot, self.dev, np.asarray(ff.thigh_calf_offsets_rad))
            if cfg.front_feedforward and ff is not None
            else None
        )
        self.body_feedforward = (
            BodyFeedforward(cfg.scene.robot, self.dev) if cfg.whole_body else None
        )
        # Each row's feed-forward and observation part, made once for the whole dance (not
        # in the real-time tick).
        self.ff_rows = self._feedforward_of(self.rows)
        self.obs_rows = self.actor_obs.rows_part(self.rows)
        self.step = 0  # dance step (policy ticks since dance time 0)
        self.heading_zero_rad = 0.0  # IMU yaw at dance time 0 (`reset`)
        self._measured: tuple[Reading, Measurement] | None = None  # the last reading's
        self._fade: tuple[torch.Tensor, int, int] | None = None
        #: What `fade_out` ends at: feet down; a whole-body policy also crouches (the lowest
        #: trunk height it dances), so damping after the dance lets it down from lower.
        self.rest_row = torch.zeros(1, self.rows.shape[1])  # same columns as `rows`
        if cfg.whole_body:
            self.rest_row[0, paws.shape[1]] = cfg.scene.robot.body_four_feet.height_offset_m[0]
        self.last_action = torch.zeros(1, cfg.scene.robot.num_joints)
        self._ids = torch.zeros(1, dtype=torch.long)

    @property
    def n_steps(self) -> int:
        return int(self.rows.shape[0])

    def extend(self, targets_m: np.ndarray, body_targets: np.ndarray) -> None:
        """Append (K, 4) paw and (K, 4) body targets: a dance made while it is danced."""
        more = torch.cat(
            [
                torch.as_tensor(np.asarray(targets_m), dtype=torch.float32).reshape(-1, 4),
                torch.as_tensor(np.asarray(body_targets), dtype=torch.float32).reshape(-1, 4),
            ],
            dim=1,
        )
        n = self.n_steps
        self.rows = torch.cat([self.rows, more], dim=0)
        if self.ff_rows is not None:
            self.ff_rows = torch.cat([self.ff_rows, self._feedforward_of(more)], dim=0)
        # The last rows' previews now see the new rows: their part is made again.
        start = max(0, n - max(self.actor_obs.preview_steps, default=0))
        self.obs_rows = torch.cat(
            [self.obs_rows[:start], self.actor_obs.rows_part(self.rows[start:])], dim=0
        )

    def _feedforward_of(self, rows: torch.Tensor) -> torch.Tensor | None:
        return row_feedforward(rows, self.feedforward, self.body_feedforward)

    def target_row(self, ahead_steps: int) -> torch.Tensor:
        """(1, 8) `targets_at` then `body_targets_at` of ``ahead_steps``."""
        k = self.step + ahead_steps
        if self._fade is not None:
            row, first, n = self._fade
            u = min(1.0, (k - first) / n)
            return row + u * (self.rest_row - row)
        return self.rows[min(k, self.n_steps - 1)][None]

    def feedforward_at(self, ahead_steps: int) -> torch.Tensor | None:
        """(1, 12) `row_feedforward` of `target_row` ``ahead_steps``; None without."""
        if self.ff_rows is None:
            return None
        if self._fade is not None:  # rows made as the dance fades: their own feed-forward
            return self._feedforward_of(self.target_row(ahead_steps))
        return self.ff_rows[min(self.step + ahead_steps, self.n_steps - 1)][None]

    def targets_at(self, ahead_steps: int) -> torch.Tensor:
        """(1, 4) paw targets ``ahead_steps`` ticks from the current step (held at the end;
        faded to `rest_row` after `fade_out`)."""
        return self.target_row(ahead_steps)[:, PAWS]

    def body_targets_at(self, ahead_steps: int) -> torch.Tensor:
        """(1, 4) body targets, as `targets_at`."""
        return self.target_row(ahead_steps)[:, BODY]

    def fade_out(self, steps: int) -> None:
        """From the current step on, targets go linearly from their value now to `rest_row`
        over ``steps`` ticks, and stay there."""
        self._fade = (self.target_row(0).clone(), self.step, max(1, steps))

    def measurement(self, reading: Reading) -> Measurement:
        """The reading as the actor's `Measurement`, its heading relative to the dance's start;
        made once per reading (the runner's posture checks and the observation both read it)."""
        if self._measured is not None and self._measured[0] is reading:
            return self._measured[1]
        # One float32 row made in numpy, read through views: one torch op, not eight.
        parts = (reading.quat_wxyz, reading.gyro_rad_s, reading.joint_pos_rad)
        row = torch.from_numpy(
            np.concatenate([*parts, reading.joint_vel_rad_s]).astype(np.float32)[None]
        )
        q, g, j = 4, 7, 7 + len(reading.joint_pos_rad)
        meas = Measurement.from_imu(
            row[:, :q], row[:, q:g], row[:, g:j], row[:, j:], self.heading_zero_rad
        )
        self._measured = (reading, meas)
        return meas

    def reset(self, reading: Reading) -> None:
        """Dance time 0: no previous action, the history filled with the current frame, the
        heading measured from here."""
        self.step = 0
        self._fade = None
        self.last_action = torch.zeros_like(self.last_action)
        quat = torch.as_tensor(np.asarray(reading.quat_wxyz), dtype=torch.float32)[None]
        self.heading_zero_rad = float(yaw_from_quat(quat)[0])
        self._measured = None  # its heading counts from the new zero
        prop = self.actor_obs.proprio(self.measurement(reading), self.last_action)
        self.actor_obs.reset(self._ids, prop)

    def observe(self, reading: Reading, step: int) -> tuple[torch.Tensor, torch.Tensor]:
        """(proprio frame, observation (1, D)) at dance step ``step``."""
        self.step = step
        prop = self.actor_obs.proprio(self.measurement(reading), self.last_action)
        part = None if self._fade is not None else self.obs_rows[min(step, self.n_steps - 1)][None]
        return prop, self.actor_obs.build(prop, self.targets_at, self.body_targets_at, part)

    def commit(self, prop: torch.Tensor, action: torch.Tensor) -> None:
        """The frame just seen joins the history; ``action`` is what the robot now does."""
        self.actor_obs.push(prop)
        self.last_action = action

    def joint_targets(self, action: torch.Tensor) -> torch.Tensor:
        return joint_targets(action, self)
