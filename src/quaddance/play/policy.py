"""An exported dance policy: ONNX actor + its JSON contract, run with ONNX Runtime."""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from quaddance.errors import InputFileError
from quaddance.play.policy_spec import PolicySpec
from quaddance.robots import GO1, RobotCfg
from quaddance.sim.config import DanceTaskCfg


def shipped_policy_path(robot: RobotCfg = GO1) -> Path:
    """The policy for ``robot`` that ships with the package (trained with `quaddance train`)."""
    return Path(str(resources.files("quaddance") / "data" / "policies" / robot.policy))


@dataclass
class OnnxPolicy:
    """Deterministic actor: `act(obs (B, D)) -> actions (B, 12)`.

    ``spec`` is the checked JSON contract; ``meta`` the same as a plain dict.
    """

    onnx_path: Path
    meta: dict
    task: DanceTaskCfg
    spec: PolicySpec | None = None

    @classmethod
    def load(cls, onnx_path: str | Path) -> OnnxPolicy:
        onnx_path = Path(onnx_path)
        json_path = onnx_path.with_suffix(".json")
        if not onnx_path.is_file():
            raise InputFileError(onnx_path, "no such policy file")
        if not json_path.is_file():
            raise InputFileError(json_path, "missing: a policy needs its JSON beside the .onnx")
        spec = PolicySpec.load(json_path)
        obs_dim = spec.obs_dim
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1  # tiny network: threads cost more than they give
        try:
            session = ort.InferenceSession(str(onnx_path), opts, providers=["CPUExecutionProvider"])
        except Exception as err:  # onnxruntime raises its own untyped errors
            first = (str(err).strip().splitlines() or ["?"])[0][:200]
            raise InputFileError(onnx_path, f"not a readable ONNX model ({first})") from err
        inp = session.get_inputs()[0]
        if inp.shape[-1] != obs_dim:
            raise InputFileError(
                onnx_path, f"model takes {inp.shape[-1]} observations but its JSON says {obs_dim}"
            )
        policy = cls(onnx_path, spec.to_dict(), spec.task_cfg, spec)
        policy._session = session
        policy._input = inp.name
        return policy

    @property
    def obs_dim(self) -> int:
        return int(self.meta["obs"]["dim"])

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        return self._session.run(None, {self._input: obs})[0]
