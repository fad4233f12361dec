"""The physics engines behind the dance task (`sim.engine.Engine`): native MuJoCo on the CPU
(`CpuEngine`, here) and MuJoCo Warp on the GPU (`sim.warp_engine.WarpEngine`); `make_engine`
picks one by name.
"""

from __future__ import annotations

import copy
import os

import mujoco
import numpy as np
import torch

from quaddance.sim.engine import (
    ADDED_MASS_KG,
    FRICTION,
    MOTOR_STRENGTH,
    Engine,
    EngineOutput,
    nominal_dynamics,
    robot_collision_geoms,
)
from quaddance.sim.scene import SceneCfg, build_model
from quaddance.sim.state import SensorLayout


def apply_dynamics(model: mujoco.MjModel, row: np.ndarray, trunk_body: str) -> None:
    """Write one variant (friction, added base mass, motor strength) into a model in place.

    Friction goes to every robot collision geom: a calf touching the floor with another
    friction than the foot beside it would make the engines disagree.
    """
    model.geom_friction[robot_collision_geoms(model), 0] = row[FRICTION]
    trunk = model.body(trunk_body).id
    model.body_mass[trunk] += row[ADDED_MASS_KG]
    # Position actuator: force = kp*(ctrl - q) - kd*qdot; strength scales both gains.
    model.actuator_gainprm[:, 0] *= row[MOTOR_STRENGTH]
    model.actuator_biasprm[:, 1] *= row[MOTOR_STRENGTH]
    model.actuator_biasprm[:, 2] *= row[MOTOR_STRENGTH]


class CpuEngine:
    """All envs stepped by `mujoco.rollout`, one thread per core."""

    name = "cpu"

    def __init__(
        self,
        num_envs: int,
        scene: SceneCfg = SceneCfg(),
        variants: np.ndarray | None = None,
        nthread: int | None = None,
    ) -> None:
        from mujoco import rollout

        self._rollout = rollout
        self.num_envs = num_envs
        self.device = torch.device("cpu")
        base = build_model(scene, visual=False)
        self.model = base
        self.layout = SensorLayout.from_model(base, scene.robot)
        rows = nominal_dynamics(scene) if variants is None else variants
        self.variants = np.asarray(rows, dtype=np.float64)
        self._variant_models = []
        for row in self.variants:
            m = copy.deepcopy(base)
            apply_dynamics(m, row, scene.robot.trunk_body)
            self._variant_models.append(m)
        self.variant_idx = np.zeros(num_envs, dtype=np.int64)
        self._models = [self._variant_models[0]] * num_envs
        self.nthread = nthread or max(1, min(os.cpu_count() or 1, num_envs))
        self._datas = [mujoco.MjData(base) for _ in range(self.nthread)]
        self._spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self.nstate = mujoco.mj_stateSize(base, self._spec)
        self.nq, self.nv, self.nu = base.nq, base.nv, base.nu
        self.state = np.zeros((num_envs, self.nstate))
        self.sensordata = np.zeros((num_envs, base.nsensordata))
        d = mujoco.MjData(base)
        mujoco.mj_resetDataKeyframe(base, d, base.key("home").id)
        mujoco.mj_forward(base, d)
        mujoco.mj_getState(base, d, self.state[0], self._spec)
        self.state[:] = self.state[0]
        self.sensordata[:] = d.sensordata
        self._scratch = d
        self._out_state: np.ndarray | None = None
        self._out_sens: np.ndarray | None = None

    # State vector order under mjSTATE_FULLPHYSICS: time, qpos, qvel, act, ...
    def _qpos(self, state: np.ndarray) -> np.ndarray:
        return state[..., 1 : 1 + self.nq]

    def _qvel(self, state: np.ndarray) -> np.ndarray:
        return state[..., 1 + self.nq : 1 + self.nq + self.nv]

    def set_variants(
        self, env_ids: torch.Tensor | np.ndarray, variant_idx: torch.Tensor | np.ndarray
    ) -> None:
        self.variant_idx[env_ids] = variant_idx
        for e, v in zip(env_ids.tolist(), np.asarray(variant_idx).tolist(), strict=True):
            self._models[e] = self._variant_models[v]

    def reset(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        """Set the state of some envs and recompute their sensors."""
        ids = env_ids.cpu().numpy()
        qp, qv = qpos.double().cpu().numpy(), qvel.double().cpu().numpy()
        d = self._scratch
        for k, e in enumerate(ids.tolist()):
            m = self._models[e]
            d.qpos[:], d.qvel[:] = qp[k], qv[k]
            d.act[:] = 0
            d.qacc_warmstart[:] = 0
            d.time = 0.0
            mujoco.mj_forward(m, d)
            mujoco.mj_getState(m, d, self.state[e], self._spec)
            self.sensordata[e] = d.sensordata

    def set_velocity(self, env_ids: torch.Tensor, qvel: torch.Tensor) -> None:
        """Overwrite joint-space velocities of some envs (pushes)."""
        ids = env_ids.cpu().numpy()
        self._qvel(self.state)[ids] = qvel.double().cpu().numpy()

    def step(self, ctrl: torch.Tensor) -> EngineOutput:
        """Advance all envs by ctrl.shape[1] substeps; ctrl (N, nsub, nu) position targets."""
        c = np.asarray(ctrl.detach().numpy(), dtype=np.float64)  # a copy: float32 -> float64
        nsub = c.shape[1]
        if self._out_state is None or self._out_state.shape[1] != nsub:
            self._out_state = np.empty((self.num_envs, nsub, self.nstate))
            self._out_sens = np.empty((self.num_envs, nsub, self.sensordata.shape[1]))
        # Shapes are fixed and checked above, so the wrapper's per-call checks are skipped.
        self._rollout.rollout(
            self._models,
            self._datas,
            self.state,
            c,
            nstep=nsub,
            state=self._out_state,
            sensordata=self._out_sens,
            skip_checks=True,
            persistent_pool=True,
        )
        self.state = np.ascontiguousarray(self._out_state[:, -1])
        self.sensordata = np.ascontiguousarray(self._out_sens[:, -1])
        return self.read()

    def read(self) -> EngineOutput:
        # Float32 copies made by numpy: no torch op per array (playback steps one env).
        f32 = lambda a: torch.from_numpy(a.astype(np.float32))  # noqa: E731
        return EngineOutput(
            qpos=f32(self._qpos(self.state)),
            qvel=f32(self._qvel(self.state)),
            sensordata=f32(self.sensordata),
        )


def make_engine(name: str, num_envs: int, scene: SceneCfg, variants: np.ndarray) -> Engine:
    """`cpu` (native MuJoCo, mujoco.rollout) or `gpu` (MuJoCo Warp on CUDA)."""
    if name == "cpu":
        return CpuEngine(num_envs, scene, variants)
    if name == "gpu":
        from quaddance.sim.warp_engine import WarpEngine

        return WarpEngine(num_envs, scene, variants)
    raise ValueError(f"unknown engine {name!r}: use cpu or gpu")
