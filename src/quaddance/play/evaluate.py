"""`quaddance eval`: run a policy over many songs and motions (no video) and report.

Held-out sets to run it on are written by `quaddance.play.heldout`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.fileio import atomic_path, check_outputs, write_json
from quaddance.play.policy import policy_label
from quaddance.play.rollout import PinnedDynamics

if TYPE_CHECKING:
    from quaddance.choreo.motion import HumanMotion

AUDIO_EXT = {".wav", ".flac", ".ogg", ".mp3"}
MOTION_EXT = {".pkl", ".pickle", ".bvh"}


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


@dataclass(frozen=True)
class EvalSettings:
    """How each item is danced: the dynamics and what drives the joints."""

    seed: int = 0  #: choreographer seed; item i's randomised dynamics use seed 1000 * seed + i
    randomize: bool = False  #: dynamics drawn as in training (`sim.config.DomainRandCfg`)
    policy_output: str = "policy"  #: "zero": the front-lift feed-forward alone
    pinned: PinnedDynamics | None = None  #: fixed dynamics and pushes (robustness envelope)
    mode: str = "feasible"  #: target mode

    def describe(self) -> str:
        """One sentence for the report's heading."""
        if self.randomize:
            dyn = "dynamics randomised as in training (a different draw per item)"
        elif self.pinned is not None:
            dyn = f"dynamics pinned to {_describe_pinned(self.pinned)}"
        else:
            dyn = "no domain randomisation"
        drive = (
            "feed-forward alone (policy output replaced by zeros)"
            if self.policy_output == "zero"
            else "policy + feed-forward"
        )
        return f"{dyn}; {drive}; {self.mode} targets"


def _describe_pinned(p: PinnedDynamics) -> str:
    parts = [
        f"friction {p.friction}" if p.friction is not None else "nominal friction",
        f"added mass {p.added_mass_kg:+.1f} kg",
        f"motor strength {p.motor_strength:.2f}",
        f"action lag {1e3 * p.action_lag_s:.0f} ms",
    ]
    if p.push_vel_m_s > 0:
        parts.append(
            f"pushes of {p.push_vel_m_s:.2f} m/s every {p.push_every_s:g} s from "
            f"{p.push_first_s:g} s"
        )
    return ", ".join(parts)


def evaluate_items(
    items: Sequence[Path],
    policy: Path | None,
    settings: EvalSettings = EvalSettings(),
    progress: Callable[[int, int, str], None] | None = None,
    motions: dict[Path, HumanMotion] | None = None,
) -> list[dict[str, Any]]:
    """Dance each item without video on the policy's robot (``policy`` None: the shipped
    Go1 policy); one row per item: ``name`` + every key of its metrics.json. A motion item
    in ``motions`` (`check_eval_files`' result) is danced as read there, not read again."""
    import tempfile

    from quaddance.pipeline import DanceSpec
    from quaddance.play.dance import DanceJob, run_dance
    from quaddance.play.policy import choose_policy
    from quaddance.targets import TargetConfig

    robot, policy = choose_policy(None, policy)
    spec = DanceSpec(seed=settings.seed, targets=TargetConfig(mode=settings.mode, robot=robot))

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
                human=(motions or {}).get(item) if is_motion else None,
                policy=policy,
                spec=spec,
                video=False,
                randomize=settings.randomize,
                # One draw of the dynamics per item, not the same robot for every item.
                sim_seed=1000 * settings.seed + i,
                policy_output=settings.policy_output,
                pinned=settings.pinned,
            )
            rows.append({"name": item.name, **run_dance(job).metrics})
    if progress:
        progress(len(items), len(items), "")
    return rows


def report_outputs(report: Path) -> dict[str, Path]:
    """The files an evaluation writes, by what they are: the report and beside it its JSON
    and plot."""
    return {
        "--report": report,
        "the report's .json": report.with_suffix(".json"),
        "the report's .png": report.with_suffix(".png"),
    }


def check_eval_files(items: Sequence[Path], report: Path) -> dict[Path, HumanMotion]:
    """Everything that can be checked before the work, so that a bad file fails in a moment
    and not after the items before it were danced: the outputs (writable, none an input
    item, none another output: ``-o x.png`` would be its own plot), and each motion file
    (read as the dance will read it; songs are checked when decoded).

    Returns:
        Each motion item as read, for `evaluate_items` to dance without reading it again.

    Raises:
        OutputFileError: an output cannot be written or collides with an input or an output.
        InputFileError: a motion file cannot be read.
    """
    from quaddance.choreo.motion import load_motion

    check_outputs(report_outputs(report), {f"item {item.name}": item for item in items})
    return {item: load_motion(item) for item in items if item.suffix.lower() in MOTION_EXT}


def evaluate(
    items: Sequence[Path],
    policy: Path | None,
    report: Path,
    settings: EvalSettings = EvalSettings(),
    progress: Callable[[int, int, str], None] | None = None,
    title: str | None = None,
) -> list[dict[str, Any]]:
    """Dance each item (see `evaluate_items`) and write the report: ``report`` (markdown:
    table + mean), the same numbers as JSON beside it (``.json``: ``items``, ``mean``,
    ``settings``) and a plot (``.png``)."""
    from quaddance.play.plots import plot_eval

    motions = check_eval_files(items, report)
    rows = evaluate_items(items, policy, settings, progress, motions)
    plot_path = report.with_suffix(".png")
    plot_eval(plot_path, rows)
    write_json(
        report.with_suffix(".json"),
        {"items": rows, "mean": summarize(rows), "settings": settings_dict(settings, policy)},
    )
    with atomic_path(report) as tmp:
        tmp.write_text(markdown_report(rows, policy, plot_path.name, settings, title))
    return rows


def settings_dict(settings: EvalSettings, policy: Path | None) -> dict[str, Any]:
    """JSON-ready settings of an evaluation."""
    d = dataclasses.asdict(settings)
    d["policy"] = policy_label(policy)
    d["description"] = settings.describe()
    return d


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
        "body_height_mae_m": mean([_body(r, "height", "mae_m") for r in rows]),
        "body_angle_mae_deg": mean([(r.get("body") or {}).get("angle_mae_deg") for r in rows]),
        "body_angle_range_deg": mean([_angle_range_deg(r) for r in rows]),
        "body_height_range_m": mean([_body(r, "height", "measured_range_m") for r in rows]),
        "beat_coverage": mean([r.get("beat_coverage") for r in rows]),
    }


def summary_line(rows: Sequence[dict[str, Any]]) -> str:
    """One line for a person from `summarize`: items, falls, front-paw tracking, rear lift."""
    s = summarize(rows)
    return (
        f"{s['items']} items, {s['falls']} falls; feasible MAE "
        f"{100 * (s['mae_feasible_m'] or 0):.1f} cm, corr {s['corr_feasible'] or 0:.2f}; rear lift "
        f"{100 * (s['rear_lift_mean_m'] or 0):.1f} cm mean"
    )


def _body(row: dict[str, Any], column: str, key: str) -> float | None:
    return ((row.get("body") or {}).get(column) or {}).get(key)


def _angle_range_deg(row: dict[str, Any]) -> float | None:
    """The largest measured range among roll, pitch and yaw, deg."""
    ranges = [_body(row, c, "measured_range_deg") for c in ("roll", "pitch", "yaw")]
    ranges = [v for v in ranges if v is not None]
    return max(ranges) if ranges else None


def markdown_report(
    rows: Sequence[dict[str, Any]],
    policy: Path | None,
    plot_name: str,
    settings: EvalSettings = EvalSettings(),
    title: str | None = None,
) -> str:
    head = (
        "| item | falls | FL MAE feas. (cm) | FR MAE feas. (cm) | FL corr feas. | FR corr feas. "
        "| FL MAE (cm) | FR MAE (cm) | rear lift mean / max (cm) | BAS "
        "| trunk height MAE (cm) | trunk angle MAE (deg) | trunk range angle (deg) / height (cm) "
        "| beat coverage | sim x real time |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
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
            f"{_num(_body(r, 'height', 'mae_m'), 100, 1)} | "
            f"{_num((r.get('body') or {}).get('angle_mae_deg'), 1, 1)} | "
            f"{_num(_angle_range_deg(r), 1, 1)} / "
            f"{_num(_body(r, 'height', 'measured_range_m'), 100, 1)} | "
            f"{_num(r.get('beat_coverage'))} | {_num(r['realtime_factor_sim'], 1, 1)} |"
        )
    s = summarize(rows)
    lines.append(
        f"| **mean** | {s['falls']} (total) | {_num(s['mae_feasible_m'], 100, 1)} (FL+FR) | | "
        f"{_num(s['corr_feasible'])} (FL+FR) | | {_num(s['mae_m'], 100, 1)} (FL+FR) | | "
        f"{_num(s['rear_lift_mean_m'], 100, 1)} / {_num(s['rear_lift_max_m'], 100, 1)} | "
        f"{_num(s['bas'])} | {_num(s['body_height_mae_m'], 100, 1)} | "
        f"{_num(s['body_angle_mae_deg'], 1, 1)} | {_num(s['body_angle_range_deg'], 1, 1)} / "
        f"{_num(s['body_height_range_m'], 100, 1)} | {_num(s['beat_coverage'])} | "
        f"{_num(s['realtime_factor_sim'], 1, 1)} |"
    )
    return (
        f"# {title or 'quaddance evaluation'}\n\npolicy: `{policy_label(policy)}`, "
        f"{len(rows)} items; {settings.describe()}. MAE/corr per front foot; *feas.* = the "
        "feasible part of the targets (see `quaddance.play.metrics`); BAS needs music beats "
        "(none for a motion file alone); trunk: measured pose vs the body targets (height in "
        "cm, the mean MAE of roll, pitch, yaw in deg; range: the largest of the three, and the "
        "height's); beat coverage: beats with a motion accent of the robot within +-100 ms. "
        "The same numbers: the `.json` beside this file.\n\n"
        + head
        + "\n".join(lines)
        + f"\n\n![metrics]({plot_name})\n"
    )
