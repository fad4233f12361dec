"""Stills: poses drawn as PNG files by the render workers, e.g. to check what a video shows."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from quaddance.play.video.config import VIDEO_FPS, RenderCfg, check_size
from quaddance.play.video.poses import QposLayout, check_poses, follow_lookat, resample_qpos
from quaddance.play.video.scene import ModelSource, load_model
from quaddance.play.video.workers import WorkerPool


def write_frames_png(
    model: ModelSource,
    qpos_s: np.ndarray,
    sim_fps: float,
    times_s: Sequence[float],
    out_dir: str | Path,
    width: int = 640,
    height: int = 480,
    target_heights_m: np.ndarray | None = None,
    cfg: RenderCfg | None = None,
) -> list[Path]:
    """Render stills at the given sim times as PNGs, e.g. to check what a video shows.

    Args:
        model, qpos_s, sim_fps, target_heights_m, cfg: as in `render_video`.
        times_s: sim times of the stills, s.
        out_dir: folder for ``frame_<i>_<time>s.png``; created if missing.

    Returns:
        The PNG paths, in the order of ``times_s``.
    """
    cfg = cfg or RenderCfg()
    check_size(width, height, 1.0)
    base_model = load_model(model, cfg.robot)
    layout = QposLayout.of(base_model)
    qpos = check_poses(layout.nq, qpos_s, sim_fps, target_heights_m)
    times = np.asarray(times_s, dtype=float).reshape(-1)
    if len(times) == 0:
        return []
    frames_qpos = resample_qpos(layout, qpos, sim_fps, times)
    # The camera is smoothed over the whole trajectory, as in the video, then sampled.
    all_times = np.arange(max(1, round(qpos.shape[0] / sim_fps * VIDEO_FPS))) / VIDEO_FPS
    path_lookat = follow_lookat(
        layout, resample_qpos(layout, qpos, sim_fps, all_times), VIDEO_FPS, cfg
    )
    lookat = np.stack([np.interp(times, all_times, col) for col in path_lookat.T], axis=1)
    arrays = {"qpos": frames_qpos, "lookat": lookat}
    if target_heights_m is not None:
        src = np.asarray(target_heights_m, dtype=float)
        arrays["targets"] = src[np.clip((times * sim_fps + 1e-9).astype(int), 0, len(src) - 1)]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    pngs = [out_dir / f"frame_{i:03d}_{t:07.2f}s.png" for i, t in enumerate(times)]
    pool = WorkerPool(base_model, width, height, 1, cfg)
    try:
        pool.send(("stills", arrays, pngs))
        pool.wait_ready()
        for _ in pngs:
            pool.receive(0)
        pool.receive(0)  # done
    finally:
        pool.close(grace_s=2.0)  # the worker ends by itself after the stills
    return pngs
