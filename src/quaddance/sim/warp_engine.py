"""MuJoCo Warp engine: all envs as worlds of one batched model, stepped by a CUDA graph.

Same scene, same (qpos, qvel, sensordata) output as `CpuEngine`; runs on CUDA, or on the
CPU through Warp's CPU backend (slow to compile, used by the engine-agreement test).
"""

from __future__ import annotations

import numpy as np
import torch

from quaddance.sim.engine import (
    ADDED_MASS_KG,
    FRICTION,
    MOTOR_STRENGTH,
    EngineOutput,
    nominal_dynamics,
    robot_collision_geoms,
)
from quaddance.sim.scene import SceneCfg, build_model
from quaddance.sim.state import SensorLayout

# Model fields that differ per world (domain randomisation).
_BATCHED = ("geom_friction", "body_mass", "actuator_gainprm", "actuator_biasprm")
CONTACTS_PER_WORLD = 32
ROWS_PER_WORLD = 160


class WarpEngine:
    """All envs as the worlds of one batched MuJoCo Warp model (see the module)."""

    name = "gpu"

    def __init__(
        self,
        num_envs: int,
        scene: SceneCfg = SceneCfg(),
        variants: np.ndarray | None = None,
        device: str | None = None,
        nsub_capture: int = 4,
    ) -> None:
        import mujoco
        import mujoco_warp as mjw
        import warp as wp

        wp.config.log_level = wp.LOG_WARNING  # no banner, no line per module loaded
        wp.init()
        self._wp, self._mjw = wp, mjw
        wp_device = device or ("cuda:0" if wp.is_cuda_available() else "cpu")
        self.wp_device = wp_device
        self.device = torch.device("cuda" if wp_device.startswith("cuda") else "cpu")
        self.num_envs = num_envs
        mjm = build_model(scene, visual=False)
        self.model = mjm
        self.layout = SensorLayout.from_model(mjm, scene.robot)
        self.nq, self.nv, self.nu = mjm.nq, mjm.nv, mjm.nu
        mjd = mujoco.MjData(mjm)
        mujoco.mj_resetDataKeyframe(mjm, mjd, mjm.key("home").id)
        mujoco.mj_forward(mjm, mjd)
        with wp.ScopedDevice(wp_device):
            self.m = mjw.put_model(mjm, batch_sizes=dict.fromkeys(_BATCHED, num_envs))
            # Both per world. Contacts: 4 feet plus body parts when fallen (a world may
            # borrow from the others' share); constraint rows: 4 per contact plus joint limits.
            self.d = mjw.put_data(
                mjm, mjd, nworld=num_envs, nconmax=CONTACTS_PER_WORLD, njmax=ROWS_PER_WORLD
            )
        t = wp.to_torch
        self.qpos, self.qvel = t(self.d.qpos), t(self.d.qvel)
        self.sensordata = t(self.d.sensordata)
        self._ctrl = t(self.d.ctrl)
        self._warmstart = t(self.d.qacc_warmstart)
        self._friction = t(self.m.geom_friction)
        self._mass = t(self.m.body_mass)
        self._gain = t(self.m.actuator_gainprm)
        self._bias = t(self.m.actuator_biasprm)
        self._defaults = {
            "friction": self._friction[0].clone(),
            "mass": self._mass[0].clone(),
            "gain": self._gain[0].clone(),
            "bias": self._bias[0].clone(),
        }
        self._contact_geoms = torch.as_tensor(robot_collision_geoms(mjm), device=self.device)
        self._trunk = mjm.body(scene.robot.trunk_body).id
        rows = nominal_dynamics(scene) if variants is None else np.asarray(variants)
        self.variants = rows
        self._variants = torch.as_tensor(rows, dtype=torch.float32, device=self.device)
        self.variant_idx = torch.zeros(num_envs, dtype=torch.long, device=self.device)
        # Per-substep control buffers, copied into d.ctrl inside the captured graph.
        self._ctrl_bufs = [
            wp.zeros((num_envs, self.nu), dtype=float, device=wp_device)
            for _ in range(nsub_capture)
        ]
        self._ctrl_views = [t(b) for b in self._ctrl_bufs]
        self._graph = None
        self._forward_graph = None
        self._capture()
        self.set_variants(torch.arange(num_envs), torch.zeros(num_envs, dtype=torch.long))

    def _run_substeps(self) -> None:
        for buf in self._ctrl_bufs:
            self._wp.copy(self.d.ctrl, buf)
            self._mjw.step(self.m, self.d)

    def _capture(self) -> None:
        wp = self._wp
        if not self.wp_device.startswith("cuda"):
            return
        with wp.ScopedDevice(self.wp_device):
            self._run_substeps()  # warm-up compiles the kernels outside the capture
            with wp.ScopedCapture() as cap:
                self._run_substeps()
            self._graph = cap.graph
            with wp.ScopedCapture() as cap:
                self._mjw.forward(self.m, self.d)
            self._forward_graph = cap.graph

    def set_variants(self, env_ids: torch.Tensor, variant_idx: torch.Tensor) -> None:
        ids = torch.as_tensor(env_ids, device=self.device)
        v = self._variants[torch.as_tensor(variant_idx, device=self.device)]
        self.variant_idx[ids] = torch.as_tensor(variant_idx, device=self.device)
        dflt = self._defaults
        fr = dflt["friction"].repeat(len(ids), 1, 1)
        fr[:, self._contact_geoms, 0] = v[:, FRICTION : FRICTION + 1]
        self._friction[ids] = fr
        mass = dflt["mass"].repeat(len(ids), 1)
        mass[:, self._trunk] += v[:, ADDED_MASS_KG]
        self._mass[ids] = mass
        s = v[:, MOTOR_STRENGTH, None]
        gain = dflt["gain"].repeat(len(ids), 1, 1)
        gain[:, :, 0] *= s
        self._gain[ids] = gain
        bias = dflt["bias"].repeat(len(ids), 1, 1)
        bias[:, :, 1] *= s
        bias[:, :, 2] *= s
        self._bias[ids] = bias

    def reset(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        ids = torch.as_tensor(env_ids, device=self.device)
        self.qpos[ids] = qpos.to(self.device, self.qpos.dtype)
        self.qvel[ids] = qvel.to(self.device, self.qvel.dtype)
        self._warmstart[ids] = 0.0
        keep = self.sensordata.clone()
        self._forward()
        # Only the reset worlds get fresh sensors, as in CpuEngine.
        mask = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        mask[ids] = True
        self.sensordata.copy_(torch.where(mask[:, None], self.sensordata, keep))

    def set_velocity(self, env_ids: torch.Tensor, qvel: torch.Tensor) -> None:
        self.qvel[torch.as_tensor(env_ids, device=self.device)] = qvel.to(
            self.device, self.qvel.dtype
        )

    def _forward(self) -> None:
        if self._forward_graph is not None:
            self._wp.capture_launch(self._forward_graph)
        else:
            with self._wp.ScopedDevice(self.wp_device):
                self._mjw.forward(self.m, self.d)

    def step(self, ctrl: torch.Tensor) -> EngineOutput:
        """ctrl (N, nsub, nu) with nsub equal to the captured substep count."""
        if ctrl.shape[1] != len(self._ctrl_bufs):
            raise ValueError(
                f"engine captured {len(self._ctrl_bufs)} substeps, got {ctrl.shape[1]}"
            )
        for j, view in enumerate(self._ctrl_views):
            view.copy_(ctrl[:, j])
        if self._graph is not None:
            self._wp.capture_launch(self._graph)
        else:
            with self._wp.ScopedDevice(self.wp_device):
                self._run_substeps()
        return self.read()

    def read(self) -> EngineOutput:
        # Copies: the Warp buffers change in place at the next step.
        return EngineOutput(
            qpos=self.qpos.float().clone(),
            qvel=self.qvel.float().clone(),
            sensordata=self.sensordata.float().clone(),
        )
