"""`quaddance study`: the variants, the verdicts, a tiny study end to end, skipping finished
runs and resuming an interrupted one, the command's options."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from quaddance import study
from quaddance.cli import app, main
from quaddance.errors import QuaddanceError
from quaddance.sim import tasks

TINY = {"budget_env_steps": 300, "num_envs": 8, "bank_size": 2, "seeds": 1}
TINY_EVAL = {"eval_items": 1, "eval_duration_s": 4.0}


# --- the variants --------------------------------------------------------------------------


def test_each_variant_changes_one_factor_of_the_default_task():
    default = study.VARIANTS["default"]
    assert default.task(256) == tasks.paws_only()
    assert (default.target_mode, default.feedforward) == ("feasible", True)
    base = tasks.dance_rewards()
    for name in ("l2", "table1-1", "table1-2", "table1-3", "table1-4"):
        rewards = study.VARIANTS[name].task(256).rewards
        changed = {k for k in base if rewards[k] != base[k]}
        assert changed == {"front_tracking"}, name
    for name, c_r in (("c_r-3", -3.0), ("c_r-30", -30.0)):
        rewards = study.VARIANTS[name].task(256).rewards
        assert rewards["rear_lift"].weight == c_r
        assert set(base) - set(rewards) == {"rear_lift_l1"}
    for name, h0 in (("h0-0.5", 0.5), ("h0-2", 2.0)):
        v = study.VARIANTS[name]
        assert (v.target_mode, v.h0_m, v.task(256)) == ("paper", h0, tasks.paws_only())
    assert study.VARIANTS["no-ff"].task(256) == tasks.paws_only(front_feedforward=False)
    paper = study.VARIANTS["paper-setup"]
    assert (paper.target_mode, paper.h0_m, paper.feedforward) == ("paper", 2.0, False)
    assert set(base) - set(paper.task(256).rewards) == set(tasks.OUR_TERMS)
    assert paper.train_options() == "--without ours --mode paper --h0 2 --no-feedforward"


def test_steps_to_2cm_reads_the_smoothed_curve(tmp_path):
    curve = tmp_path / "curve.csv"
    errs = [0.05, 0.03, 0.019, 0.05, 0.018, 0.018, 0.018, 0.018, 0.018, 0.018]
    rows = [f"{i + 1},{1000 * (i + 1)},{e}" for i, e in enumerate(errs)]
    curve.write_text("iteration,env_steps,front_abs_err_m\n" + "\n".join(rows) + "\n")
    # The first 5-iteration mean at or below 2 cm ends at iteration 9 (not the lone 1.9 cm).
    assert study.steps_to_front_err(curve, 0.02) == 9000
    assert study.steps_to_front_err(curve, 0.01) is None


def _run(name: str, seed: int, **summary: float) -> dict:
    base = {
        "mae_own_m": 0.01,
        "standing_mae_own_m": 0.03,
        "mae_feasible_m": 0.01,
        "fall_item_fraction": 0.0,
        "rear_lift_mean_m": 0.0,
        "front_height_mean_m": 0.03,
    }
    return {"variant": name, "seed": seed, "env_steps_to_2cm": None, "summary": base | summary}


def _verdicts(runs: dict[str, list[dict]]) -> dict[str, str]:
    table = {
        v: {k: study.stats(rs, k) for k, *_ in study.COLUMNS if k != "wall_s"}
        for v, rs in runs.items()
    }
    return {c["claim"][:12]: c["verdict"] for c in study.verdicts(table, runs)}


def test_verdicts_follow_the_thresholds():
    runs = {
        "default": [_run("default", s) for s in (1, 2)],
        "l2": [_run("l2", s, mae_own_m=0.03) for s in (1, 2)],
        "c_r-3": [_run("c_r-3", 1, fall_item_fraction=0.5), _run("c_r-3", 2)],
        "c_r-30": [_run("c_r-30", s) for s in (1, 2)],
        "h0-0.5": [_run("h0-0.5", s, front_height_mean_m=0.03) for s in (1, 2)],
        "h0-2": [_run("h0-2", s) for s in (1, 2)],
    }
    for name in ("table1-1", "table1-2", "table1-3", "table1-4"):
        runs[name] = [_run(name, s, mae_feasible_m=0.02) for s in (1, 2)]
    got = _verdicts(runs)
    assert got == {
        "An L2 front ": "holds",
        "Table 1's se": "holds",
        "With a small": "inconclusive at this budget",  # one seed of two toppled
        "Eq. 4 with h": "does not hold",  # h0 = 0.5 lifted its paws
    }
    runs["table1-2"] = [_run("table1-2", s, mae_feasible_m=0.005) for s in (1, 2)]
    del runs["l2"]
    got = _verdicts(runs)
    assert (got["Table 1's se"], got["An L2 front "]) == ("does not hold", "not run")


# --- options -------------------------------------------------------------------------------


def test_study_list_prints_every_variant_with_what_it_changes():
    result = CliRunner().invoke(app, ["study", "--list"])
    assert result.exit_code == 0
    for name, v in study.VARIANTS.items():
        assert name in result.output and v.changes in result.output


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--only", "default,nope"], "unknown study variant 'nope'"),
        (["--engine", "tpu"], "unknown engine 'tpu'"),
        (["--seeds", "0"], "--seeds"),
        (["--budget", "0"], "--budget"),
        (["--eval-items", "9"], "--eval-items"),
    ],
)
def test_study_rejects_bad_options_in_one_line(tmp_path, monkeypatch, capsys, args, needle):
    out = tmp_path / "study"
    monkeypatch.setattr(sys, "argv", ["quaddance", "study", "--out", str(out), *args])
    with pytest.raises(SystemExit) as stop:
        main()
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert needle in err
    assert not out.exists()


def test_the_command_defaults_are_the_study_defaults():
    import inspect

    from quaddance.cli.study import study_cmd

    defaults = {k: p.default for k, p in inspect.signature(study_cmd).parameters.items()}
    cfg = study.StudyCfg()
    assert (defaults["budget"], defaults["seeds"], defaults["out"]) == (
        cfg.budget_env_steps,
        cfg.seeds,
        cfg.out,
    )
    assert cfg.report == Path("docs/results/study.md")
    # Where the checkpoints go changes no result: the report's command leaves it out.
    moved = study.StudyCfg(work=Path("/elsewhere/runs"))
    assert moved.command() == cfg.command() == "quaddance study --budget 1250000 --seeds 2"


def test_an_unknown_variant_fails_before_any_work(tmp_path):
    with pytest.raises(QuaddanceError, match="unknown study variant 'x'"):
        study.StudyCfg(out=tmp_path / "s", only=("x",))


# --- a tiny study --------------------------------------------------------------------------


def test_a_tiny_study_runs_skips_finished_runs_and_resumes_an_interrupted_one(
    tmp_path, monkeypatch
):
    cfg = study.StudyCfg(
        out=tmp_path / "study",
        work=tmp_path / "work",
        only=("default", "h0-0.5"),
        **TINY,
        **TINY_EVAL,
    )
    args = ["study", "--budget", "300", "--num-envs", "8", "--bank-size", "2", "--seeds", "1"]
    args += ["--eval-items", "1", "--eval-seconds", "4", "--only", "default,h0-0.5"]
    args += ["--out", str(cfg.out), "--work-dir", str(cfg.work)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "[1/2] default seed 1" in result.output and "study time left about" in result.output
    report = json.loads(cfg.report.with_suffix(".json").read_text())
    for name in ("default", "h0-0.5"):
        done = cfg.out / name / "seed1"
        for file in ("policy.onnx", "policy.json", "curve.csv", "feet.png", "metrics.json"):
            assert (done / file).stat().st_size > 0, file
        metrics = json.loads((done / "metrics.json").read_text())
        assert metrics["env_steps"] >= 300 and metrics["eval_items"] == [study.EVAL_ITEMS[0]]
        assert set(metrics["summary"]) >= {"falls", "mae_own_m", "corr_feasible", "beat_coverage"}
    policy = json.loads((cfg.out / "h0-0.5" / "seed1" / "policy.json").read_text())
    assert policy["targets"]["mode"] == "paper" and policy["targets"]["h0_m"] == 0.5
    assert set(report["table"]) == {"default", "h0-0.5"}
    text = cfg.report.read_text()
    assert cfg.report == tmp_path / "study.md" and (tmp_path / "study.json").is_file()
    assert "| default |" in text and "| l2 |" in text and "0/1" in text  # l2: not run
    assert cfg.command() in text and (cfg.out / "curves.png").is_file()
    assert "--only default --only h0-0.5" in cfg.command()

    # A rerun trains nothing and writes no finished run again.
    stamps = {p: p.stat().st_mtime_ns for p in cfg.out.glob("*/seed1/*")}

    def no_training(*args, **kwargs):
        raise AssertionError("a finished run was trained again")

    monkeypatch.setattr(study, "train_run", no_training)
    lines: list[str] = []
    study.run_study(cfg, log=lambda line: lines.append(str(line)))
    assert sum("finished earlier, skipped" in line for line in lines) == 2
    assert {p: p.stat().st_mtime_ns for p in cfg.out.glob("*/seed1/*")} == stamps
    monkeypatch.undo()

    # Interrupted during its evaluation: the next call resumes the run, not a new one.
    more = study.StudyCfg(out=cfg.out, work=cfg.work, only=("no-ff",), **TINY, **TINY_EVAL)
    real = study.evaluate_run

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(study, "evaluate_run", interrupted)
    with pytest.raises(KeyboardInterrupt):
        study.run_study(more, log=lambda line: None)
    assert not study.is_finished(more, "no-ff", 1)
    monkeypatch.setattr(study, "evaluate_run", real)
    lines.clear()
    study.run_study(more, log=lambda line: lines.append(str(line)))
    assert any("resumed" in line and "iteration 2" in line for line in lines), lines
    assert study.is_finished(more, "no-ff", 1)
    assert "| no-ff |" in cfg.report.read_text()

    # Runs of another budget do not join this study.
    with pytest.raises(QuaddanceError, match="--budget 300"):
        study.run_study(study.StudyCfg(out=cfg.out, work=cfg.work, only=("l2",)))


def test_each_run_dances_its_own_targets_and_is_compared_with_the_feasible_ones(tmp_path):
    """The feasible reference is the same dance's feasible targets: a run dancing feasible
    targets scores the same against both."""
    cfg = study.StudyCfg(out=tmp_path / "s", work=tmp_path / "w", **TINY_EVAL)
    items = study.held_out_items(cfg)
    from quaddance.play.policy import shipped_policy_path

    got = study.evaluate_run(shipped_policy_path(), items, tmp_path / "eval", {})
    s = got["summary"]
    assert s["mae_feasible_m"] == pytest.approx(s["mae_own_m"], abs=1e-6)
    assert s["mae_own_m"] < s["standing_mae_own_m"]  # the shipped policy dances
    assert np.isfinite(s["corr_feasible"]) and s["falls"] == 0
