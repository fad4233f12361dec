"""What the dance task needs of a physics engine (`Engine`), what an engine returns
(`EngineOutput`), and the dynamics variants every engine builds.

The engines are `sim.engines.CpuEngine` (native MuJoCo) and `sim.warp_engine.WarpEngine`
(MuJoCo Warp); `sim.engines.make_engine` picks one by name. Both step N copies of the same
scene with per-env controls and return (qpos, qvel, sensordata) as torch tensors, which
`quaddance.sim.state.state_from_arrays` turns into the task's state. Domain randomisation of
the dynamics picks, per env, one of K variants (rows of friction, added base mass, motor
strength) built once.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import mujoco
import numpy as np
import torch

from quaddance.sim.scene import SceneCfg
from quaddance.sim.state import SensorLayout

# Columns of a dynamics variant row.
FRICTION, ADDED_MASS_KG, MOTOR_STRENGTH = 0, 1, 2


def nominal_dynamics(scene: SceneCfg) -> np.ndarray:
    """(1, 3) the unrandomised robot: the scene's friction, no added mass, full strength."""
    return np.array([[scene.foot_friction, 0.0, 1.0]])


def robot_collision_geoms(model: mujoco.MjModel) -> list[int]:
    """Ids of every robot geom that can touch the floor (feet, and calves when kneeling)."""
    return [i for i in range(model.ngeom) if "_collision" in (model.geom(i).name or "")]


@dataclass
class EngineOutput:
    """The state of all envs after a step (or at `Engine.read`)."""

    qpos: torch.Tensor  # (N, nq)
    qvel: torch.Tensor  # (N, nv)
    sensordata: torch.Tensor  # (N, nsensordata)


class Engine(Protocol):
    """N copies of the scene, stepped together with per-env joint position targets."""

    name: str  #: "cpu" or "gpu", as `make_engine` takes it
    num_envs: int
    device: torch.device  #: where `EngineOutput`'s tensors live
    model: mujoco.MjModel  #: the nominal model (sizes, keyframes, sensor addresses)
    layout: SensorLayout  #: where each sensor sits in ``sensordata``
    variants: np.ndarray  #: (K, 3) dynamics variant rows (`FRICTION`, ...)
    nq: int
    nv: int
    nu: int

    def step(self, ctrl: torch.Tensor) -> EngineOutput:
        """Advance all envs by ``ctrl.shape[1]`` substeps; ctrl (N, nsub, nu) targets."""
        ...

    def read(self) -> EngineOutput:
        """The current state of all envs."""
        ...

    def reset(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        """Set the state of some envs and recompute their sensors."""
        ...

    def set_velocity(self, env_ids: torch.Tensor, qvel: torch.Tensor) -> None:
        """Overwrite joint-space velocities of some envs (pushes)."""
        ...

    def set_variants(self, env_ids: torch.Tensor, variant_idx: torch.Tensor) -> None:
        """Give some envs the dynamics of the variants ``variant_idx`` (rows of `variants`)."""
        ...
