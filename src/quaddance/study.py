"""The paper's study (section 4.3) in one command: every reward and target variant trained at
one budget of env steps, evaluated the same way, tabulated, and the paper's claims tested.

Each `Variant` is the default paws-only Go1 task (feasible targets, the front-lift
feed-forward on, our reward table) with one factor changed. A run (variant x seed) trains in
``work/<variant>/seed<k>`` (checkpoint, bank, logs: resumable on the same machine) and, when
it is evaluated, writes its results at once into ``out/<variant>/seed<k>``: ``policy.onnx`` +
``policy.json`` (playable with ``dance --policy``), ``curve.csv``, ``feet.png`` and last
``metrics.json``, the mark of a finished run. A finished run is never trained, evaluated or
written again, so a study stopped anywhere continues where it stopped, on any machine that
has ``out``. The report (``study.md`` + ``study.json`` beside ``out``) is rewritten from every
finished run after each one.

Each run is evaluated on a fixed held-out set (`EVAL_ITEMS`: songs and a motion the training
bank did not make, from `quaddance.play.heldout`), danced with the targets it trained on; the
measured paws are also compared with the feasible targets of the same dance. The verdicts
follow `THRESHOLDS`, fixed before any run.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.fileio import atomic_path, write_json
from quaddance.sim import tasks
from quaddance.sim.config import DanceTaskCfg

#: Steps each env takes per PPO iteration (the cpu preset's).
STEPS_PER_ENV = 24


@dataclass(frozen=True)
class Variant:
    """The default paws-only task with one factor changed (``changes`` says which)."""

    name: str
    changes: str
    reward_set: str = "paper"
    c_r: float = tasks.C_R
    without: tuple[str, ...] = ()
    target_mode: str = "feasible"
    h0_m: float = 2.0
    feedforward: bool = True

    def task(self, num_envs: int) -> DanceTaskCfg:
        """The variant's `DanceTaskCfg`."""
        return tasks.paws_only(
            self.reward_set, num_envs, self.feedforward, c_r=self.c_r, without=self.without
        )

    def train_options(self) -> str:
        """The `quaddance train` options that train this variant."""
        opts = []
        if self.reward_set != "paper":
            opts.append(f"--reward {self.reward_set}")
        if self.c_r != tasks.C_R:
            opts.append(f"--c-r {self.c_r:g}")
        if set(self.without) == set(tasks.OUR_TERMS):
            opts.append("--without ours")
        else:
            opts += [f"--without {name}" for name in self.without]
        if self.target_mode != "feasible":
            opts.append(f"--mode {self.target_mode} --h0 {self.h0_m:g}")
        if not self.feedforward:
            opts.append("--no-feedforward")
        return " ".join(opts) or "(defaults)"


_TABLE1 = {
    name: Variant(name, f"Table 1's (c_f, lambda_f) = ({c_f:g}, {lam:g}) in eq. 6", reward_set=name)
    for name, (c_f, lam) in tasks.TABLE1.items()
    if name != "table1-5"  # (30, 10): the default's
}
#: The study's variants, by name; the default task is Table 1's set 5, (c_f, lambda_f) =
#: (30, 10), and the reference of every other.
VARIANTS: dict[str, Variant] = {
    v.name: v
    for v in (
        Variant("default", "nothing (feasible targets, feed-forward, our rewards; Table 1 set 5)"),
        Variant("l2", "the front reward's form: L2, -30 (h - h*)^2, instead of eq. 6", "l2"),
        *_TABLE1.values(),
        Variant(
            "c_r-3", "c_r = -3, our rear-lift L1 term off", c_r=-3.0, without=("rear_lift_l1",)
        ),
        Variant("c_r-30", "c_r = -30, our rear-lift L1 term off", without=("rear_lift_l1",)),
        Variant("h0-0.5", "eq. 4 targets with h0 = 0.5 m", target_mode="paper", h0_m=0.5),
        Variant("h0-2", "eq. 4 targets with h0 = 2 m (the paper's)", target_mode="paper"),
        Variant("no-ff", "the front-lift feed-forward off", feedforward=False),
        Variant(
            "paper-setup",
            "the paper's setup: eq. 4 targets with h0 = 2 m, no feed-forward, its rewards only",
            without=tasks.OUR_TERMS,
            target_mode="paper",
            feedforward=False,
        ),
    )
}

#: The held-out items every run dances (files of `quaddance.play.heldout`'s generator set).
EVAL_ITEMS: tuple[str, ...] = (
    "song_84bpm_seed9001.wav",
    "song_112bpm_seed9004.wav",
    "song_142bpm_seed9007.wav",
    "edge_style.pkl",
)

#: What decides the verdicts, fixed before the runs.
THRESHOLDS: dict[str, Any] = {
    # Front error (to the run's own targets) at least this fraction of standing still's.
    "stands_still_error_fraction": 0.95,
    # Falls on more than this fraction of the evaluation items.
    "topples_item_fraction": 0.1,
    # Mean rear-paw lift above this, m.
    "hops_rear_lift_m": 0.005,
    # Mean measured front-paw height below this, m: the front paws stay down.
    "paws_down_height_m": 0.01,
    # The training curve's front error, m (mean over `CURVE_WINDOW` iterations).
    "converged_front_err_m": 0.02,
}
#: Iterations averaged when reading the 2 cm crossing off a curve.
CURVE_WINDOW = 5

#: PPO env steps/s on this task with 256 envs on 2 CPU cores (`bench train`: 6,370; the
#: shipped 19 M-step run: 4,730 on average) and the seconds each run adds (bank, export,
#: evaluation of 4 items of 20 s): the study's estimate of its time until a run has finished.
CPU_ENV_STEPS_PER_S = 5_000
RUN_OVERHEAD_S = 40.0
#: Default budget, env steps per run, sized for the whole study (12 variants x 2 seeds: 24
#: runs) in about 2 hours on 2 CPU cores: 1.25 M steps are 204 iterations of 256 envs,
#: 24 x (1,253,376 / 5,000 + 40 s) = 6,980 s.
DEFAULT_BUDGET = 1_250_000


@dataclass
class StudyCfg:
    """A study: where it writes, what it trains and how long."""

    out: Path = Path("docs/results/study")
    work: Path = Path("runs/study")
    budget_env_steps: int = DEFAULT_BUDGET
    seeds: int = 2
    only: tuple[str, ...] = ()  # variant names; empty: all
    engine: str = "cpu"
    num_envs: int = 256
    bank_size: int = 256
    eval_items: int = len(EVAL_ITEMS)
    eval_duration_s: float = 20.0

    def __post_init__(self) -> None:
        self.variants()  # an unknown name fails here, before any work
        if self.engine not in ("cpu", "gpu"):
            raise QuaddanceError(f"unknown engine {self.engine!r}: use cpu or gpu")
        if self.seeds < 1 or self.budget_env_steps < 1 or self.num_envs < 1:
            raise QuaddanceError("the seeds, the budget and the envs must be at least 1")
        if not 1 <= self.eval_items <= len(EVAL_ITEMS):
            raise QuaddanceError(f"the evaluation takes 1 ... {len(EVAL_ITEMS)} items")

    @property
    def report(self) -> Path:
        """The markdown report, beside ``out`` (``docs/results/study.md``)."""
        return self.out.parent / f"{self.out.name}.md"

    @property
    def iterations(self) -> int:
        """PPO iterations per run: the budget, rounded up to whole iterations."""
        return max(1, math.ceil(self.budget_env_steps / (self.num_envs * STEPS_PER_ENV)))

    @property
    def env_steps_per_run(self) -> int:
        return self.iterations * self.num_envs * STEPS_PER_ENV

    def command(self) -> str:
        """The `quaddance study` command line of these settings (options left at their
        defaults are left out, except the budget and the seeds; so is ``--work-dir``, where
        checkpoints go, which changes no result)."""
        default = StudyCfg()
        opts = [f"--budget {self.budget_env_steps}", f"--seeds {self.seeds}"]
        opts += [f"--only {name}" for name in self.only]
        flags = (
            ("out", "--out"),
            ("engine", "--engine"),
            ("num_envs", "--num-envs"),
            ("bank_size", "--bank-size"),
            ("eval_items", "--eval-items"),
            ("eval_duration_s", "--eval-seconds"),
        )
        opts += [
            f"{flag} {getattr(self, name)}"
            for name, flag in flags
            if getattr(self, name) != getattr(default, name)
        ]
        return "quaddance study " + " ".join(opts)

    def variants(self) -> list[Variant]:
        """The variants to run, in `VARIANTS` order; an unknown name is a one-line error."""
        unknown = [name for name in self.only if name not in VARIANTS]
        if unknown:
            raise QuaddanceError(
                f"unknown study variant {unknown[0]!r}: use {', '.join(VARIANTS)} (--list)"
            )
        return [v for name, v in VARIANTS.items() if not self.only or name in self.only]


def list_variants() -> str:
    """One line per variant: its name, what it changes and its `train` options."""
    width = max(len(name) for name in VARIANTS)
    return "\n".join(
        f"{v.name:<{width}}  {v.changes}  [{v.train_options()}]" for v in VARIANTS.values()
    )


def result_dir(cfg: StudyCfg, variant: str, seed: int) -> Path:
    return cfg.out / variant / f"seed{seed}"


def is_finished(cfg: StudyCfg, variant: str, seed: int) -> bool:
    return (result_dir(cfg, variant, seed) / "metrics.json").is_file()


# --- training and evaluation of one run ----------------------------------------------------


def train_run(cfg: StudyCfg, variant: Variant, seed: int, log: Callable[[str], None]):
    """Train (or continue) one run in its work dir; returns the trainer."""
    from quaddance.train import TrainCfg, train

    run_dir = cfg.work / variant.name / f"seed{seed}"
    train_cfg = TrainCfg(
        run_dir=run_dir,
        engine=cfg.engine,
        iterations=cfg.iterations,
        seed=seed,
        resume=(run_dir / "checkpoint.pt").is_file(),
        bank_size=cfg.bank_size,
        target_mode=variant.target_mode,
        h0_m=variant.h0_m,
        task=variant.task(cfg.num_envs),
    )
    return train(train_cfg, progress=True, log=log)


def held_out_items(cfg: StudyCfg) -> list[Path]:
    """The evaluation items, written once into the work dir (the same files everywhere)."""
    from quaddance.play.heldout import write_held_out_set

    folder = cfg.work / f"heldout_{cfg.eval_duration_s:g}s"
    wanted = [folder / name for name in EVAL_ITEMS[: cfg.eval_items]]
    if not all(p.is_file() for p in wanted):
        write_held_out_set(folder, "generator", cfg.eval_duration_s)
    return wanted


def _feasible_targets(
    item: Path, max_height_m: float, cache: dict[tuple[Path, float], np.ndarray]
) -> np.ndarray:
    """The feasible paw targets of ``item``'s dance (seed 0) up to ``max_height_m``, (T, 4)."""
    if (item, max_height_m) not in cache:
        from quaddance.pipeline import DanceSpec, make_dance
        from quaddance.targets import TargetConfig

        is_song = item.suffix == ".wav"
        spec = DanceSpec(targets=TargetConfig(max_height_m=max_height_m))
        dance, _ = make_dance(item if is_song else None, None if is_song else item, spec)
        cache[item, max_height_m] = dance.targets_m
    return cache[item, max_height_m]


def evaluate_run(
    policy: Path,
    items: Sequence[Path],
    scratch: Path,
    feasible: dict[tuple[Path, float], np.ndarray],
) -> dict[str, Any]:
    """Dance each item with ``policy`` (its own kind of targets) and measure it against
    those and against the feasible targets of the same dance in the policy's range;
    ``scratch`` keeps each item's dance, rollout and foot plot; ``feasible``: a cache."""
    from quaddance.play.dance import DanceJob, run_dance
    from quaddance.play.metrics import tracking_metrics

    max_height_m = json.loads(policy.with_suffix(".json").read_text())["targets"]["max_height_m"]
    per_item = []
    for i, item in enumerate(items):
        is_song = item.suffix == ".wav"
        job = DanceJob(
            out_dir=scratch / f"{i}",
            song=item if is_song else None,
            motion=None if is_song else item,
            policy=policy,
            video=False,
        )
        m = run_dance(job).metrics
        with np.load(scratch / f"{i}" / "rollout.npz") as r:
            feet, own = r["foot_heights_m"], r["targets_m"]
        ref = _feasible_targets(item, max_height_m, feasible)
        n = min(len(ref), len(feet))
        ref, feet, own = ref[:n], feet[:n], own[:n]
        all_frames = np.ones((n, 2), bool)
        to_own = tracking_metrics(own, feet, all_frames)
        to_feasible = tracking_metrics(ref, feet, all_frames)
        per_item.append(
            {
                "name": item.name,
                "falls": len(m["falls_s"]),
                "mae_own_m": _mean(to_own[f]["mae_m"] for f in ("fl", "fr")),
                "corr_own": _mean(to_own[f]["corr"] for f in ("fl", "fr")),
                "mae_feasible_m": _mean(to_feasible[f]["mae_m"] for f in ("fl", "fr")),
                "corr_feasible": _mean(to_feasible[f]["corr"] for f in ("fl", "fr")),
                "standing_mae_own_m": float(np.abs(own[:, :2]).mean()),
                "standing_mae_feasible_m": float(np.abs(ref[:, :2]).mean()),
                "front_height_mean_m": float(feet[:, :2].mean()),
                "rear_lift_mean_m": m["rear_lift_mean_m"],
                "rear_lift_max_m": m["rear_lift_max_m"],
                "beat_coverage": m.get("beat_coverage"),
            }
        )
    summary = {k: _mean(r[k] for r in per_item) for k in per_item[0] if k not in ("name", "falls")}
    summary["falls"] = sum(r["falls"] for r in per_item)
    summary["fall_item_fraction"] = sum(r["falls"] > 0 for r in per_item) / len(per_item)
    return {"summary": summary, "items": per_item}


def _mean(values) -> float | None:
    vals = [float(v) for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(vals)) if vals else None


def steps_to_front_err(curve: Path, err_m: float) -> int | None:
    """Env steps at which the curve's front error (mean of `CURVE_WINDOW` iterations) first
    reaches ``err_m``; None: never."""
    from quaddance.train import read_curve

    cols = read_curve(curve)
    err = cols["front_abs_err_m"]
    k = min(CURVE_WINDOW, len(err))
    smooth = np.convolve(err, np.ones(k) / k, "valid")
    hit = np.flatnonzero(smooth <= err_m)
    return None if hit.size == 0 else int(cols["env_steps"][hit[0] + k - 1])


def finish_run(
    cfg: StudyCfg,
    variant: Variant,
    seed: int,
    trainer,
    items: Sequence[Path],
    feasible: dict[tuple[Path, float], np.ndarray],
) -> dict[str, Any]:
    """Evaluate a trained run and write its results; ``metrics.json`` last."""
    run_dir = trainer.cfg.run_dir
    t0 = time.monotonic()
    scratch = run_dir / "eval"
    evaluation = evaluate_run(run_dir / "policy.onnx", items, scratch, feasible)
    out = result_dir(cfg, variant.name, seed)
    out.mkdir(parents=True, exist_ok=True)
    for src, name in (
        (run_dir / "policy.onnx", "policy.onnx"),
        (run_dir / "policy.json", "policy.json"),
        (run_dir / "curve.csv", "curve.csv"),
        (scratch / "0" / "feet.png", "feet.png"),
    ):
        with atomic_path(out / name) as tmp:
            shutil.copyfile(src, tmp)
    metrics = {
        "variant": variant.name,
        "changes": variant.changes,
        "train_options": variant.train_options(),
        "seed": seed,
        "budget_env_steps": cfg.budget_env_steps,
        "env_steps": trainer.env_steps,
        "iterations": trainer.iteration,
        "num_envs": cfg.num_envs,
        "engine": cfg.engine,
        "train_wall_s": round(trainer.wall_s, 1),
        "eval_wall_s": round(time.monotonic() - t0, 1),
        "env_steps_to_2cm": steps_to_front_err(
            run_dir / "curve.csv", THRESHOLDS["converged_front_err_m"]
        ),
        "eval_items": [p.name for p in items],
        "eval_duration_s": cfg.eval_duration_s,
        **evaluation,
    }
    write_json(out / "metrics.json", metrics)
    return metrics


# --- the study -----------------------------------------------------------------------------


def run_study(cfg: StudyCfg, log: Callable[[str], None] = print) -> dict[str, Any]:
    """Train and evaluate every run not finished yet, then write the report; returns it."""
    variants = cfg.variants()
    check_settings(cfg)
    runs = [(v, s) for v in variants for s in range(1, cfg.seeds + 1)]
    todo = [(v, s) for v, s in runs if not is_finished(cfg, v.name, s)]
    for v, s in runs:
        if (v, s) not in todo:
            log(f"{v.name} seed {s}: finished earlier, skipped ({result_dir(cfg, v.name, s)})")
    items = held_out_items(cfg) if todo else []
    feasible: dict[tuple[Path, float], np.ndarray] = {}
    spent_s = 0.0
    for i, (variant, seed) in enumerate(todo):
        per_run_s = (
            spent_s / i if i else cfg.env_steps_per_run / CPU_ENV_STEPS_PER_S + RUN_OVERHEAD_S
        )
        left = f"about {_duration(per_run_s * (len(todo) - i))}"
        log(
            f"[{i + 1}/{len(todo)}] {variant.name} seed {seed}: {variant.changes}; "
            f"{cfg.iterations} iterations ({cfg.env_steps_per_run:,} env steps); study time "
            f"left {left}"
        )
        t0 = time.monotonic()
        trainer = train_run(cfg, variant, seed, log)
        metrics = finish_run(cfg, variant, seed, trainer, items, feasible)
        spent_s += time.monotonic() - t0
        s = metrics["summary"]
        log(
            f"{variant.name} seed {seed}: done in {_duration(time.monotonic() - t0)}; falls "
            f"{s['falls']}, front MAE {_cm(s['mae_own_m'])} (feasible {_cm(s['mae_feasible_m'])}),"
            f" rear lift {_cm(s['rear_lift_mean_m'])}"
        )
        write_report(cfg)
    return write_report(cfg)


#: Settings every run of one study shares: (metrics key, `StudyCfg` field, option). Not the
#: engine: a study begun on a CPU may go on where a GPU is lent.
SHARED = (
    ("budget_env_steps", "budget_env_steps", "--budget"),
    ("num_envs", "num_envs", "--num-envs"),
    ("eval_duration_s", "eval_duration_s", "--eval-seconds"),
)


def check_settings(cfg: StudyCfg) -> None:
    """Refuse to add runs to ``out`` that would not be comparable with its finished ones."""
    for runs in load_finished(cfg).values():
        for run in runs:
            for key, name, option in SHARED:
                if run[key] != getattr(cfg, name):
                    raise QuaddanceError(
                        f"{cfg.out} holds runs made with {option} {run[key]}: give the same "
                        f"or another --out"
                    )
            if run["eval_items"] != list(EVAL_ITEMS[: cfg.eval_items]):
                raise QuaddanceError(
                    f"{cfg.out} holds runs evaluated on {len(run['eval_items'])} items: give "
                    f"--eval-items {len(run['eval_items'])} or another --out"
                )


def _duration(seconds: float) -> str:
    minutes = round(seconds / 60)
    return f"{minutes // 60} h {minutes % 60:02d} min" if minutes >= 60 else f"{minutes} min"


def _cm(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.1f} cm"


# --- the report ----------------------------------------------------------------------------

#: Table columns: (key in a run's metrics summary or the run itself, heading, scale, digits).
COLUMNS: tuple[tuple[str, str, float, int], ...] = (
    ("fall_item_fraction", "items with a fall", 1.0, 2),
    ("mae_own_m", "front MAE, own targets (cm)", 100.0, 1),
    ("standing_mae_own_m", "standing still, own (cm)", 100.0, 1),
    ("corr_own", "corr, own", 1.0, 2),
    ("mae_feasible_m", "front MAE, feasible (cm)", 100.0, 1),
    ("corr_feasible", "corr, feasible", 1.0, 2),
    ("front_height_mean_m", "front paw height (cm)", 100.0, 1),
    ("rear_lift_mean_m", "rear lift (cm)", 100.0, 2),
    ("beat_coverage", "beat coverage", 1.0, 2),
    ("env_steps_to_2cm", "M env steps to 2 cm", 1e-6, 2),
    ("wall_s", "wall (min)", 1 / 60, 1),
)


def load_finished(cfg: StudyCfg) -> dict[str, list[dict[str, Any]]]:
    """Every finished run under ``out``, by variant (in `VARIANTS` order), seeds sorted."""
    found: dict[str, list[dict[str, Any]]] = {}
    for name in VARIANTS:
        paths = sorted((cfg.out / name).glob("seed*/metrics.json"))
        runs = [json.loads(p.read_text()) for p in paths]
        if runs:
            found[name] = runs
    return found


def _value(run: dict[str, Any], key: str) -> float | None:
    if key == "env_steps_to_2cm":
        return run[key]
    if key == "wall_s":
        return run["train_wall_s"] + run["eval_wall_s"]
    return run["summary"].get(key)


def stats(runs: list[dict[str, Any]], key: str) -> dict[str, Any]:
    """Mean and spread (half the range) over seeds; for the 2 cm crossing, how many never."""
    values = [_value(r, key) for r in runs]
    known = [v for v in values if v is not None]
    out: dict[str, Any] = {"values": values, "mean": None, "spread": None}
    if known:
        out["mean"] = float(np.mean(known))
        out["spread"] = float((max(known) - min(known)) / 2)
    out["missing"] = len(values) - len(known)
    return out


def _cell(s: dict[str, Any], scale: float, digits: int, key: str) -> str:
    if s["mean"] is None:
        return "never" if key == "env_steps_to_2cm" else "-"
    text = f"{s['mean'] * scale:.{digits}f} ± {s['spread'] * scale:.{digits}f}"
    if key == "env_steps_to_2cm" and s["missing"]:
        text += f" ({s['missing']} never)"
    return text


def _mean_of(table: dict[str, Any], variant: str, key: str) -> float | None:
    return table.get(variant, {}).get(key, {}).get("mean")


def verdicts(table: dict[str, dict[str, Any]], runs: dict[str, list[dict]]) -> list[dict]:
    """Each of the paper's claims: ``holds``, ``does not hold`` or ``inconclusive at this
    budget``, with the numbers that decide it (`THRESHOLDS`)."""
    th = THRESHOLDS

    def contrast(
        claim: str,
        rule: str,
        pair: tuple[str, str],
        effect: Callable[[dict[str, Any]], bool],
        keys: tuple[str, ...],
    ) -> dict[str, Any]:
        """A claim that ``effect`` shows in the first variant of ``pair`` and not in the
        second; seed by seed (holds: every seed shows it; does not hold: no seed of the first
        shows the effect; not run until both variants have the same seeds finished)."""
        first = [effect(r) for r in runs.get(pair[0], [])]
        second = [effect(r) for r in runs.get(pair[1], [])]
        yes = [a and not b for a, b in zip(first, second, strict=False)]
        verdict = "not run" if len(first) != len(second) else decide(yes, [not a for a in first])
        return {
            "claim": claim,
            "verdict": verdict,
            "rule": rule,
            "numbers": nums(pair, keys),
            "figures": [f"{name}/seed1/feet.png" for name in pair],
        }

    def stands_still(r: dict[str, Any]) -> bool:
        s = r["summary"]
        return s["mae_own_m"] >= th["stands_still_error_fraction"] * s["standing_mae_own_m"]

    def topples_or_hops(r: dict[str, Any]) -> bool:
        s = r["summary"]
        return (
            s["fall_item_fraction"] > th["topples_item_fraction"]
            or s["rear_lift_mean_m"] > th["hops_rear_lift_m"]
        )

    def paws_down(r: dict[str, Any]) -> bool:
        return r["summary"]["front_height_mean_m"] < th["paws_down_height_m"]

    def decide(yes: list[bool], no: list[bool]) -> str:
        """``yes``: per seed, the claim's effect is seen; ``no``: per seed, its opposite."""
        if not yes and not no:
            return "not run"
        if yes and all(yes):
            return "holds"
        if no and all(no):
            return "does not hold"
        return "inconclusive at this budget"

    def nums(variants: Sequence[str], keys: Sequence[str]) -> str:
        parts = []
        for v in variants:
            shown = [
                f"{k} {_mean_of(table, v, k):.3g}"
                for k in keys
                if _mean_of(table, v, k) is not None
            ]
            parts.append(f"{v}: " + (", ".join(shown) if shown else "not run"))
        return "; ".join(parts)

    # 1. An L2 reward left the robot standing still (section 4.3.2), eq. 6 did not.
    out = [
        contrast(
            "An L2 front reward leaves the robot standing still; eq. 6 does not.",
            "stands still: front MAE to its own targets >= "
            f"{th['stands_still_error_fraction']} x standing still's",
            ("l2", "default"),
            stands_still,
            ("mae_own_m", "standing_mae_own_m"),
        )
    ]
    # 2. (c_f, lambda_f) = (30, 10) is the best of Table 1's five sets.
    sets = ["default", *_TABLE1]
    errs = {v: _mean_of(table, v, "mae_feasible_m") for v in sets}
    spreads = {v: table.get(v, {}).get("mae_feasible_m", {}).get("spread") for v in sets}
    ran = [v for v in sets if errs[v] is not None]
    verdict = "not run"
    if "default" in ran and len(ran) == len(sets):
        best = min(ran, key=lambda v: errs[v])
        if best == "default":
            verdict = "holds"
        elif errs[best] + spreads[best] < errs["default"] - spreads["default"]:
            verdict = "does not hold"
        else:
            verdict = "inconclusive at this budget"
    out.append(
        {
            "claim": "Table 1's set 5, (c_f, lambda_f) = (30, 10), tracks best of the five sets.",
            "verdict": verdict,
            "rule": "holds: the lowest held-out front MAE to the feasible targets (mean over "
            "seeds); does not hold: another set lower by more than both spreads",
            "numbers": nums(sets, ("mae_feasible_m", "env_steps_to_2cm")),
            "figures": ["curves.png"],
        }
    )
    # 3. A small |c_r| lets the rear feet hop and the robot topple; c_r = -30 does not.
    out.append(
        contrast(
            "With a small |c_r| (-3) the rear feet hop and the robot topples; "
            "c_r = -30 keeps them down (our rear-lift L1 term off in both).",
            f"topples: falls on more than {th['topples_item_fraction']:.0%} of the items; "
            f"hops: mean rear lift above {_cm(th['hops_rear_lift_m'])}",
            ("c_r-3", "c_r-30"),
            topples_or_hops,
            ("fall_item_fraction", "rear_lift_mean_m"),
        )
    )
    # 4. h0 = 0.5 keeps the front paws on the floor (reward hacking); h0 = 2 dances.
    out.append(
        contrast(
            "Eq. 4 with h0 = 0.5 m keeps the front paws on the floor; h0 = 2 m makes the robot "
            "lift them.",
            "paws down: mean measured front-paw height below "
            + _cm(th["paws_down_height_m"])
            + "; the feed-forward, on in both, lifts the paws toward their targets by itself: "
            "paper-setup's row shows h0 = 2 m without it",
            ("h0-0.5", "h0-2"),
            paws_down,
            ("front_height_mean_m", "beat_coverage"),
        )
    )
    return out


def write_report(cfg: StudyCfg) -> dict[str, Any]:
    """``study.md`` and ``study.json`` from every finished run under ``out``, and the curves
    of all variants in one figure (``out/curves.png``)."""
    runs = load_finished(cfg)
    table = {v: {key: stats(rs, key) for key, *_ in COLUMNS} for v, rs in runs.items()}
    claims = verdicts(table, runs)
    if runs:
        plot_curves(cfg.out / "curves.png", cfg.out, runs)
    report = {
        "command": cfg.command(),
        "budget_env_steps": cfg.budget_env_steps,
        "seeds": cfg.seeds,
        "machine": _machine(cfg.engine),
        "thresholds": THRESHOLDS,
        "eval_items": list(EVAL_ITEMS[: cfg.eval_items]),
        "variants": {
            v.name: {"changes": v.changes, "train_options": v.train_options()}
            for v in VARIANTS.values()
        },
        "table": table,
        "claims": claims,
    }
    write_json(cfg.report.with_suffix(".json"), report)
    with atomic_path(cfg.report) as tmp:
        tmp.write_text(markdown(cfg, report, runs))
    return report


def _machine(engine: str) -> str:
    import os
    import platform

    return f"{platform.machine()}, {os.cpu_count()} CPU cores, engine {engine}"


def markdown(cfg: StudyCfg, report: dict[str, Any], runs: dict[str, list[dict]]) -> str:
    """The report's text: the settings, the thresholds, the table, the curves, the claims."""
    rel = cfg.out.name
    finished = sum(len(seeds) for seeds in runs.values())
    th = THRESHOLDS
    lines = [
        "# The paper's study (section 4.3), repeated",
        "",
        f"Made by `{report['command']}` on {report['machine']}: each variant trained "
        f"{cfg.env_steps_per_run:,} env steps per seed ({cfg.iterations} PPO iterations of "
        f"{cfg.num_envs} envs), {cfg.seeds} seed{'s' if cfg.seeds > 1 else ''}, paws only, "
        f"Go1, the rest as `quaddance train` makes it; {finished} of "
        f"{len(VARIANTS) * cfg.seeds} runs finished. "
        "A finished run lies in "
        f"`{rel}/<variant>/seed<k>/` (policy.onnx + .json, playable with `quaddance dance "
        "--policy`; curve.csv; metrics.json; feet.png). Variants with fewer finished seeds than "
        "asked are marked in the table; the study continues where it stopped when run again.",
        "",
        "## Thresholds (fixed before the runs)",
        "",
        f"- *stands still*: front MAE to its own targets at least "
        f"{th['stands_still_error_fraction']} x that of a robot that does not move (the mean "
        "|target|);",
        f"- *topples*: falls on more than {th['topples_item_fraction']:.0%} of the items; "
        f"*hops*: mean rear-paw lift above {_cm(th['hops_rear_lift_m'])};",
        f"- *paws down*: mean measured front-paw height below {_cm(th['paws_down_height_m'])};",
        f"- *converged*: the training curve's front error (mean of {CURVE_WINDOW} iterations) at "
        f"{_cm(th['converged_front_err_m'])} or less; *never* if it does not get there;",
        "- a claim *holds* when every seed shows its effect, *does not hold* when every seed "
        "shows the opposite, else it is *inconclusive at this budget*.",
        "",
        f"Evaluation: {', '.join(report['eval_items'])} ({cfg.eval_duration_s:g} s each, the "
        "held-out generator set), no domain randomisation, each run dancing the kind of targets "
        "it trained on; *own* = those targets, *feasible* = the feasible targets of the same "
        "dance. Values: mean ± half the range over seeds.",
        "",
        "## Variants",
        "",
        "| variant | changes | seeds done | " + " | ".join(head for _, head, *_ in COLUMNS) + " |",
        "|---|---|---|" + "---|" * len(COLUMNS),
    ]
    for name, v in VARIANTS.items():
        if name not in runs:
            lines.append(f"| {name} | {v.changes} | 0/{cfg.seeds} |" + " |" * len(COLUMNS))
            continue
        cells = [_cell(report["table"][name][key], scale, d, key) for key, _, scale, d in COLUMNS]
        lines.append(
            f"| {name} | {v.changes} | {len(runs[name])}/{cfg.seeds} | " + " | ".join(cells) + " |"
        )
    lines += [
        "",
        f"![front error during training, all variants]({rel}/curves.png)",
        "",
        "## The paper's claims",
        "",
        "The foot-height plots (`feet.png`, the first item danced by seed 1) show targets and "
        "measured paw heights as the paper's Fig. 13 does.",
        "",
    ]
    for c in report["claims"]:
        figures = ", ".join(f"[{f}]({rel}/{f})" for f in c["figures"])
        lines.append(
            f"- **{c['claim']}** {c['verdict'].capitalize()} ({c['rule']}). {c['numbers']}. "
            f"Figures: {figures}."
        )
    return "\n".join(lines) + "\n"


def plot_curves(path: Path, out: Path, runs: dict[str, list[dict]]) -> Path:
    """Front error during training of every variant (seeds averaged where they overlap)."""
    from quaddance.play.plots import save_figure, subplots
    from quaddance.train import read_curve

    fig, ax = subplots(1, 1, figsize=(9, 5))
    for name, seeds in runs.items():
        cols = [read_curve(out / name / f"seed{r['seed']}" / "curve.csv") for r in seeds]
        n = min(len(c["env_steps"]) for c in cols)
        err = np.mean([c["front_abs_err_m"][:n] for c in cols], axis=0)
        k = max(1, min(CURVE_WINDOW, n))
        smooth = np.convolve(err, np.ones(k) / k, "valid")
        ax.plot(cols[0]["env_steps"][k - 1 : n] / 1e6, 100 * smooth, label=name, lw=1.2)
    ax.axhline(100 * THRESHOLDS["converged_front_err_m"], color="0.3", ls="--", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("env steps (millions)")
    ax.set_ylabel("front-paw |h - h*| to own targets (cm), training")
    ax.legend(frameon=False, fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)
    return path
