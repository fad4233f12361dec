"""The dance task: a Go1 tracks front-foot height targets while its rear feet stay down.

Written once over batched torch tensors (`RobotState`); the physics comes from an engine
(`cpu`: native MuJoCo, `gpu`: MuJoCo Warp). Training (rsl-rl's VecEnv interface) and
playback (one env, no randomisation) use this same class.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np
import torch

from quaddance.layout import BODY, FRONT_PAWS, N_BODY, PAWS, row_width
from quaddance.sim import observations, rewards, terminations
from quaddance.sim.body import BodyFeedforward
from quaddance.sim.config import DanceTaskCfg, ObsSlice
from quaddance.sim.engine import Engine, nominal_dynamics
from quaddance.sim.engines import make_engine
from quaddance.sim.feedforward import FrontLiftFeedforward
from quaddance.sim.state import RobotState, state_from_arrays


def sample_dynamics(cfg: DanceTaskCfg, rng: np.random.Generator) -> np.ndarray:
    """K dynamics variants (friction, added mass kg, motor strength) drawn uniformly."""
    dr = cfg.domain_rand
    nominal = nominal_dynamics(cfg.scene)
    if not dr.enabled:
        return nominal
    k = dr.num_variants
    rows = np.stack(
        [
            rng.uniform(*dr.friction, k),
            rng.uniform(*dr.added_mass_kg, k),
            rng.uniform(*dr.motor_strength, k),
        ],
        axis=1,
    )
    rows[0] = nominal[0]  # always keep the nominal robot among the variants
    return rows


class JointTargetSource(Protocol):
    """What the joint-target law reads: a `DanceEnv` (N envs) or the robot runner's
    `deploy.runner.DanceController` (one robot)."""

    nominal_joint_pos: torch.Tensor
    action_scale: torch.Tensor

    def feedforward_at(self, ahead_steps: int) -> torch.Tensor | None:
        """(N, 12) the feed-forward (`row_feedforward`) of the target row ``ahead_steps``
        policy steps from now; None for a task without one."""
        ...


def row_feedforward(
    rows: torch.Tensor, lift: FrontLiftFeedforward | None, body: BodyFeedforward | None
) -> torch.Tensor | None:
    """(T, 12) joint offsets (rad, model order) that target rows (T, 8) [paws | body] call
    for: the front-lift feed-forward of the front paws' targets (`sim.feedforward`) plus, for
    whole-body dance, the body feed-forward of the trunk's (`sim.body`); None with neither.

    A function of the row alone, so a task with fixed rows makes it once for all of them
    (training's bank, the runner's dance) instead of at every step."""
    ff = None if lift is None else lift(rows[:, FRONT_PAWS])
    if body is not None:
        offsets = body(rows[:, BODY])
        ff = offsets if ff is None else ff + offsets
    return ff


def joint_targets(actions: torch.Tensor, src: JointTargetSource) -> torch.Tensor:
    """(N, 12) PD targets: nominal pose + scaled actions + the feed-forward of the targets
    due after this step (`row_feedforward`; the contract written into the policy's JSON).
    Training, playback and the robot runner (deploy/) all call this."""
    target = src.nominal_joint_pos + src.action_scale * actions
    ff = src.feedforward_at(1)
    return target if ff is None else target + ff


class _StepRows(NamedTuple):
    """One step's target rows by offset (policy steps ahead): whole, paws, body, and the
    feed-forward of each; and the observation's part made of this step's rows."""

    full: dict[int, torch.Tensor]
    paws: dict[int, torch.Tensor]
    body: dict[int, torch.Tensor]
    ff: dict[int, torch.Tensor] | None  # `row_feedforward`, when the task has one
    obs: torch.Tensor | None  # `ActorObservation.rows_part`; None: the step makes it


class DanceEnv:
    """Vectorised dance task. `bank` (B, L, 4) holds paw-target sequences at the policy rate,
    or (B, L, 8) paw then body targets (`quaddance.layout.BODY_COLUMNS`) for whole-body dance.

    Implements rsl-rl's `VecEnv` interface by duck typing: importing it (with tensordict,
    which imports torch._dynamo) would cost playback 2 s. With `compute_rewards=False`
    (playback) observations come as a plain dict of tensors instead of a TensorDict.
    """

    def __init__(
        self,
        cfg: DanceTaskCfg,
        bank: torch.Tensor | np.ndarray,
        engine: str = "cpu",
        seed: int = 0,
        random_start: bool = True,
        compute_rewards: bool = True,
        feedforward_table: np.ndarray | None = None,
        dynamics: np.ndarray | None = None,
    ) -> None:
        """``dynamics``: (K, 3) variants (friction, added mass kg, motor strength) to use
        instead of drawing them; evaluation pins the robot to chosen values this way."""
        self.cfg = cfg
        # Playback needs the same observations, dynamics and terminations but no rewards.
        self.compute_rewards = compute_rewards
        self.num_envs = cfg.num_envs
        self.num_actions = cfg.scene.robot.num_joints
        self.max_episode_length = cfg.max_episode_steps
        self._rng = np.random.default_rng(seed)
        self._gen = torch.Generator().manual_seed(seed)
        if abs(cfg.scene.timestep_s * cfg.decimation - cfg.step_dt_s) > 1e-9:
            raise ValueError("scene.timestep_s * decimation must equal 1 / policy_hz")
        variants = sample_dynamics(cfg, self._rng) if dynamics is None else np.asarray(dynamics)
        self.engine: Engine = make_engine(engine, cfg.num_envs, cfg.scene, variants)
        self.device = self.engine.device
        dev = self.device
        self._variants = torch.as_tensor(self.engine.variants, dtype=torch.float32, device=dev)

        bank_t = torch.as_tensor(np.asarray(bank), dtype=torch.float32)
        if bank_t.ndim != 3 or bank_t.shape[2] not in (row_width(False), row_width(True)):
            raise ValueError(
                f"target bank must be (B, L, 4) or (B, L, 8), got {tuple(bank_t.shape)}"
            )
        if bank_t.shape[2] == 4:  # no body targets: the trunk stands still
            bank_t = torch.cat([bank_t, torch.zeros(*bank_t.shape[:2], N_BODY)], dim=2)
        self.bank = bank_t.to(dev)
        self.random_start = random_start
        self._curriculum_scale = 1.0
        # The actor's observation: the same builder as the robot runner's (deploy/).
        self.actor_obs = observations.ActorObservation(cfg, cfg.num_envs, dev)
        self.preview_steps = self.actor_obs.preview_steps

        model = self.engine.model
        self.nominal_joint_pos = torch.tensor(cfg.scene.robot.nominal_joint_pos_rad, device=dev)
        self.home_qpos = torch.tensor(model.key("home").qpos, dtype=torch.float32, device=dev)
        scale = torch.full((self.num_actions,), cfg.action_scale, device=dev)
        scale[0::3] *= cfg.hip_scale_factor  # hips are every third joint in model order
        self.action_scale = scale
        # Playback passes the table from the policy's JSON (the same numbers, no 2 s rebuild).
        self.feedforward = (
            FrontLiftFeedforward(cfg.scene.robot, dev, feedforward_table)
            if cfg.front_feedforward
            else None
        )
        self.body_feedforward = BodyFeedforward(cfg.scene.robot, dev) if cfg.whole_body else None
        # What a step looks up in the bank, made here once for every row (at batch 1, making
        # them at each step cost half of playback's step): the row [paws | body], its
        # feed-forward (`row_feedforward`; made in one batch, sin and atan2 may round a last
        # bit otherwise than row by row), and the observation's terms made of the rows alone
        # (`ActorObservation.rows_part`: the targets now and ahead).
        b, n_rows = self.bank.shape[:2]
        ff = self._feedforward_of(self.bank.reshape(b * n_rows, -1))
        ff_width = 0 if ff is None else ff.shape[1]
        ffs = [] if ff is None else [ff.view(b, n_rows, ff_width)]
        self._lookup = torch.cat([self.bank, *ffs, self.actor_obs.rows_part(self.bank)], dim=2)
        self._ff_cols = slice(BODY.stop, BODY.stop + ff_width) if ff is not None else None
        self._obs_cols = slice(BODY.stop + ff_width, None)
        lo = torch.tensor(model.jnt_range[1:, 0], dtype=torch.float32, device=dev)
        hi = torch.tensor(model.jnt_range[1:, 1], dtype=torch.float32, device=dev)
        mid, half = (lo + hi) / 2, (hi - lo) / 2 * 0.9
        self.soft_joint_limits = (mid - half, mid + half)

        n, j = self.num_envs, self.num_actions
        z = lambda *shape: torch.zeros(*shape, device=dev)  # noqa: E731
        self.episode_length_buf = torch.zeros(n, dtype=torch.long, device=dev)
        self.bank_idx = torch.zeros(n, dtype=torch.long, device=dev)
        self.bank_offset = torch.zeros(n, dtype=torch.long, device=dev)
        self.last_action, self.prev_action, self.prev_prev_action = z(n, j), z(n, j), z(n, j)
        self.prev_joint_vel = z(n, j)
        self._target_hist = self.nominal_joint_pos.repeat(n, 3, 1)  # joint targets t, t-1, t-2
        self.action_lag = torch.zeros(n, dtype=torch.long, device=dev)
        d = cfg.decimation
        self._lag_shift = d - 1 - torch.arange(d, device=dev)  # `_lagged_controls`' D - 1 - j
        self.joint_offset = z(n, j)
        self.dynamics = self._variants[torch.zeros(n, dtype=torch.long, device=dev)]
        self._last_proprio: torch.Tensor | None = None
        self._ahead: dict[tuple[int, ...], torch.Tensor] = {}  # `_bank_rows`' step offsets
        # Every offset a step reads (observation, joint targets, rewards) and this step's rows
        # at them, looked up together at the first read (`_rows_now`): one lookup per step.
        # The observation's previews are in the rows, but not under a curriculum's scale.
        self._row_steps = (0, 1)
        self._row_steps_scaled = tuple(dict.fromkeys((0, 1, *self.preview_steps)))
        self._rows: _StepRows | None = None
        self._lag_index = self._lag_gather_index()
        self.robot: RobotState = self._read_state()
        self.errors = rewards.TrackingErrors(self)
        self.fell = torch.zeros(n, dtype=torch.bool, device=dev)
        #: The critic's privileged slices, each term's size found by calling it once.
        self.privileged_slices = tuple(
            ObsSlice(t.name, t.fn(self).shape[1], t.source) for t in observations.PRIVILEGED_TERMS
        )
        self.obs_layout = observations.ObsLayout.of(
            self.actor_obs.layout, self.privileged_slices, cfg.obs.privileged_critic
        )
        self.reset_all()

    # --- targets ---------------------------------------------------------------------------
    def _bank_rows(self, *ahead_steps: int) -> torch.Tensor:
        """(N, K, C) the bank's rows [paws | body | feed-forward | observation part] at each
        of the K ``ahead_steps`` policy steps from now (held at the sequence's end): one
        lookup for them all. Under the curriculum's scale: [paws | scaled body | its
        feed-forward], made again."""
        ahead = self._ahead.get(ahead_steps)
        if ahead is None:
            with torch.inference_mode(False):  # usable in and out of inference mode
                ahead = torch.tensor(ahead_steps, device=self.device)
            self._ahead[ahead_steps] = ahead
        t = (self.bank_offset + self.episode_length_buf).unsqueeze(1) + ahead
        rows = self._lookup[self.bank_idx.unsqueeze(1), t.clamp(max=self.bank.shape[1] - 1)]
        if self.curriculum_scale == 1.0:
            return rows
        scaled = rows[..., BODY] * self.curriculum_scale
        rows = torch.cat([rows[..., PAWS], scaled], dim=2)
        ff = self._feedforward_of(rows.reshape(-1, rows.shape[2]))
        return rows if ff is None else torch.cat([rows, ff.view(*rows.shape[:2], -1)], dim=2)

    def _feedforward_of(self, rows: torch.Tensor) -> torch.Tensor | None:
        return row_feedforward(rows, self.feedforward, self.body_feedforward)

    @property
    def curriculum_scale(self) -> float:
        """Training's curriculum (0: the paws-only task, 1: the full one): it scales the body
        targets, which everything reads through `body_targets_at` (observation, rewards,
        feed-forward), and the weights of the `RewardTerm.curriculum` terms."""
        return self._curriculum_scale

    @curriculum_scale.setter
    def curriculum_scale(self, value: float) -> None:
        self._curriculum_scale = value
        self._rows = None

    def _rows_now(self) -> _StepRows:
        """This step's target rows at each of `_row_steps`, looked up at the first read after
        the time or the sequence changed."""
        if self._rows is None:
            whole = self.curriculum_scale == 1.0
            steps = self._row_steps if whole else self._row_steps_scaled
            rows = self._bank_rows(*steps)
            at = lambda cols: dict(zip(steps, rows[..., cols].unbind(1), strict=True))  # noqa: E731
            self._rows = _StepRows(
                at(slice(0, BODY.stop)),
                at(PAWS),
                at(BODY),
                at(self._ff_cols) if self._ff_cols is not None else None,
                rows[:, 0, self._obs_cols] if whole else None,
            )
        return self._rows

    def target_row(self, ahead_steps: int) -> torch.Tensor:
        """(N, 8) `targets_at` then `body_targets_at` of ``ahead_steps``."""
        row = self._rows_now().full.get(ahead_steps)
        return row if row is not None else self._bank_rows(ahead_steps)[:, 0, : BODY.stop]

    def feedforward_at(self, ahead_steps: int) -> torch.Tensor | None:
        """(N, 12) `row_feedforward` of the target row ``ahead_steps`` from now; None without."""
        ff = self._rows_now().ff
        if ff is None:
            return None
        row = ff.get(ahead_steps)
        return row if row is not None else self._bank_rows(ahead_steps)[:, 0, self._ff_cols]

    def targets_at(self, ahead_steps: int) -> torch.Tensor:
        """(N, 4) paw targets `ahead_steps` policy steps from now (held at the sequence's end)."""
        row = self._rows_now().paws.get(ahead_steps)
        return row if row is not None else self.target_row(ahead_steps)[:, PAWS]

    def body_targets_at(self, ahead_steps: int) -> torch.Tensor:
        """(N, 4) body targets (height offset m, roll, pitch, yaw rad) `ahead_steps` from now;
        zeros for a paws-only dance."""
        row = self._rows_now().body.get(ahead_steps)
        return row if row is not None else self.target_row(ahead_steps)[:, BODY]

    def start_at(self, ids: torch.Tensor, bank_step: int) -> None:
        """Envs ``ids`` play their sequence from ``bank_step`` on, from their next step."""
        self.bank_offset[ids] = bank_step
        self._rows = None

    def set_action_lag(self, substeps: int | torch.Tensor) -> None:
        """Delay the envs' joint targets by ``substeps`` physics steps (one number, or (N,)
        one per env), kept until a randomising reset draws new lags."""
        self.action_lag[:] = substeps
        self._lag_index = self._lag_gather_index()

    # --- VecEnv interface ----------------------------------------------------------------------
    def get_observations(self):
        """Observation groups "actor" and "critic": a TensorDict when training (rsl-rl).
        In playback (no rewards) a dict of (N, k) tensors, "actor" only: no one reads the
        critic's there."""
        prop = self._proprio()
        self._last_proprio = prop  # the next step's history frame
        actor = self.actor_obs.build(
            prop, self.targets_at, self.body_targets_at, self._rows_now().obs
        )
        groups = {"actor": actor}
        if not self.compute_rewards:
            return groups
        if self.cfg.obs.privileged_critic:
            privileged = [t.fn(self) for t in observations.PRIVILEGED_TERMS]
            groups["critic"] = torch.cat([actor, *privileged], dim=1)
        else:
            groups["critic"] = actor
        from tensordict import TensorDict

        return TensorDict(groups, batch_size=[self.num_envs], device=self.device)

    def step(self, actions: torch.Tensor) -> tuple[dict, torch.Tensor, torch.Tensor, dict]:
        actions = actions.to(self.device).clamp(-10.0, 10.0)
        # History of what the policy saw, before the state changes: the proprio frame of the
        # last observation is this state's (same tensors).
        prop = self._last_proprio if self._last_proprio is not None else self._proprio()
        self.actor_obs.push(prop)
        self.prev_prev_action, self.prev_action = self.prev_action, self.last_action
        self.last_action = actions
        self.prev_joint_vel = self.robot.joint_vel
        target = self.joint_targets(actions)
        self._target_hist = torch.cat([target.unsqueeze(1), self._target_hist[:, :2]], dim=1)
        self.robot = self._read_state(self.engine.step(self._lagged_controls()))
        self.episode_length_buf += 1
        self._rows = None

        self.fell, time_out = terminations.evaluate(self)
        self._push()
        done = self.fell | time_out
        extras: dict = {"time_outs": time_out}
        if self.compute_rewards:
            self.errors = rewards.TrackingErrors(self)  # this step's, for the terms and the log
            reward, terms = self._reward()
            extras["log"] = self._log(terms, done)
        else:
            reward = torch.zeros(self.num_envs, device=self.device)
        if done.any():
            self.reset_envs(done.nonzero().squeeze(1))
        return self.get_observations(), reward, done, extras

    def joint_targets(self, actions: torch.Tensor) -> torch.Tensor:
        return joint_targets(actions, self)

    # --- internals -------------------------------------------------------------------------------
    def _lag_gather_index(self) -> torch.Tensor:
        """(N, decimation, 12) `_lagged_controls`' index into the joint-target history.

        The target applied at substep j of a step is the one computed ceil((lag - j) / D)
        policy steps ago (D = decimation), so a lag of 6 substeps is 30 ms. Made when the lags
        change, not at every step.
        """
        lag = self.action_lag.unsqueeze(1) + self._lag_shift  # lag - j + D - 1, (N, D)
        back = torch.div(lag, self.cfg.decimation, rounding_mode="floor")
        back = back.clamp(0, self._target_hist.shape[1] - 1)
        return back.unsqueeze(2).expand(-1, -1, self.num_actions)

    def _lagged_controls(self) -> torch.Tensor:
        """(N, decimation, 12) joint targets per physics substep, delayed by each env's lag."""
        return torch.gather(self._target_hist, 1, self._lag_index)

    def measure(self) -> observations.Measurement:
        """What the robots' sensors read now (with sensor noise when randomising)."""
        meas = observations.Measurement.from_state(self.robot, self.joint_offset)
        dr = self.cfg.domain_rand
        return meas.with_noise(dr, self._gen) if dr.enabled and dr.sensor_noise else meas

    def _proprio(self) -> torch.Tensor:
        return self.actor_obs.proprio(self.measure(), self.last_action)

    def _read_state(self, out=None) -> RobotState:
        out = out if out is not None else self.engine.read()
        return state_from_arrays(out.qpos, out.qvel, out.sensordata, self.engine.layout)

    def _reward(self) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """The sum of the `DanceTaskCfg.rewards` terms, in order, and each term's share."""
        dt = self.cfg.step_dt_s
        total = torch.zeros(self.num_envs, device=self.device)
        terms = {}
        for name, term in self.cfg.rewards.items():
            w = term.weight * self.curriculum_scale if term.curriculum else term.weight
            if w == 0.0:
                continue
            value = w * term.fn(self, **term.params)
            value = value * dt if term.per_step else value
            terms[name] = value
            total += value
        return total, terms

    def _log(self, terms: dict, done: torch.Tensor) -> dict:
        e = self.errors  # what the reward terms read, computed once
        return {
            **{f"/reward/{k}": v.mean() for k, v in terms.items()},
            "/metrics/front_abs_err_m": e.front_m.abs().mean(1).mean(),
            "/metrics/rear_lift_m": self.robot.foot_height_m[:, 2:].clamp(min=0).mean(),
            "/metrics/falls": self.fell.float().sum(),
            "/metrics/body_height_err_m": e.body_height_m.abs().mean(),
            "/metrics/body_tilt_err_rad": e.body_tilt.mean(),
            "/metrics/episodes_ended": done.float().sum(),
        }

    def _push(self) -> None:
        dr = self.cfg.domain_rand
        if not dr.enabled or dr.push_vel_m_s <= 0:
            return
        every = max(1, round(dr.push_interval_s * self.cfg.policy_hz))
        ids = (self.episode_length_buf % every == 0).nonzero().squeeze(1)
        if ids.numel() == 0:
            return
        kick = (torch.rand(ids.numel(), 2, generator=self._gen) * 2 - 1) * dr.push_vel_m_s
        self.push_base(ids, kick)

    def push_base(self, ids: torch.Tensor, vel_xy_m_s: torch.Tensor) -> None:
        """Add (n, 2) horizontal velocity, world frame, m/s, to the bases of envs ``ids``."""
        qvel = torch.cat(
            [self.robot.base_lin_vel_w, self.robot.base_ang_vel_b, self.robot.joint_vel], dim=1
        )[ids]
        qvel[:, :2] += vel_xy_m_s.to(self.device)
        self.engine.set_velocity(ids, qvel)

    def reset_all(self) -> None:
        self.reset_envs(torch.arange(self.num_envs, device=self.device))

    def reset_envs(self, ids: torch.Tensor) -> None:
        """New pose, dynamics variant, calibration offsets, lag and target sequence."""
        n, dr, dev = ids.numel(), self.cfg.domain_rand, self.device
        rand = lambda *shape: torch.rand(*shape, generator=self._gen).to(dev)  # noqa: E731
        qpos = self.home_qpos.repeat(n, 1)
        qvel = torch.zeros(n, self.engine.nv, device=dev)
        if dr.enabled:
            qpos[:, 7:] += (rand(n, self.num_actions) * 2 - 1) * dr.init_joint_noise_rad
            variant = torch.randint(len(self._variants), (n,), generator=self._gen).to(dev)
            self.joint_offset[ids] = (rand(n, self.num_actions) * 2 - 1) * dr.joint_offset_rad
            self.action_lag[ids] = torch.randint(
                dr.max_action_lag_substeps + 1, (n,), generator=self._gen
            ).to(dev)
        else:
            variant = torch.zeros(n, dtype=torch.long, device=dev)
        self.engine.set_variants(ids, variant)
        self.dynamics[ids] = self._variants[variant]
        self.bank_idx[ids] = torch.randint(self.bank.shape[0], (n,), generator=self._gen).to(dev)
        span = self.bank.shape[1] - self.max_episode_length - max(self.preview_steps, default=0)
        if self.random_start and span > 0:
            self.bank_offset[ids] = torch.randint(span, (n,), generator=self._gen).to(dev)
        else:
            self.bank_offset[ids] = 0
        self.episode_length_buf[ids] = 0
        for buf in (self.last_action, self.prev_action, self.prev_prev_action, self.prev_joint_vel):
            buf[ids] = 0.0
        self._target_hist[ids] = qpos[:, 7:].unsqueeze(1).expand(-1, 3, -1)
        self._lag_index = self._lag_gather_index()
        self._rows = None
        self.engine.reset(ids, qpos, qvel)
        self.robot = self._read_state()
        self.actor_obs.reset(ids, self._proprio())
