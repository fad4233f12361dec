"""PPO training of the dance task with rsl-rl: presets, checkpoints, resume, ONNX export.

A run directory holds one run: `checkpoint.pt` (written atomically every few minutes and at
the end), `bank.npy` (the target bank, rebuilt from its seed if missing; `bank.json`: the
options it was built with), `curve.csv` (the learning curve), TensorBoard logs under `tb/`, and
at the end `policy.onnx` + `policy.json`. A new run refuses a folder with another run in it;
``--resume`` refuses options that change what the run learns (`run_start`).
"""

from __future__ import annotations

import contextlib
import copy
import csv
import dataclasses
import gzip
import io
import json
import math
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from quaddance import __version__
from quaddance.errors import InputFileError, OutputFileError, QuaddanceError
from quaddance.fileio import atomic_path, write_json
from quaddance.layout import row_width
from quaddance.play.policy_spec import FORMAT
from quaddance.sim import tasks
from quaddance.sim.config import DanceTaskCfg
from quaddance.sim.records import task_record


@dataclass(frozen=True)
class Preset:
    """Network sizes and PPO batch settings."""

    actor_hidden: tuple[int, ...]
    critic_hidden: tuple[int, ...]
    num_envs: int  # the envs it is sized for: the CLI's default `DanceTaskCfg.num_envs`
    num_steps_per_env: int
    num_learning_epochs: int
    num_mini_batches: int


PRESETS: dict[str, Preset] = {
    # The paper / released code (FACTS.md section 1-2): for GPUs.
    "paper": Preset((512, 256, 128), (512, 256, 128), 4096, 24, 5, 4),
    # Chosen by measurement on 2 cores (`quaddance bench train`): learning, not physics,
    # bounds CPU training, so smaller networks, fewer epochs and bigger mini-batches.
    "cpu": Preset((256, 128, 64), (256, 128, 64), 256, 24, 3, 2),
}


@dataclass
class TrainCfg:
    """A training run: its directory, PPO settings and target bank; the task (`task`, one of
    `quaddance.sim.tasks`'s variants) is trained as it is, envs and curriculum included."""

    run_dir: Path = Path("runs/dance")
    engine: str = "cpu"
    preset: str = "cpu"
    iterations: int = 1000
    seed: int = 1
    resume: bool = False
    bank_size: int = 256
    bank_duration_s: float = 32.0
    max_height_m: float | None = None  # feasible target bound; None: the robot's
    # How the bank's human dances become paw targets: "feasible", or "paper" (eq. 4,
    # h0_m * h / max(h), the paper's study of h0 in section 4.3.3).
    target_mode: str = "feasible"
    h0_m: float = 2.0  # eq. 4's h0 (the paper's headline value); only for target_mode "paper"
    checkpoint_every_s: float = 120.0
    max_minutes: float | None = None  # wall-clock budget of this call; stops cleanly
    torch_threads: int | None = None
    learning_rate: float = 1e-3  # FACTS.md section 1
    entropy_coef: float = 0.01
    # Start from another run's networks (its checkpoint.pt): inputs both tasks have keep
    # their weights, new ones (say the body targets of the whole-body task) start at zero
    # weight, so the new policy begins as the old one and PPO learns what the new inputs add.
    init_from: Path | None = None
    task: DanceTaskCfg = field(default_factory=tasks.paws_only)


def rsl_rl_cfg(preset: Preset, cfg: TrainCfg) -> dict:
    """The dict rsl-rl's PPO expects (gamma, lambda, clip from FACTS.md section 1)."""
    return {
        "num_steps_per_env": preset.num_steps_per_env,
        "obs_groups": {"actor": ["actor"], "critic": ["critic"]},
        "multi_gpu": None,
        "algorithm": {
            "class_name": "PPO",
            "num_learning_epochs": preset.num_learning_epochs,
            "num_mini_batches": preset.num_mini_batches,
            "clip_param": 0.2,
            "gamma": 0.99,
            "lam": 0.95,
            "value_loss_coef": 1.0,
            "entropy_coef": cfg.entropy_coef,
            "learning_rate": cfg.learning_rate,
            "max_grad_norm": 1.0,
            "use_clipped_value_loss": True,
            "schedule": "adaptive",
            "desired_kl": 0.01,
            "rnd_cfg": None,
            "symmetry_cfg": None,
        },
        "actor": {
            "class_name": "MLPModel",
            "hidden_dims": list(preset.actor_hidden),
            "activation": "elu",
            "obs_normalization": True,
            "distribution_cfg": {
                "class_name": "GaussianDistribution",
                "init_std": 1.0,
                "std_type": "scalar",
            },
        },
        "critic": {
            "class_name": "MLPModel",
            "hidden_dims": list(preset.critic_hidden),
            "activation": "elu",
            "obs_normalization": True,
        },
    }


def bank_options(cfg: TrainCfg) -> dict:
    """What decides a run's target bank (`build_bank`), as plain data."""
    record = {
        "bank_size": cfg.bank_size,
        "bank_duration_s": cfg.bank_duration_s,
        "seed": cfg.seed,
        "whole_body": cfg.task.whole_body,
        "robot": cfg.task.scene.robot.name,
        "targets": dataclasses.asdict(_target_cfg(cfg)),
    }
    return json.loads(json.dumps(record, default=str))


def build_bank(cfg: TrainCfg, progress=None) -> np.ndarray:
    """The target bank: built-in choreographies of synthetic songs, cached in the run dir
    (`bank.npy`, with the options it was built with in `bank.json`; other options, or a
    cache that does not read, build it again)."""
    from quaddance.pipeline import target_bank

    path, options_path = cfg.run_dir / "bank.npy", cfg.run_dir / "bank.json"
    width = row_width(cfg.task.whole_body)
    options = bank_options(cfg)
    with contextlib.suppress(Exception):  # a missing, stale or unreadable cache is rebuilt
        if json.loads(options_path.read_text()) == options:
            bank = np.load(path, allow_pickle=False)
            if bank.ndim == 3 and bank.shape[2] == width:
                return bank
    bank = target_bank(
        cfg.bank_size,
        cfg.bank_duration_s,
        seed=cfg.seed,
        cfg=_target_cfg(cfg),
        progress=progress,
        body=cfg.task.whole_body,
    )
    with atomic_path(path) as tmp:
        np.save(tmp, bank)
    write_json(options_path, options)
    return bank


def _transplant(old: dict, new: dict, old_cols: list[str], new_cols: list[str]) -> dict:
    """``new`` with ``old``'s weights: the first layer and the input normalizer column by
    column where the names match (new columns: zero weight, mean 0, variance 1); the other
    layers as they are (their shapes must match)."""
    out = dict(new)
    where = {name: i for i, name in enumerate(old_cols)}
    pairs = [(j, where[name]) for j, name in enumerate(new_cols) if name in where]
    if not pairs:
        raise ValueError("no observation in common")
    device = next(iter(new.values())).device
    dst = torch.tensor([j for j, _ in pairs], device=device)
    src = torch.tensor([i for _, i in pairs], device=device)
    for key, value in old.items():
        if key not in new:
            raise ValueError(f"{key} is not in this network")
        value = value.to(new[key].device)  # read on the CPU; the new run may be on a GPU
        if key == "mlp.0.weight":
            w = torch.zeros_like(new[key])
            w[:, dst] = value[:, src]
            out[key] = w
        elif key.startswith("obs_normalizer._"):
            fill = 0.0 if key.endswith("_mean") else 1.0
            v = torch.full_like(new[key], fill)
            v[:, dst] = value[:, src]
            out[key] = v
        else:
            if value.shape != new[key].shape:
                raise ValueError(f"{key}: shape {tuple(value.shape)} vs {tuple(new[key].shape)}")
            out[key] = value.clone()
    return out


def curriculum_scale_at(ramp: tuple[int, int] | None, env_steps: int) -> float:
    """0 before ``ramp[0]`` env steps, 1 from ``ramp[1]``, linear between; 1 without a ramp."""
    if ramp is None:
        return 1.0
    start, end = ramp
    if env_steps >= end:
        return 1.0
    if env_steps <= start:
        return 0.0
    return (env_steps - start) / (end - start)


#: Target modes a training bank can be made in (`quaddance.layout.MODES`).
TRAIN_MODES: tuple[str, ...] = ("feasible", "paper")


def _target_cfg(cfg: TrainCfg):
    from quaddance.targets import TargetConfig

    if cfg.target_mode not in TRAIN_MODES:
        raise QuaddanceError(
            f"unknown training target mode {cfg.target_mode!r}: use {', '.join(TRAIN_MODES)}"
        )
    return TargetConfig(
        mode=cfg.target_mode,
        h0_m=cfg.h0_m,
        max_height_m=cfg.max_height_m,
        robot=cfg.task.scene.robot,
    )


def targets_record(cfg: TrainCfg, bank: np.ndarray) -> dict:
    """The policy JSON's ``targets``: the highest feasible front target (the bank's own for a
    feasible bank, else the feasible bound it was not held to), and for an eq. 4 bank its mode
    and h0, with which playback makes the targets the policy learnt to track."""
    if cfg.target_mode == "feasible":
        return {"max_height_m": round(float(bank[..., :2].max()), 4)}
    return {
        "max_height_m": _target_cfg(cfg).max_height_m,
        "mode": cfg.target_mode,
        "h0_m": cfg.h0_m,
    }


def _config_dict(cfg: TrainCfg) -> dict:
    d = {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)}
    d["run_dir"] = str(cfg.run_dir)
    d["task"] = task_record(cfg.task)
    d["robot"] = cfg.task.scene.robot.name
    return d


RESUME_MAY_CHANGE = frozenset(
    {"run_dir", "resume", "iterations", "checkpoint_every_s", "max_minutes", "torch_threads",
     "init_from", "engine", "task.num_envs"}
)  # fmt: skip
"""Options a resumed run may change: how long and where it runs, not what it learns."""


def _differences(run: dict, now: dict, prefix: str = "") -> list[str]:
    """``key (run: a, now: b)`` for each option both records have and that differs."""
    out = []
    for key in run.keys() & now.keys():
        name = prefix + key
        if name in RESUME_MAY_CHANGE:
            continue
        if isinstance(run[key], dict) and isinstance(now[key], dict):
            out += _differences(run[key], now[key], name + ".")
        elif run[key] != now[key]:
            out.append(f"{name} (run: {run[key]}, now: {now[key]})")
    return sorted(out)


def read_checkpoint(path: Path, device: str = "cpu") -> dict:
    """A checkpoint's state, read by torch's weights-only unpickler (tensors and plain
    containers, never code); one line for a file that is not a quaddance checkpoint."""
    try:
        state = torch.load(path, map_location=device, weights_only=True)
    except Exception as err:  # torch.load raises many types for a foreign or corrupt file
        first = (str(err).strip().splitlines() or [""])[0][:160]
        raise InputFileError(
            path, f"not a quaddance checkpoint ({type(err).__name__}: {first})"
        ) from None
    if not isinstance(state, dict) or not isinstance(state.get("config_json"), str):
        raise InputFileError(path, "not a quaddance checkpoint (no run options in it)")
    return state


RunStart = tuple[dict | None, dict | None]
"""What `run_start` read: (the state ``--resume`` continues, the state ``--init-from`` starts
from)."""


def run_start(cfg: TrainCfg) -> RunStart:
    """Check the run folder and read the checkpoint the run starts from, before anything is
    built or written: (the state ``--resume`` continues, the state ``--init-from`` starts
    from); None where not asked for.

    Raises:
        InputFileError: a checkpoint is missing or unreadable, or ``--resume`` would change what
            the run learns (its task, robot, rewards, bank or PPO settings).
        OutputFileError: a new run would write over another run in its folder.
    """
    if cfg.resume:
        return _resumable(cfg, cfg.run_dir / "checkpoint.pt"), None
    _check_fresh_run_dir(cfg.run_dir)
    if cfg.init_from is None:
        return None, None
    if not Path(cfg.init_from).is_file():
        raise InputFileError(cfg.init_from, "no such checkpoint (--init-from)")
    return None, read_checkpoint(Path(cfg.init_from))


def _resumable(cfg: TrainCfg, path: Path) -> dict:
    """The checkpoint ``path`` of the run to continue, refused where ``cfg`` would change what
    the run learns."""
    if not path.exists():
        raise InputFileError(path, "no checkpoint to resume from (train without --resume)")
    state = read_checkpoint(path)
    try:
        run = json.loads(state["config_json"])
    except json.JSONDecodeError:
        raise InputFileError(path, "not a quaddance checkpoint (unreadable options)") from None
    now = json.loads(json.dumps(_config_dict(cfg), default=str))
    changed = _differences(run, now)
    if changed:
        raise InputFileError(
            path,
            "--resume continues a run with the options it was started with; these differ: "
            + "; ".join(changed)
            + " (to train with other options from its networks: a new --run-dir with "
            "--init-from this checkpoint)",
        )
    return state


class Trainer:
    """Owns the env, the PPO algorithm and the run directory."""

    def __init__(
        self,
        cfg: TrainCfg,
        bank: np.ndarray | None = None,
        log=print,
        start: RunStart | None = None,
    ) -> None:
        """``bank``: a target bank already built (None: `build_bank`); ``start``: what
        `run_start` read for ``cfg`` already (None: read it here)."""
        from quaddance.sim.task import DanceEnv

        self.cfg = cfg
        self.log = log
        if cfg.preset not in PRESETS:
            raise QuaddanceError(f"unknown preset {cfg.preset!r}: use {sorted(PRESETS)}")
        self.preset = PRESETS[cfg.preset]
        if not cfg.task.rewards:
            raise QuaddanceError(
                "the task has no reward terms: build it with quaddance.sim.tasks "
                f"({', '.join(tasks.TASKS)})"
            )
        if cfg.torch_threads:
            torch.set_num_threads(cfg.torch_threads)
        torch.manual_seed(cfg.seed)
        self.ckpt_path = cfg.run_dir / "checkpoint.pt"
        resumed, started_from = run_start(cfg) if start is None else start
        cfg.run_dir.mkdir(parents=True, exist_ok=True)
        self.bank = build_bank(cfg) if bank is None else bank
        self.env = DanceEnv(copy.deepcopy(cfg.task), self.bank, engine=cfg.engine, seed=cfg.seed)
        self.device = str(self.env.device)

        from rsl_rl.algorithms import PPO

        self.alg_cfg = rsl_rl_cfg(self.preset, cfg)
        obs = self.env.get_observations()
        # rsl-rl prints both networks in full; the run's policy.json describes them instead.
        with contextlib.redirect_stdout(io.StringIO()):
            self.alg = PPO.construct_algorithm(
                obs, self.env, copy.deepcopy(self.alg_cfg), self.device
            )
        self.iteration = 0
        self.env_steps = 0
        self.wall_s = 0.0
        curve = cfg.run_dir / "curve.csv"
        if resumed is None and curve.exists():
            # The curve of a run killed before its first checkpoint: kept aside, not continued.
            curve.replace(cfg.run_dir / "curve.unfinished.csv")
            log(f"{curve}: a run that left no checkpoint; its curve is now curve.unfinished.csv")
        if resumed is not None:
            self._load(self.ckpt_path, resumed)
        elif started_from is not None:
            self._init_from(Path(cfg.init_from), started_from)

    # --- checkpoints -------------------------------------------------------------------------
    def save(self) -> None:
        """Everything needed to continue: models, optimizer, normalizers, counters, RNG."""
        state = self.alg.save()
        state.update(
            iteration=self.iteration,
            env_steps=self.env_steps,
            wall_s=self.wall_s,
            torch_rng=torch.get_rng_state(),
            env_rng=self.env._gen.get_state(),
            config_json=json.dumps(_config_dict(self.cfg), default=str),
            version=__version__,
        )
        with atomic_path(self.ckpt_path) as tmp:
            torch.save(state, tmp)

    def _load(self, path: Path, state: dict) -> None:
        try:
            self.alg.load(state, None, strict=True)
            self.iteration = int(state["iteration"])
            self.env_steps = int(state["env_steps"])
            self.wall_s = float(state["wall_s"])
            torch.set_rng_state(state["torch_rng"])
            self.env._gen.set_state(state["env_rng"])
        except Exception as err:  # a checkpoint of another version or task fails in many ways
            if "size mismatch" in str(err):
                # A run of another task (say paws-only, resumed with --whole-body): its
                # networks cannot continue here, but they can start a new run.
                raise InputFileError(
                    path,
                    "its networks were trained for another observation (another task or "
                    "options); start a new run from it with --init-from instead of --resume",
                ) from err
            raise InputFileError(
                path, f"not a usable checkpoint for this task ({type(err).__name__}: {err})"
            ) from err
        # Rows written after the checkpoint (a run killed between two checkpoints) are redone.
        _truncate_curve(self.cfg.run_dir / "curve.csv", self.iteration)
        self.log(f"resumed {path} at iteration {self.iteration} ({self.env_steps:,} env steps)")

    def _init_from(self, path: Path, state: dict) -> None:
        """Copy another run's actor and critic (``state``, read from ``path``), input column by
        input column (by name)."""
        from quaddance.sim.observations import ActorObservation, ObsLayout
        from quaddance.sim.records import task_from_record

        try:
            record = json.loads(state["config_json"])["task"]
            old_task = task_from_record(record, self.cfg.task.scene.robot)
            old_names = ObsLayout.of(
                ActorObservation(old_task, 1).layout,
                self.env.privileged_slices,
                old_task.obs.privileged_critic,
            ).column_names()
            ours = self.env.obs_layout.column_names()
            new_state = self.alg.save()
            for key, group in (("actor_state_dict", "actor"), ("critic_state_dict", "critic")):
                new_state[key] = _transplant(
                    state[key], new_state[key], old_names[group], ours[group]
                )
            self.alg.load(new_state, {"actor": True, "critic": True}, strict=True)
        except (KeyError, TypeError, ValueError, RuntimeError, json.JSONDecodeError) as err:
            raise InputFileError(
                path, f"cannot start from this checkpoint ({type(err).__name__}: {err})"
            ) from err
        shared = len(set(old_names["actor"]) & set(ours["actor"]))
        self.log(f"started from {path}: {shared} of {len(ours['actor'])} actor inputs carried over")

    # --- learning ------------------------------------------------------------------------------
    def curriculum_now(self) -> float:
        """The curriculum's scale at this run's env-step count."""
        return curriculum_scale_at(self.cfg.task.curriculum_env_steps, self.env_steps)

    def learn(self, iterations: int, progress: bool = True) -> list[dict]:
        """Run `iterations` more PPO iterations; returns the learning-curve rows."""
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(log_dir=str(self.cfg.run_dir / "tb"), purge_step=self.iteration)
        curve_path = self.cfg.run_dir / "curve.csv"
        restore_sigterm = _sigterm_as_interrupt()
        rows: list[dict] = []
        obs = self.env.get_observations().to(self.device)
        self.alg.train_mode()
        steps = self.preset.num_steps_per_env
        last_ckpt = time.monotonic()
        deadline = (
            None if self.cfg.max_minutes is None else time.monotonic() + 60 * self.cfg.max_minutes
        )
        bar = _progress_bar(progress)
        task_id = bar.add_task("training", total=iterations) if bar else None
        if bar:
            bar.start()
        try:
            for _ in range(iterations):
                t0 = time.monotonic()
                self.env.curriculum_scale = self.curriculum_now()
                sums: dict = {}  # tensors while collecting, floats after
                ep_reward = torch.zeros(self.env.num_envs, device=self.device)
                with torch.inference_mode():
                    for _ in range(steps):
                        actions = self.alg.act(obs)
                        obs, rew, dones, extras = self.env.step(actions)
                        self.alg.process_env_step(obs, rew, dones, extras)
                        ep_reward += rew
                        # Summed where they are (on a GPU, float() each step would wait)
                        for k, v in extras["log"].items():
                            sums[k] = sums.get(k, 0.0) + v
                    sums = {k: float(v) for k, v in sums.items()}
                    self.alg.compute_returns(obs)
                t1 = time.monotonic()
                losses = self.alg.update()
                t2 = time.monotonic()
                # Counters and the curve row together: a signal in between would leave a
                # checkpoint of an iteration without its row, so it waits until both are done.
                with _signals_deferred():
                    self.iteration += 1
                    self.env_steps += steps * self.env.num_envs
                    self.wall_s += t2 - t0
                    row = self._curve_row(sums, steps, ep_reward, losses, t1 - t0, t2 - t1)
                    _append_csv(curve_path, row)
                rows.append(row)
                for k, v in row.items():
                    if k not in ("iteration",):
                        writer.add_scalar(k, v, self.iteration)
                writer.add_scalar("curriculum_scale", self.env.curriculum_scale, self.iteration)
                if bar:
                    bar.update(
                        task_id,
                        advance=1,
                        description=(
                            f"it {self.iteration} | reward/step {row['reward_per_step']:.3f} | "
                            f"front err {100 * row['front_abs_err_m']:.1f} cm | "
                            f"falls/ep {row['fall_rate']:.2f} | "
                            f"{row['env_steps_per_s']:.0f} steps/s"
                        ),
                    )
                if time.monotonic() - last_ckpt > self.cfg.checkpoint_every_s:
                    self.save()
                    self.export()  # a usable policy at every checkpoint, not only at the end
                    last_ckpt = time.monotonic()
                if deadline is not None and time.monotonic() > deadline:
                    self.log(f"time budget of {self.cfg.max_minutes} min reached")
                    break
        finally:
            if bar:
                bar.stop()
            self.save()  # also on Ctrl-C or `kill`: the run resumes from here
            writer.close()
            restore_sigterm()
        return rows

    def _curve_row(self, sums, steps, ep_reward, losses, collect_s, learn_s) -> dict:
        ended = sums.get("/metrics/episodes_ended", 0.0)
        falls = sums.get("/metrics/falls", 0.0)
        n = self.env.num_envs
        return {
            "iteration": self.iteration,
            "env_steps": self.env_steps,
            "wall_s": round(self.wall_s, 2),
            "reward_per_step": float(ep_reward.mean()) / steps,
            "front_abs_err_m": sums.get("/metrics/front_abs_err_m", 0.0) / steps,
            "rear_lift_m": sums.get("/metrics/rear_lift_m", 0.0) / steps,
            # falls per ended episode; also per env-minute, which stays defined when none end
            "fall_rate": falls / ended if ended else 0.0,
            "falls_per_env_min": falls / (n * steps * self.cfg.task.step_dt_s / 60.0),
            "env_steps_per_s": steps * n / max(collect_s + learn_s, 1e-9),
            "collect_s": collect_s,
            "learn_s": learn_s,
            "value_loss": float(losses.get("value", losses.get("value_function", math.nan))),
            "surrogate_loss": float(losses.get("surrogate", math.nan)),
            "action_std": float(self.alg.get_policy().output_std.detach().mean()),
        }

    # --- export ------------------------------------------------------------------------------
    def export(self, out_dir: Path | None = None) -> tuple[Path, Path]:
        """Write `policy.onnx` and `policy.json` (what playback and deployment need)."""
        out_dir = out_dir or self.cfg.run_dir
        onnx_path, json_path = out_dir / "policy.onnx", out_dir / "policy.json"
        export_onnx(self.alg.get_policy(), onnx_path)
        from quaddance.play.policy_spec import PolicySpec

        # Through the one class that reads it back: an export that would not load fails here.
        PolicySpec.from_dict(policy_metadata(self.env, self.cfg, self), json_path).save(json_path)
        curve = self.cfg.run_dir / "curve.csv"
        if curve.exists():
            from quaddance.play.plots import plot_learning_curve

            plot_learning_curve(out_dir / "curve.png", curve)
        return onnx_path, json_path


def export_onnx(policy, path: Path) -> None:
    """Deterministic actor (normaliser included) as ONNX: input `obs` (B, D) -> `actions`."""
    model = policy.as_onnx(verbose=False).to("cpu").eval()
    with atomic_path(path) as tmp:
        torch.onnx.export(
            model,
            model.get_dummy_inputs(),
            str(tmp),
            export_params=True,
            opset_version=18,
            input_names=model.input_names,
            output_names=model.output_names,
            dynamo=False,
            dynamic_axes={name: {0: "batch"} for name in (*model.input_names, *model.output_names)},
        )


def policy_metadata(env, cfg: TrainCfg, trainer: Trainer | None = None) -> dict:
    """The policy's contract with playback and a real robot."""
    task = env.cfg
    robot = task.scene.robot
    return {
        "format": FORMAT,
        "version": __version__,
        "robot": robot.name,
        "joint_names": list(robot.joint_names),
        "feet": list(robot.feet),
        "foot_height": "height of the foot sphere's bottom above the floor, m",
        "nominal_joint_pos_rad": list(robot.nominal_joint_pos_rad),
        "action_scale": env.action_scale.cpu().tolist(),
        "joint_target": (
            "nominal_joint_pos_rad + action_scale * action"
            + (" + front_feedforward(front targets 1 policy step ahead)" if env.feedforward else "")
        ),
        "front_feedforward": None
        if env.feedforward is None
        else {
            "heights_m": robot.front_lift.heights_m.tolist(),
            "thigh_calf_offsets_rad": env.feedforward.table.cpu().tolist(),
            "applies_to": list(robot.feet[:2]),
            "interpolation": "linear in height, clamped to the table",
        },
        "kp": task.scene.kp,
        "kd": task.scene.kd,
        "policy_hz": task.policy_hz,
        "sim_dt_s": task.scene.timestep_s,
        "decimation": task.decimation,
        "obs": {
            "terms": [dataclasses.asdict(s) for s in env.obs_layout.actor],
            "dim": env.obs_layout.actor_dim,
            "preview_s": list(task.obs.preview_s),
            "history_len": task.obs.history_len,
            "normalization": "inside the ONNX model (running mean/std)",
        },
        "task": task_record(task),  # the task as trained (reward terms, envs, ...)
        # The targets the policy trained on: playback makes the same kind, in the same range.
        "targets": targets_record(cfg, env.bank),
        "training": {
            "engine": cfg.engine,
            "preset": cfg.preset,
            "iterations": trainer.iteration if trainer else None,
            "env_steps": trainer.env_steps if trainer else None,
            "wall_s": round(trainer.wall_s, 1) if trainer else None,
            "num_envs": env.num_envs,
            "seed": cfg.seed,
            # below 1: exported mid-curriculum, trained on smaller trunk motion than the dance's
            "curriculum_scale": env.curriculum_scale,
        },
    }


class _Deferral:
    """While ``active``, a SIGINT/SIGTERM is kept in ``pending`` and acted on at the end."""

    def __init__(self) -> None:
        self.active = False
        self.pending: tuple[int, object] | None = None
        self.previous: dict[int, object] = {}


_DEFER = _Deferral()


def _act_on_signal(signum: int, frame: object) -> None:
    """What the signal did before training took it over (the CLI's handler records it for the
    exit status and raises), else KeyboardInterrupt: the final checkpoint gets written."""
    previous = _DEFER.previous.get(signum)
    if callable(previous):
        previous(signum, frame)
    raise KeyboardInterrupt(f"signal {signum}")


def _sigterm_as_interrupt():
    """Make SIGINT and SIGTERM raise KeyboardInterrupt (so the final checkpoint is written),
    except inside `_signals_deferred`, which acts on them when it ends; returns a function
    that restores the previous handlers."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def interrupt(signum, frame):
        if _DEFER.active:
            _DEFER.pending = (signum, frame)
            return
        _act_on_signal(signum, frame)

    _DEFER.previous = {
        sig: signal.signal(sig, interrupt) for sig in (signal.SIGINT, signal.SIGTERM)
    }

    def restore() -> None:
        for sig, handler in _DEFER.previous.items():
            signal.signal(sig, handler)

    return restore


@contextlib.contextmanager
def _signals_deferred():
    """A block that SIGINT and SIGTERM do not cut short: they are acted on after it."""
    _DEFER.active = True
    try:
        yield
    finally:
        _DEFER.active = False
        if _DEFER.pending is not None:
            signum, frame = _DEFER.pending
            _DEFER.pending = None
            _act_on_signal(signum, frame)


def _check_fresh_run_dir(run_dir: Path) -> None:
    """A new run must not write over another run's checkpoint. (A curve without one is of a
    run killed before its first checkpoint, which cannot be continued: `Trainer` sets it
    aside and starts the curve again.)"""
    if (run_dir / "checkpoint.pt").exists():
        raise OutputFileError(
            run_dir,
            "holds another run (checkpoint.pt); continue it with --resume, or train in a new "
            "--run-dir",
        )


def _truncate_curve(path: Path, iteration: int) -> None:
    """Keep the rows of `curve.csv` up to ``iteration`` (written atomically)."""
    if not path.exists():
        return
    lines = path.read_text().splitlines(keepends=True)

    def up_to(line: str) -> bool:
        try:
            return int(float(line.split(",", 1)[0])) <= iteration
        except ValueError:  # a row cut short by the kill
            return False

    keep = lines[:1] + [ln for ln in lines[1:] if up_to(ln)]
    if len(keep) < len(lines):
        with atomic_path(path) as tmp:
            tmp.write_text("".join(keep))


def _append_csv(path: Path, row: dict) -> None:
    new = not path.exists()
    with path.open("a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow(row)


def read_curve(path: Path) -> dict[str, np.ndarray]:
    """A run's `curve.csv` (or `.csv.gz`) as columns of floats."""
    try:
        raw = path.read_bytes()
        text = gzip.decompress(raw).decode() if path.suffix == ".gz" else raw.decode()
        rows = list(csv.DictReader(io.StringIO(text)))
        cols = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    except (OSError, ValueError, IndexError, KeyError, gzip.BadGzipFile, EOFError) as err:
        raise InputFileError(path, f"not a readable learning curve ({err})") from err
    if "env_steps" not in cols or "front_abs_err_m" not in cols:
        raise InputFileError(path, "learning curve lacks env_steps or front_abs_err_m")
    return cols


def _progress_bar(enabled: bool):
    if not enabled:
        return None
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )

    return Progress(
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn()
    )


def train(
    cfg: TrainCfg,
    progress: bool = True,
    log=print,
    bank: np.ndarray | None = None,
    start: RunStart | None = None,
) -> Trainer:
    """Train (or continue) and export; returns the trainer. ``bank`` and ``start`` as
    `Trainer` takes them."""
    trainer = Trainer(cfg, bank=bank, log=log, start=start)
    todo = cfg.iterations - trainer.iteration if cfg.resume else cfg.iterations
    if todo > 0:
        trainer.learn(todo, progress=progress)
    trainer.export()
    return trainer
