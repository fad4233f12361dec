"""An exported dance policy: ONNX actor + its JSON contract, run with ONNX Runtime."""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from quaddance.errors import InputFileError
from quaddance.sim.config import DanceTaskCfg, DomainRandCfg, ObsCfg, RewardCfg
from quaddance.sim.feedforward import LUT_HEIGHTS_M
from quaddance.sim.scene import SceneCfg


def shipped_policy_path() -> Path:
    """The policy that ships with the package (trained with `quaddance train`)."""
    return Path(str(resources.files("quaddance") / "data" / "policies" / "go1_dance.onnx"))


def task_cfg_from_json(task: dict) -> DanceTaskCfg:
    """Rebuild the task settings a policy was trained with (JSON `task` section)."""
    task = dict(task)
    scene = SceneCfg(**task.pop("scene"))
    rewards = RewardCfg(**task.pop("rewards"))
    dr = task.pop("domain_rand")
    dr = DomainRandCfg(**{k: tuple(v) if isinstance(v, list) else v for k, v in dr.items()})
    obs = task.pop("obs")
    obs = ObsCfg(**{k: tuple(v) if isinstance(v, list) else v for k, v in obs.items()})
    return DanceTaskCfg(scene=scene, rewards=rewards, domain_rand=dr, obs=obs, **task)


@dataclass
class OnnxPolicy:
    """Deterministic actor: `act(obs (B, D)) -> actions (B, 12)`."""

    onnx_path: Path
    meta: dict
    task: DanceTaskCfg

    @classmethod
    def load(cls, onnx_path: str | Path) -> OnnxPolicy:
        onnx_path = Path(onnx_path)
        json_path = onnx_path.with_suffix(".json")
        if not onnx_path.is_file():
            raise InputFileError(onnx_path, "no such policy file")
        if not json_path.is_file():
            raise InputFileError(json_path, "missing: a policy needs its JSON beside the .onnx")
        try:
            meta = json.loads(json_path.read_text())
            task = task_cfg_from_json(meta["task"])
            obs_dim = int(meta["obs"]["dim"])
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
            raise InputFileError(json_path, f"not a quaddance policy description ({err})") from err
        if task.front_feedforward:
            table = (meta.get("front_feedforward") or {}).get("thigh_calf_offsets_rad", [])
            if np.asarray(table, dtype=float).shape != (LUT_HEIGHTS_M.size, 2):
                raise InputFileError(
                    json_path, "front_feedforward.thigh_calf_offsets_rad is missing or malformed"
                )
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1  # tiny network: threads cost more than they give
        try:
            session = ort.InferenceSession(str(onnx_path), opts, providers=["CPUExecutionProvider"])
        except Exception as err:  # onnxruntime raises its own untyped errors
            raise InputFileError(onnx_path, f"not a readable ONNX model ({err})") from err
        inp = session.get_inputs()[0]
        if inp.shape[-1] != obs_dim:
            raise InputFileError(
                onnx_path, f"model takes {inp.shape[-1]} observations but its JSON says {obs_dim}"
            )
        policy = cls(onnx_path, meta, task)
        policy._session = session
        policy._input = inp.name
        return policy

    @property
    def obs_dim(self) -> int:
        return int(self.meta["obs"]["dim"])

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        return self._session.run(None, {self._input: obs})[0]
