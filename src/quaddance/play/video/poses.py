"""Poses to frames: the pose of each video frame (`resample_qpos`) and the follow camera's
smoothed path (`follow_lookat`), computed in the caller from a model's `QposLayout`."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.play.metrics import gaussian_smooth
from quaddance.play.video.config import RenderCfg


@dataclass(frozen=True)
class QposLayout:
    """What turning poses into frames needs to know of a model: a render worker reports it
    for the model it built, so the caller never compiles the visual model itself."""

    nq: int
    #: (start, stop) qpos ranges holding unit quaternions (free and ball joints).
    quat_ranges: tuple[tuple[int, int], ...]
    #: qpos address of the first free joint (the base position); None: no free joint.
    base_adr: int | None
    #: ``model.stat.center``: the look-at point of a model without a free joint, m.
    center: tuple[float, float, float]

    @classmethod
    def of(cls, model: mujoco.MjModel) -> QposLayout:
        quats, base = [], None
        for j in range(model.njnt):
            adr = int(model.jnt_qposadr[j])
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                quats.append((adr + 3, adr + 7))
                base = adr if base is None else base
            elif model.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
                quats.append((adr, adr + 4))
        center = tuple(float(c) for c in model.stat.center)
        return cls(int(model.nq), tuple(quats), base, center)  # type: ignore[arg-type]


def _layout(model: mujoco.MjModel | QposLayout) -> QposLayout:
    return model if isinstance(model, QposLayout) else QposLayout.of(model)


def resample_qpos(
    model: mujoco.MjModel | QposLayout, qpos_s: np.ndarray, sim_fps: float, times_s: np.ndarray
) -> np.ndarray:
    """Poses at arbitrary times: linear interpolation, quaternions normalised (nlerp).

    Args:
        model: gives the qpos layout (which entries are quaternions).
        qpos_s: (T, nq) poses sampled at ``sim_fps`` Hz, sample i at time i / sim_fps.
        sim_fps: sample rate of ``qpos_s``, Hz.
        times_s: (N,) times, s; clipped to the sampled span.

    Returns:
        (N, nq) poses.
    """
    quats = [slice(a, b) for a, b in _layout(model).quat_ranges]
    qpos = np.asarray(qpos_s, dtype=float)
    pos = np.clip(np.asarray(times_s, dtype=float) * sim_fps, 0.0, qpos.shape[0] - 1)
    i0 = np.floor(pos).astype(int)
    i1 = np.minimum(i0 + 1, qpos.shape[0] - 1)
    w = (pos - i0)[:, None]
    a, b = qpos[i0], qpos[i1].copy()
    for sl in quats:
        # q and -q are the same rotation: interpolate along the shorter arc.
        flip = np.sum(a[:, sl] * b[:, sl], axis=1) < 0
        b[flip, sl] *= -1.0
    out = (1.0 - w) * a + w * b
    for sl in quats:
        norm = np.linalg.norm(out[:, sl], axis=1, keepdims=True)
        out[:, sl] /= np.where(norm > 0, norm, 1.0)
    return out


def follow_lookat(
    model: mujoco.MjModel | QposLayout, qpos_frames: np.ndarray, fps: float, cfg: RenderCfg
) -> np.ndarray:
    """Smoothed look-at points of the follow camera, (N, 3) m, from the base position."""
    layout = _layout(model)
    if layout.base_adr is None:
        return np.tile(np.asarray(layout.center, dtype=float), (len(qpos_frames), 1))
    adr = layout.base_adr
    base = qpos_frames[:, adr : adr + 3] + np.asarray(cfg.lookat_offset_m)
    return gaussian_smooth(base, cfg.smooth_s * fps)


def check_poses(
    nq: int, qpos_s: np.ndarray, sim_fps: float, targets: np.ndarray | None
) -> np.ndarray:
    """``qpos_s`` as a float (T, nq) array, checked (finite, T >= 1) with ``sim_fps`` and the
    (T, 4) ``targets``; raises QuaddanceError naming the wrong argument."""
    qpos = np.asarray(qpos_s, dtype=float)
    if qpos.ndim != 2 or qpos.shape[1] != nq or qpos.shape[0] < 1:
        raise QuaddanceError(f"qpos_s must be (T, {nq}) with T >= 1, got {qpos.shape}")
    if not np.all(np.isfinite(qpos)):
        raise QuaddanceError("qpos_s contains NaN or inf")
    if not sim_fps > 0:
        raise QuaddanceError(f"sim_fps must be > 0, got {sim_fps}")
    if targets is not None and np.shape(targets) != (qpos.shape[0], 4):
        raise QuaddanceError(
            f"target_heights_m must be ({qpos.shape[0]}, 4) like qpos_s, got {np.shape(targets)}"
        )
    return qpos
