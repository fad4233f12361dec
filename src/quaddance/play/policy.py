"""An exported dance policy: ONNX actor + its JSON contract, run with ONNX Runtime."""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from quaddance.errors import InputFileError, QuaddanceError, not_a_file
from quaddance.play.policy_spec import PolicySpec
from quaddance.robots import GO1, RobotCfg, get_robot
from quaddance.sim.config import DanceTaskCfg


def _shipped_dir() -> Path:
    return Path(str(resources.files("quaddance") / "data" / "policies"))


def policy_label(policy: str | Path | None) -> str:
    """How reports name a policy: a shipped one as ``shipped (FILE)`` (not the path of this
    machine's install), another by the path it was given as; None is the shipped Go1's."""
    if policy is None:
        return f"shipped ({GO1.policy})"
    path = Path(policy)
    if path.parent.resolve() == _shipped_dir().resolve():
        return f"shipped ({path.name})"
    return str(path)


def shipped_policy_path(robot: RobotCfg = GO1) -> Path:
    """The policy for ``robot`` that ships with the package (trained with `quaddance train`);
    one line naming the robot and the path where the package has none."""
    path = _shipped_dir() / robot.policy
    if not path.is_file():
        raise QuaddanceError(
            f"no {robot.short_name} policy ships with this quaddance ({path} is missing); "
            "give one with --policy"
        )
    return path


def choose_policy(robot: str | None, policy: Path | None) -> tuple[RobotCfg, Path]:
    """The robot and the policy file of ``--robot`` and ``--policy``: without a policy, the
    robot's shipped one (the Go1's when neither is given); with a policy alone, the robot
    its JSON names; with both, they must agree (else one line naming both)."""
    if policy is None:
        cfg = GO1 if robot is None else get_robot(robot)
        return cfg, shipped_policy_path(cfg)
    own = get_robot(_read_spec(Path(policy)).robot)
    if robot is not None:
        require_robot(own, Path(policy), get_robot(robot), f"--robot {robot}")
    return own, Path(policy)


def require_robot(own: RobotCfg, path: Path, robot: RobotCfg, asked_by: str) -> None:
    """Refuse, in one line, to run the policy at ``path`` (trained for ``own``) on ``robot``,
    which ``asked_by`` chose, when the two differ."""
    if own.name != robot.name:
        raise InputFileError(
            path, f"a policy for {own.short_name}, not for {robot.short_name} ({asked_by})"
        )


def _read_spec(onnx_path: Path) -> PolicySpec:
    """The checked JSON contract beside ``onnx_path`` (both files must be there)."""
    json_path = onnx_path.with_suffix(".json")
    if not onnx_path.is_file():
        raise not_a_file(onnx_path)
    if not json_path.is_file():
        raise InputFileError(json_path, "missing: a policy needs its JSON beside the .onnx")
    return PolicySpec.load(json_path)


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
        spec = _read_spec(onnx_path)
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
    def robot(self) -> RobotCfg:
        """The robot the policy was trained for (its JSON's ``robot``)."""
        return self.task.scene.robot

    def require_robot(self, robot: RobotCfg, asked_by: str) -> None:
        """Refuse, in one line, to run this policy on ``robot`` (which ``asked_by`` chose)
        when it was trained for another (`require_robot`)."""
        require_robot(self.robot, self.onnx_path, robot, asked_by)

    @property
    def obs_dim(self) -> int:
        return int(self.meta["obs"]["dim"])

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        return self._session.run(None, {self._input: obs})[0]
