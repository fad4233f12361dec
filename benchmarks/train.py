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


def noisy_home(model, n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(n, nq) home poses with joint noise and (n, nv) small random velocities."""
    gen = torch.Generator().manual_seed(seed)
    qpos = torch.tensor(model.key("home").qpos, dtype=torch.float32).repeat(n, 1)
    qpos[:, 7:] += (torch.rand(n, model.nq - 7, generator=gen) * 2 - 1) * 0.1
    qvel = (torch.rand(n, model.nv, generator=gen) * 2 - 1) * 0.2
    return qpos, qvel


def random_controls(n: int, steps: int, seed: int, substeps: int = 4) -> torch.Tensor:
    """(steps, n, substeps, 12) Go1 joint targets around the nominal pose, rad."""
    from quaddance.robots import GO1

    gen = torch.Generator().manual_seed(seed)
    nominal = torch.tensor(GO1.nominal_joint_pos_rad)
    noise = (torch.rand(steps, n, substeps, GO1.num_joints, generator=gen) * 2 - 1) * 0.3
    return nominal + noise


def engine_gaps(
    rows: np.ndarray, variant_idx: list[int], steps: int = 20, warp_device: str = "cpu"
) -> tuple[float, float]:
    """Largest |qpos| (m, rad) and |sensordata| gaps between the MuJoCo Warp engine on
    ``warp_device`` and the CPU engine, over ``steps`` policy steps of the same controls from
    the same noisy poses, with the dynamics variants ``rows`` (one per env by ``variant_idx``)."""
    from quaddance.sim.engines import CpuEngine
    from quaddance.sim.warp_engine import WarpEngine

    n = len(variant_idx)
    gpu = WarpEngine(n, variants=rows, device=warp_device)
    cpu = CpuEngine(n, variants=rows)
    ids = torch.arange(n)
    gpu.set_variants(ids, torch.tensor(variant_idx))
    cpu.set_variants(ids.numpy(), np.array(variant_idx))
    qpos, qvel = noisy_home(cpu.model, n, seed=11)
    gpu.reset(ids, qpos, qvel)
    cpu.reset(ids, qpos, qvel)
    gaps_q, gaps_s = [], []
    for ctrl in random_controls(n, steps, seed=12):
        a, b = gpu.step(ctrl.to(gpu.device)), cpu.step(ctrl)
        gaps_q.append((a.qpos.cpu() - b.qpos).abs().max().item())
        gaps_s.append((a.sensordata.cpu() - b.sensordata).abs().max().item())
    return max(gaps_q), max(gaps_s)


# Friction, added trunk mass (kg), motor strength: the variants the engine test uses.
AGREEMENT_VARIANTS = np.array([[1.0, 0.0, 1.0], [1.0, 2.0, 1.1], [0.4, -1.0, 0.9]])


def engine_agreement(warp_device: str, steps: int = 50) -> dict[str, float]:
    """`engine_gaps` over 8 envs with the three variants: what the GPU engine's physics
    differs by from the CPU engine's on this device."""
    gap_q, gap_s = engine_gaps(AGREEMENT_VARIANTS, [0, 1, 2, 1, 0, 2, 1, 0], steps, warp_device)
    return {"device": warp_device, "steps": steps, "max_qpos_gap": gap_q, "max_sensor_gap": gap_s}


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
    if engine == "gpu":
        warp_device = "cuda:0" if torch.cuda.is_available() else "cpu"
        results["engine_agreement"] = engine_agreement(warp_device)
        print(f"engine agreement: {results['engine_agreement']}")
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
