"""`quaddance bench envelope`: how far the policy's robustness reaches.

Two parts, each on a few held-out items (`quaddance.play.heldout`), with the dynamics pinned
(`quaddance.play.rollout.PinnedDynamics`) rather than drawn:

1. Ends of the training ranges (`quaddance.sim.config.DomainRandCfg`): each of friction,
   added mass, motor strength and action lag at its low and high end alone, and the four
   hard ends together (friction 0.1, +3 kg, strength 0.9, 30 ms). Falls and tracking.
2. Pushes of increasing strength: a horizontal velocity added to the base every few seconds,
   directions cycling left, back, right, front. The first push velocity at which the robot
   falls, on the nominal robot and on the hard corner.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from quaddance.fileio import atomic_path, write_json
from quaddance.play.evaluate import EvalSettings, evaluate_items, summarize
from quaddance.play.policy import policy_label
from quaddance.play.rollout import PinnedDynamics

#: The four hard ends of the training ranges at once (FACTS.md section 2 / DomainRandCfg).
HARD_CORNER = PinnedDynamics(
    friction=0.1, added_mass_kg=3.0, motor_strength=0.9, action_lag_s=0.030
)

#: Conditions of part 1: name -> pinned dynamics.
RANGE_ENDS: dict[str, PinnedDynamics] = {
    "nominal": PinnedDynamics(),
    "friction 0.1": PinnedDynamics(friction=0.1),
    "friction 3.0": PinnedDynamics(friction=3.0),
    "added mass +3 kg": PinnedDynamics(added_mass_kg=3.0),
    "added mass -1 kg": PinnedDynamics(added_mass_kg=-1.0),
    "motor strength 0.9": PinnedDynamics(motor_strength=0.9),
    "motor strength 1.1": PinnedDynamics(motor_strength=1.1),
    "action lag 30 ms": PinnedDynamics(action_lag_s=0.030),
    "all four hard ends": HARD_CORNER,
}

#: Push velocities of part 2, m/s (training pushes: up to 0.5 m/s per axis every 8 s).
PUSH_VELS_M_S: tuple[float, ...] = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0)

#: A fall this soon after a push is the push's doing, s.
FALL_AFTER_PUSH_S = 3.0

#: Items of the envelope: a song of the generator set and a motion of the other set (two
#: items: each condition dances all of them on a shared 2-core machine).
ENVELOPE_ITEMS: dict[str, tuple[str, ...]] = {
    "generator": ("song_104bpm_seed9003.wav",),
    "other": ("high_knees_100bpm_biped_mm_zup.bvh",),
}


def default_items(folder: Path) -> list[Path]:
    """Write the held-out sets into ``folder`` and return the envelope's items."""
    from quaddance.play.heldout import write_held_out_set

    items = []
    for which, names in ENVELOPE_ITEMS.items():
        written = {p.name: p for p in write_held_out_set(folder / which, which)}
        items += [written[n] for n in names]
    return items


def _row_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The means over items (`summarize`) and, per item, its falls and front-foot tracking."""
    s = summarize(rows)
    s["per_item"] = {
        r["name"]: {
            "falls_s": r["falls_s"],
            "front": r["front"],
            "rear_lift_max_m": r["rear_lift_max_m"],
        }
        for r in rows
    }
    return s


def push_outcome(falls_s: Sequence[float], pushes_s: Sequence[float]) -> list[bool]:
    """For each push, whether the robot fell within `FALL_AFTER_PUSH_S` after it."""
    return [any(p <= f <= p + FALL_AFTER_PUSH_S for f in falls_s) for p in pushes_s]


def push_sweep(
    items: Sequence[Path],
    policy: Path | None,
    base: PinnedDynamics,
    vels_m_s: Sequence[float] = PUSH_VELS_M_S,
    stop_after_falls: int = 1,
    log: Callable[[str], None] = lambda msg: None,
) -> dict[str, Any]:
    """Dance ``items`` with pushes of each velocity on robot ``base``.

    Stops after ``stop_after_falls`` velocities in a row made it fall (the rest would too).

    Returns:
        ``first_fall_vel_m_s`` (None if it never fell) and per velocity the falls, the
        pushes that were followed by a fall (with their direction) and the tracking means.
    """
    from quaddance.play.rollout import PUSH_DIRECTIONS

    per_vel = []
    first = None
    falling_in_a_row = 0
    for vel in vels_m_s:
        pinned = dataclasses.replace(base, push_vel_m_s=vel)
        rows = evaluate_items(items, policy, EvalSettings(pinned=pinned))
        fell_after = []
        n_pushes = 0
        for r in rows:
            pushes_s = pinned.push_times_s(r["duration_s"])
            n_pushes += len(pushes_s)
            for k, fell in enumerate(push_outcome(r["falls_s"], pushes_s)):
                if fell:
                    d = PUSH_DIRECTIONS[k % len(PUSH_DIRECTIONS)]
                    fell_after.append({"item": r["name"], "push_s": pushes_s[k], "dir_xy": d})
        s = _row_summary(rows)
        per_vel.append(
            {"push_vel_m_s": vel, "pushes": n_pushes, "pushes_followed_by_a_fall": fell_after, **s}
        )
        log(f"  push {vel:.2f} m/s: {s['falls']} falls, {len(fell_after)}/{n_pushes} pushes")
        if s["falls"] and first is None:
            first = vel
        falling_in_a_row = falling_in_a_row + 1 if s["falls"] else 0
        if falling_in_a_row >= stop_after_falls:
            break
    return {"first_fall_vel_m_s": first, "per_vel": per_vel}


def run_envelope(
    items: Sequence[Path],
    policy: Path | None = None,
    conditions: dict[str, PinnedDynamics] | None = None,
    push_bases: dict[str, PinnedDynamics] | None = None,
    vels_m_s: Sequence[float] = PUSH_VELS_M_S,
    log: Callable[[str], None] = lambda msg: None,
) -> dict[str, Any]:
    """Both parts of the envelope (module doc) on ``items``; JSON-ready."""
    conditions = RANGE_ENDS if conditions is None else conditions
    push_bases = (
        {"nominal": PinnedDynamics(), "all four hard ends": HARD_CORNER}
        if push_bases is None
        else push_bases
    )
    t0 = time.perf_counter()
    ranges = {}
    for name, pinned in conditions.items():
        rows = evaluate_items(items, policy, EvalSettings(pinned=pinned))
        ranges[name] = {"dynamics": dataclasses.asdict(pinned), **_row_summary(rows)}
        log(f"{name}: {ranges[name]['falls']} falls")
    pushes = {}
    for name, base in push_bases.items():
        log(f"pushes, {name}:")
        pushes[name] = {
            "dynamics": dataclasses.asdict(base),
            **push_sweep(items, policy, base, vels_m_s, log=log),
        }
    return {
        "items": [p.name for p in items],
        "policy": policy_label(policy),
        "push_schedule": {
            "first_s": PinnedDynamics().push_first_s,
            "every_s": PinnedDynamics().push_every_s,
            "directions": "left, back, right, front, repeated",
            "fall_attributed_within_s": FALL_AFTER_PUSH_S,
        },
        "range_ends": ranges,
        "pushes": pushes,
        "wall_s": round(time.perf_counter() - t0, 1),
    }


def _cm(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:.1f}"


def _f2(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def markdown(result: dict[str, Any], command: str) -> str:
    """The envelope as a markdown page."""
    lines = [
        "# Robustness envelope",
        "",
        f"Made by `{command}`; policy `{result['policy']}`; items (held-out, 20 s each): "
        + ", ".join(f"`{n}`" for n in result["items"])
        + ". Dynamics pinned (joint calibration offsets 0, nominal start pose); MAE/corr "
        "are means over items and both front feet; *feas.* = feasible part of the targets.",
        "",
        "## Ends of the training randomisation ranges",
        "",
        "| dynamics | falls | MAE feas. (cm) | MAE all (cm) | corr feas. | corr all "
        "| rear lift mean / max (cm) |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, r in result["range_ends"].items():
        lines.append(
            f"| {name} | {r['falls']} | {_cm(r['mae_feasible_m'])} | {_cm(r['mae_m'])} | "
            f"{_f2(r['corr_feasible'])} | {_f2(r['corr'])} | {_cm(r['rear_lift_mean_m'])} / "
            f"{_cm(r['rear_lift_max_m'])} |"
        )
    sched = result["push_schedule"]
    lines += [
        "",
        "## Pushes",
        "",
        f"A horizontal velocity added to the base at {sched['first_s']:g} s and every "
        f"{sched['every_s']:g} s after, directions {sched['directions']}; a fall within "
        f"{sched['fall_attributed_within_s']:g} s of a push counts for it. The sweep stops at "
        "the first velocity with a fall.",
        "",
    ]
    for name, p in result["pushes"].items():
        first = p["first_fall_vel_m_s"]
        lines += [
            f"### {name}: first fall at "
            + ("no push tried" if first is None and not p["per_vel"] else "")
            + (f"{first:.2f} m/s" if first is not None else "none of the pushes tried"),
            "",
            "| push (m/s) | falls | pushes followed by a fall | MAE feas. (cm) | corr feas. "
            "| rear lift mean / max (cm) |",
            "|---|---|---|---|---|---|",
        ]
        for v in p["per_vel"]:
            lines.append(
                f"| {v['push_vel_m_s']:.2f} | {v['falls']} | "
                f"{len(v['pushes_followed_by_a_fall'])} / {v['pushes']} | "
                f"{_cm(v['mae_feasible_m'])} | {_f2(v['corr_feasible'])} | "
                f"{_cm(v['rear_lift_mean_m'])} / {_cm(v['rear_lift_max_m'])} |"
            )
        lines.append("")
    return "\n".join(lines)


def write_envelope(result: dict[str, Any], json_path: Path, md_path: Path, command: str) -> None:
    """Write the JSON and the markdown page, each atomically."""
    write_json(json_path, result)
    with atomic_path(md_path) as tmp:
        tmp.write_text(markdown(result, command))
