"""`quaddance eval`: run a policy over many songs and motions (no video) and report.

Also builds a held-out evaluation set the shipped policy never trained on: songs made by
code at other tempi and seeds than the training bank, plus EDGE- and AIST++-style motion
files made by SMPL forward kinematics.
"""

from __future__ import annotations

import pickle
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.fileio import atomic_path

AUDIO_EXT = {".wav", ".flac", ".ogg", ".mp3"}
MOTION_EXT = {".pkl", ".pickle", ".bvh"}

# Held-out songs: (tempo_bpm, seed, swing, syncopation); seeds far from the bank's.
HELD_OUT_SONGS: tuple[tuple[float, int, float, bool], ...] = (
    (84.0, 9001, 0.0, False),
    (96.0, 9002, 0.3, False),
    (104.0, 9003, 0.0, True),
    (112.0, 9004, 0.0, False),
    (124.0, 9005, 0.5, False),
    (132.0, 9006, 0.0, True),
    (142.0, 9007, 0.0, False),
    (156.0, 9008, 0.2, True),
)


def collect_items(paths: Sequence[Path]) -> list[Path]:
    """Files to evaluate: audio and motion files, folders expanded (sorted)."""
    items: list[Path] = []
    for p in paths:
        p = Path(p)
        if p.is_dir():
            items += sorted(f for f in p.iterdir() if f.suffix.lower() in AUDIO_EXT | MOTION_EXT)
        elif p.is_file():
            items.append(p)
        else:
            raise QuaddanceError(f"{p}: no such file or folder")
    if not items:
        raise QuaddanceError("nothing to evaluate: no audio or motion files found")
    return items


def _stepping_poses(n: int, fps: float, tempo_bpm: float, seed: int) -> np.ndarray:
    """(n, 72) SMPL axis-angle poses of a dancer stepping left/right on the beat."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fps
    beat = 60.0 / tempo_bpm
    poses = np.zeros((n, 72))
    for side, (hip, knee) in enumerate(((1, 4), (2, 5))):  # SMPL joints: hips 1/2, knees 4/5
        phase = (t / beat - side) % 2.0  # each leg lifts every other beat
        lift = np.where(phase < 1.0, np.sin(np.pi * phase) ** 2, 0.0)
        amp = rng.uniform(0.5, 0.9)
        poses[:, 3 * hip] = -amp * lift  # hip flexion (about x)
        poses[:, 3 * knee] = 2.0 * amp * lift  # knee flexion
    return poses


def write_held_out_set(folder: Path, duration_s: float = 20.0) -> list[Path]:
    """Write the held-out evaluation set into `folder`; returns its files."""
    import soundfile as sf

    from quaddance.choreo.smpl import smpl_joints
    from quaddance.music.synth import render_song

    folder.mkdir(parents=True, exist_ok=True)
    files = []
    for tempo, seed, swing, sync in HELD_OUT_SONGS:
        path = folder / f"song_{int(tempo)}bpm_seed{seed}.wav"
        if not path.exists():
            y, _ = render_song(tempo, duration_s, seed, swing=swing, syncopation=sync)
            with atomic_path(path) as tmp:
                sf.write(tmp, y, 22050)
        files.append(path)
    # EDGE style: full_pose (T, 24, 3) z-up metres at 30 fps.
    edge_poses = _stepping_poses(int(duration_s * 30), 30.0, 110.0, seed=9101)
    joints = smpl_joints(edge_poses, np.tile([0.0, 0.95, 0.0], (len(edge_poses), 1)))
    z_up = np.stack([joints[..., 0], -joints[..., 2], joints[..., 1]], axis=-1)
    edge = {
        "smpl_poses": edge_poses,
        "smpl_trans": np.zeros((len(edge_poses), 3)),
        "full_pose": z_up,
    }
    # AIST++ style: poses + translation in centimetre-like units with a scaling, y-up, 60 fps.
    aist_poses = _stepping_poses(int(duration_s * 60), 60.0, 126.0, seed=9102)
    aist = {
        "smpl_poses": aist_poses,
        "smpl_trans": np.tile([0.0, 0.95 * 93.0, 0.0], (len(aist_poses), 1)),
        "smpl_scaling": np.array([93.0]),
    }
    for name, obj in (("edge_style.pkl", edge), ("aistpp_style.pkl", aist)):
        path = folder / name
        with atomic_path(path) as tmp, tmp.open("wb") as f:
            pickle.dump(obj, f, protocol=4)  # writing our own data; loading is the safe side
        files.append(path)
    return files


def evaluate(
    items: Sequence[Path],
    policy: Path | None,
    report: Path,
    seed: int = 0,
    progress: Callable[[int, int, str], None] | None = None,
    randomize: bool = False,
) -> list[dict[str, Any]]:
    """Dance each item without video; write a markdown table (+ mean) and a plot.

    ``randomize`` draws the robot's dynamics as in training (friction, mass, strength,
    joint offsets, action lag, pushes): a robustness check."""
    import tempfile

    from quaddance.play.dance import DanceJob, run_dance
    from quaddance.play.plots import plot_eval

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, item in enumerate(items):
            if progress:
                progress(i, len(items), item.name)
            is_motion = item.suffix.lower() in MOTION_EXT
            job = DanceJob(
                out_dir=Path(tmp) / f"{i}",
                song=None if is_motion else item,
                motion=item if is_motion else None,
                policy=policy,
                seed=seed,
                video=False,
            )
            metrics = run_dance(job).metrics
            rows.append({"name": item.name, **metrics})
    if progress:
        progress(len(items), len(items), "")
    plot_path = report.with_suffix(".png")
    plot_eval(plot_path, rows)
    with atomic_path(report) as tmp:
        tmp.write_text(markdown_report(rows, policy, plot_path.name, randomize))
    return rows


def _num(v: Any, scale: float = 1.0, digits: int = 2) -> str:
    return "-" if v is None else f"{v * scale:.{digits}f}"


def summarize(rows: Sequence[dict[str, Any]]) -> dict[str, float | None]:
    """Means over items (feasible-part tracking, rear lift, BAS) and the total falls."""

    def mean(values: list) -> float | None:
        vals = [v for v in values if v is not None]
        return float(np.mean(vals)) if vals else None

    feet = ("fl", "fr")
    return {
        "items": len(rows),
        "falls": int(sum(len(r["falls_s"]) for r in rows)),
        "mae_feasible_m": mean([r["front"][f]["mae_feasible_m"] for r in rows for f in feet]),
        "corr_feasible": mean([r["front"][f]["corr_feasible"] for r in rows for f in feet]),
        "mae_m": mean([r["front"][f]["mae_m"] for r in rows for f in feet]),
        "corr": mean([r["front"][f]["corr"] for r in rows for f in feet]),
        "rear_lift_mean_m": mean([r["rear_lift_mean_m"] for r in rows]),
        "rear_lift_max_m": max((r["rear_lift_max_m"] or 0.0) for r in rows),
        "bas": mean([r["bas"] for r in rows]),
        "realtime_factor_sim": mean([r["realtime_factor_sim"] for r in rows]),
    }


def markdown_report(
    rows: Sequence[dict[str, Any]], policy: Path | None, plot_name: str, randomize: bool = False
) -> str:
    head = (
        "| item | falls | FL MAE feas. (cm) | FR MAE feas. (cm) | FL corr feas. | FR corr feas. "
        "| FL MAE (cm) | FR MAE (cm) | rear lift mean / max (cm) | BAS | sim x real time |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r in rows:
        fl, fr = r["front"]["fl"], r["front"]["fr"]
        lines.append(
            f"| {r['name']} | {len(r['falls_s'])} | {_num(fl['mae_feasible_m'], 100, 1)} | "
            f"{_num(fr['mae_feasible_m'], 100, 1)} | {_num(fl['corr_feasible'])} | "
            f"{_num(fr['corr_feasible'])} | {_num(fl['mae_m'], 100, 1)} | "
            f"{_num(fr['mae_m'], 100, 1)} | {_num(r['rear_lift_mean_m'], 100, 1)} / "
            f"{_num(r['rear_lift_max_m'], 100, 1)} | {_num(r['bas'])} | "
            f"{_num(r['realtime_factor_sim'], 1, 1)} |"
        )
    s = summarize(rows)
    lines.append(
        f"| **mean** | {s['falls']} (total) | {_num(s['mae_feasible_m'], 100, 1)} (FL+FR) | | "
        f"{_num(s['corr_feasible'])} (FL+FR) | | {_num(s['mae_m'], 100, 1)} (FL+FR) | | "
        f"{_num(s['rear_lift_mean_m'], 100, 1)} / {_num(s['rear_lift_max_m'], 100, 1)} | "
        f"{_num(s['bas'])} | {_num(s['realtime_factor_sim'], 1, 1)} |"
    )
    return (
        f"# quaddance evaluation\n\npolicy: `{policy or 'shipped'}`, {len(rows)} items, "
        + ("dynamics randomised as in training" if randomize else "no domain randomisation")
        + ". MAE/corr per front foot; *feas.* = the feasible part of the "
        "targets (see `quaddance.play.metrics`).\n\n"
        + head
        + "\n".join(lines)
        + f"\n\n![metrics]({plot_name})\n"
    )
