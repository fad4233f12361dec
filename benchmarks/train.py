"""`quaddance bench train`: env-only and end-to-end PPO env steps/s on the engine at hand,
with mjlab's own Go1 velocity task measured in the same run for comparison."""

from __future__ import annotations

import os
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from quaddance.fileio import write_json


def _bench_bank() -> np.ndarray:
    """A small bank with regular lifts (building the real one is not what is timed)."""
    t = np.arange(1600) / 50.0
    bank = np.zeros((4, 1600, 4), np.float32)
    bank[:, :, 0] = 0.15 * np.clip(np.sin(2 * np.pi * 0.5 * t), 0, None) ** 2
    bank[:, :, 1] = 0.15 * np.clip(-np.sin(2 * np.pi * 0.5 * t), 0, None) ** 2
    return bank


def env_only(engine: str, num_envs: int, steps: int) -> float:
    """Env steps/s of the dance task with random actions (physics + task code)."""
    from quaddance.sim import tasks
    from quaddance.sim.task import DanceEnv

    env = DanceEnv(tasks.paws_only(num_envs=num_envs), _bench_bank(), engine=engine)
    actions = torch.zeros(num_envs, 12, device=env.device)
    for _ in range(3):  # warm-up (kernel compilation, thread pools)
        env.step(actions)
    _sync(env.device)
    start = time.perf_counter()
    for _ in range(steps):
        env.step(actions.normal_(0.0, 0.5))
    _sync(env.device)
    return steps * num_envs / (time.perf_counter() - start)


def end_to_end(engine: str, preset: str, num_envs: int, iterations: int) -> dict[str, float]:
    """PPO env steps/s (collection + learning), after one warm-up iteration."""
    from quaddance.sim import tasks
    from quaddance.train import TrainCfg, Trainer

    with tempfile.TemporaryDirectory() as tmp:
        task = tasks.paws_only(num_envs=num_envs)
        cfg = TrainCfg(run_dir=Path(tmp), engine=engine, preset=preset, task=task)
        trainer = Trainer(cfg, bank=_bench_bank(), log=lambda *a: None)
        trainer.learn(1, progress=False)
        rows = trainer.learn(iterations, progress=False)
    collect = sum(r["collect_s"] for r in rows)
    learn = sum(r["learn_s"] for r in rows)
    steps = iterations * trainer.preset.num_steps_per_env * num_envs
    return {
        "env_steps_per_s": steps / (collect + learn),
        "collect_s_per_iter": collect / iterations,
        "learn_s_per_iter": learn / iterations,
    }


def mjlab_go1(num_envs: int, steps: int, device: str) -> float | None:
    """Env steps/s of mjlab's `Mjlab-Velocity-Flat-Unitree-Go1` with random actions."""
    try:
        import mjlab.tasks  # noqa: F401  (registers the tasks)
        from mjlab.envs import ManagerBasedRlEnv
        from mjlab.tasks.registry import load_env_cfg

        cfg = load_env_cfg("Mjlab-Velocity-Flat-Unitree-Go1")
        cfg.scene.num_envs = num_envs
        env = ManagerBasedRlEnv(cfg=cfg, device=device)
        env.reset()
        actions = torch.zeros(num_envs, env.action_manager.total_action_dim, device=device)
        for _ in range(3):
            env.step(actions)
        _sync(torch.device(device))
        start = time.perf_counter()
        for _ in range(steps):
            env.step(actions.normal_(0.0, 0.5))
        _sync(torch.device(device))
        rate = steps * num_envs / (time.perf_counter() - start)
        env.close()
        return rate
    except Exception as err:  # a comparison only: report, don't fail the benchmark
        print(f"mjlab comparison skipped: {type(err).__name__}: {err}")
        return None


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


def run_train_bench(
    out: Path,
    engine: str,
    env_counts: tuple[int, ...],
    preset: str,
    iterations: int = 3,
    env_steps: int = 50,
    mjlab: bool = True,
) -> dict[str, Any]:
    results: dict[str, Any] = {
        "engine": engine,
        "preset": preset,
        "machine": {
            "cpu_count": os.cpu_count(),
            "platform": platform.platform(),
            "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
            "torch_threads": torch.get_num_threads(),
        },
        "by_num_envs": {},
    }
    for n in env_counts:
        row = {"env_only_steps_per_s": env_only(engine, n, env_steps)}
        row.update({f"ppo_{k}": v for k, v in end_to_end(engine, preset, n, iterations).items()})
        if mjlab:
            device = "cuda:0" if engine == "gpu" else "cpu"
            row["mjlab_go1_velocity_env_only_steps_per_s"] = mjlab_go1(
                n, env_steps if engine == "gpu" else 5, device
            )
        results["by_num_envs"][str(n)] = row
        print(f"{n} envs: {row}")
    write_json(out, results)
    return results
