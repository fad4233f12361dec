"""`quaddance eval`: randomised and pinned dynamics, the feed-forward-only baseline, the JSON
report beside the markdown, and the CLI flags that select them."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
import torch
from dance_keys import DANCE_METRIC_KEYS
from typer.testing import CliRunner

from quaddance.cli import app
from quaddance.dancefile import Dance
from quaddance.errors import QuaddanceError
from quaddance.music.synth import render_song
from quaddance.play import evaluate as evaluate_mod
from quaddance.play.evaluate import EvalSettings, evaluate, evaluate_items, summarize
from quaddance.play.metrics import dance_metrics
from quaddance.play.policy import OnnxPolicy, shipped_policy_path
from quaddance.play.rollout import PinnedDynamics, playback_env, rollout
from quaddance.robots import GO1

METRICS_JSON_KEYS = DANCE_METRIC_KEYS | {
    "source",
    "policy",
    "mode",
    "body",
    "beat_coverage",
    "clamped",
    "timings_s",
}


@pytest.fixture(scope="module")
def song(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("song") / "song_4s.wav"
    y, _ = render_song(120.0, 4.0, seed=3)
    sf.write(path, y, 22050)
    return path


@pytest.fixture(scope="module")
def policy() -> OnnxPolicy:
    return OnnxPolicy.load(shipped_policy_path())


def lift_dance(duration_s: float = 3.0, height_m: float = 0.15) -> Dance:
    """A dance at 50 Hz: the front-left foot lifts to ``height_m`` from 1 s to 2 s."""
    t = np.arange(int(duration_s * 50)) / 50.0
    targets = np.zeros((t.size, 4))
    inside = (t >= 1.0) & (t <= 2.0)
    targets[inside, 0] = height_m * np.sin(np.pi * (t[inside] - 1.0)) ** 2
    return Dance(
        fps=50.0,
        time_s=t,
        human_feet_m=targets[:, :2].copy(),
        targets_m=targets,
        beats_s=np.zeros(0),
        downbeats_s=np.zeros(0),
        mode="feasible",
        source="test lift",
        seed=0,
        version="test",
    )


# --- randomised dynamics and the JSON report ----------------------------------------------


@pytest.fixture(scope="module")
def nominal_and_randomised(song, tmp_path_factory):
    out = tmp_path_factory.mktemp("eval")
    nominal = evaluate([song], None, out / "nominal.md")
    randomised = evaluate([song], None, out / "randomised.md", EvalSettings(randomize=True))
    return out, nominal, randomised


def test_randomised_metrics_differ_from_nominal_on_the_same_item(nominal_and_randomised):
    _, nominal, randomised = nominal_and_randomised
    n, r = nominal[0], randomised[0]
    assert n["name"] == r["name"]
    diffs = [
        abs(n["front"][f][k] - r["front"][f][k])
        for f in ("fl", "fr")
        for k in ("mae_m", "corr")
        if n["front"][f][k] is not None and r["front"][f][k] is not None
    ]
    assert max(diffs) > 1e-4
    assert n["rear_lift_max_m"] != r["rear_lift_max_m"]


def test_nominal_playback_repeats_exactly(song, nominal_and_randomised):
    """So the difference above comes from the randomisation, not from noise."""
    _, nominal, _ = nominal_and_randomised
    again = evaluate_items([song], None)
    assert again[0]["front"] == nominal[0]["front"]
    assert again[0]["rear_lift_max_m"] == nominal[0]["rear_lift_max_m"]


def test_report_json_holds_every_metric_of_each_item_and_the_mean(nominal_and_randomised):
    out, _, randomised = nominal_and_randomised
    data = json.loads((out / "randomised.json").read_text())
    assert set(data) >= {"items", "mean"}
    assert [item["name"] for item in data["items"]] == ["song_4s.wav"]
    assert set(data["items"][0]) == {"name"} | METRICS_JSON_KEYS
    assert data["items"][0]["front"] == randomised[0]["front"]
    assert data["mean"] == json.loads(json.dumps(summarize(randomised)))
    assert data["settings"]["randomize"] is True
    text = (out / "randomised.md").read_text()
    assert "randomised as in training" in text
    assert "no domain randomisation" in (out / "nominal.md").read_text()


def test_report_json_is_written_atomically(nominal_and_randomised, monkeypatch):
    """A failure while writing leaves the previous JSON whole and no temporary file."""
    out, nominal, _ = nominal_and_randomised
    json_path = out / "nominal.json"
    before = json_path.read_bytes()
    bad_row = {**nominal[0], "unserialisable": object()}
    monkeypatch.setattr(evaluate_mod, "evaluate_items", lambda *a, **k: [bad_row])
    with pytest.raises(TypeError):
        evaluate([Path("x.wav")], None, out / "nominal.md")
    assert json_path.read_bytes() == before
    assert not list(out.glob(".nominal.*"))


def test_each_item_gets_its_own_randomised_robot(policy):
    dance = lift_dance()
    envs = [playback_env(dance, policy, randomize=True, seed=s) for s in (0, 1, 2)]
    drawn = {
        (tuple(env.dynamics[0].tolist()), int(env.action_lag[0]), *env.joint_offset[0].tolist())
        for env in envs
    }
    assert len(drawn) == 3


# --- pinned dynamics and pushes ------------------------------------------------------------


def test_pinned_dynamics_reach_the_engine(policy):
    nominal = playback_env(lift_dance(), policy)
    pinned = PinnedDynamics(friction=0.1, added_mass_kg=3.0, motor_strength=0.9, action_lag_s=0.03)
    env = playback_env(lift_dance(), policy, pinned=pinned)
    m0, m = nominal.engine._variant_models[0], env.engine._variant_models[0]
    feet = [i for i in range(m.ngeom) if "_collision" in (m.geom(i).name or "")]
    np.testing.assert_allclose(m.geom_friction[feet, 0], 0.1)
    trunk = m.body("trunk").id
    assert m.body_mass[trunk] == pytest.approx(m0.body_mass[trunk] + 3.0)
    np.testing.assert_allclose(m.actuator_gainprm[:, 0], 0.9 * m0.actuator_gainprm[:, 0])
    assert int(env.action_lag[0]) == 6  # 30 ms at 5 ms physics steps
    assert torch.all(env.joint_offset == 0)


def test_bad_pinned_settings_are_refused(policy):
    with pytest.raises(QuaddanceError, match="exclude"):
        playback_env(lift_dance(), policy, randomize=True, pinned=PinnedDynamics())
    with pytest.raises(QuaddanceError, match="action lag"):
        playback_env(lift_dance(), policy, pinned=PinnedDynamics(action_lag_s=0.2))


def test_push_schedule_cycles_directions():
    pinned = PinnedDynamics(push_vel_m_s=0.5, push_first_s=1.0, push_every_s=2.0)
    steps = pinned.push_steps(n_steps=400, policy_hz=50.0)  # 8 s
    assert sorted(steps) == [50, 150, 250, 350]
    assert [steps[k] for k in sorted(steps)] == [(0, 0.5), (-0.5, 0), (0, -0.5), (0.5, 0)]
    assert PinnedDynamics().push_steps(400, 50.0) == {}


def test_a_hard_push_makes_it_fall_and_none_does_not(policy):
    calm = rollout(lift_dance(), policy, pinned=PinnedDynamics())
    pushed = rollout(
        lift_dance(), policy, pinned=PinnedDynamics(push_vel_m_s=3.0, push_first_s=0.5)
    )
    assert calm.falls_s == [] and calm.pushes_s == []
    assert pushed.pushes_s == [0.5]
    assert pushed.falls_s and 0.5 < pushed.falls_s[0] < 2.5


# --- feed-forward alone ------------------------------------------------------------------


def test_zero_output_is_the_feedforward_alone(policy, monkeypatch):
    def no_policy(obs):
        raise AssertionError("the policy must not run with policy_output='zero'")

    dance = lift_dance(height_m=0.15)
    with_policy = rollout(dance, policy)
    monkeypatch.setattr(policy, "act", no_policy)
    ff_only = rollout(dance, policy, policy_output="zero")
    no_ff = dataclasses.replace(
        policy, task=dataclasses.replace(policy.task, front_feedforward=False)
    )
    nothing = rollout(dance, no_ff, policy_output="zero")
    before = ff_only.time_s < 0.95  # the feed-forward of a zero target is zero
    np.testing.assert_allclose(ff_only.qpos[before], nothing.qpos[before], atol=1e-9)
    # During the lift the feed-forward bends the front-left leg's thigh and calf.
    fl = [7 + GO1.joint_names.index(f"FL_{part}_joint") for part in ("thigh", "calf")]
    assert np.abs(ff_only.qpos[:, fl] - nothing.qpos[:, fl]).max() > 0.1
    assert not np.allclose(ff_only.feet_m, with_policy.feet_m, atol=1e-3)
    with pytest.raises(QuaddanceError, match="policy output"):
        rollout(dance, policy, policy_output="half")


# --- CLI -------------------------------------------------------------------------------------


def fake_row(name: str) -> dict:
    t = np.arange(100) / 50.0
    feet = np.zeros((100, 4))
    feet[:, 0] = 0.1 * np.sin(t) ** 2
    return {"name": name, **dance_metrics(t, feet, feet, [], [], 1.0, None)}


@pytest.fixture
def captured(monkeypatch):
    """Replace the dancing by a recorder: what the CLI asked for, fast."""
    calls: list[tuple[list[Path], EvalSettings]] = []

    def fake_items(items, policy, settings=None, progress=None, motions=None):
        calls.append((list(items), settings))
        return [fake_row(p.name) for p in items]

    monkeypatch.setattr(evaluate_mod, "evaluate_items", fake_items)
    return calls


@pytest.mark.parametrize(
    ("flags", "field", "value"),
    [
        ([], "policy_output", "policy"),
        (["--policy-output", "zero"], "policy_output", "zero"),
        (["--randomize"], "randomize", True),
        (["--seed", "4"], "seed", 4),
    ],
)
def test_eval_flags_reach_the_settings(song, tmp_path, captured, flags, field, value):
    report = tmp_path / "r.md"
    result = CliRunner().invoke(app, ["eval", str(song), "-o", str(report), *flags])
    assert result.exit_code == 0, result.output
    assert getattr(captured[0][1], field) == value
    data = json.loads(report.with_suffix(".json").read_text())
    assert data["settings"][field] == value
    assert report.with_suffix(".png").exists()


def test_eval_held_out_other_set_flag_writes_and_evaluates_that_set(tmp_path, captured):
    from quaddance.play.heldout import OTHER_ITEMS

    folder = tmp_path / "other"
    args = ["eval", "--held-out", str(folder), "--set", "other", "-o", str(tmp_path / "r.md")]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    names = sorted(p.name for p in captured[0][0])
    assert names == sorted(item.name for item in OTHER_ITEMS)
    assert sorted(p.name for p in folder.iterdir()) == names


@pytest.mark.parametrize(
    ("flags", "needle"),
    [(["--set", "nope"], "--set"), (["--policy-output", "half"], "--policy-output")],
)
def test_eval_rejects_bad_choices(song, tmp_path, flags, needle):
    result = CliRunner().invoke(app, ["eval", str(song), "-o", str(tmp_path / "r.md"), *flags])
    assert result.exit_code == 2
    assert needle in result.output
    assert not (tmp_path / "r.md").exists()


def test_eval_title_flag_heads_the_report(song, tmp_path, captured):
    report = tmp_path / "r.md"
    args = ["eval", str(song), "-o", str(report), "--title", "Set X, nominal"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert report.read_text().startswith("# Set X, nominal\n")


# --- files checked before the work -------------------------------------------------------------


def _no_work(*args, **kwargs):
    raise AssertionError("an item was danced before the files were checked")


def test_eval_checks_its_files_before_dancing_any_item(tmp_path, monkeypatch):
    """`eval -o` over an input replaced it with the report; `-o x.png` made the report its own
    plot; a bad motion after a good one failed only after the good one was danced."""
    from quaddance.errors import InputFileError, OutputFileError

    monkeypatch.setattr(evaluate_mod, "evaluate_items", _no_work)
    song = tmp_path / "song.wav"
    y, _ = render_song(110.0, 3.0, seed=2)
    sf.write(song, y, 22050)
    before = song.read_bytes()
    bad = tmp_path / "nan.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET nan 0 0\n}\nMOTION\n")
    cases = [
        ([str(song), "-o", str(song)], OutputFileError, "is also the input (item song.wav)"),
        ([str(song), "-o", str(tmp_path / "r.png")], OutputFileError, "is given for both"),
        ([str(song), "-o", str(tmp_path)], OutputFileError, "exists and is a folder"),
        ([str(song), str(bad), "-o", str(tmp_path / "r.md")], InputFileError, "nan.bvh"),
    ]
    for args, error, words in cases:
        result = CliRunner().invoke(app, ["eval", *args])
        assert isinstance(result.exception, error), (args, result.output)
        assert words in str(result.exception), str(result.exception)
    assert song.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nan.bvh", "song.wav"]


def test_eval_held_out_over_a_file_is_one_line(tmp_path):
    from quaddance.errors import OutputFileError

    taken = tmp_path / "beats.txt"
    taken.write_text("0.5\n")
    result = CliRunner().invoke(app, ["eval", "--held-out", str(taken), "--set", "other"])
    assert isinstance(result.exception, OutputFileError), result.output
    assert str(result.exception).startswith(f"{taken}: exists and is a file")


def test_eval_reads_each_motion_file_once(tmp_path, monkeypatch):
    """The early check reads each motion file; the dance takes that reading, not a second one
    (a large BVH was parsed twice)."""
    from motion_fuzz_cases import valid_bvh

    from quaddance.choreo import motion as motion_mod
    from quaddance.play import dance as dance_mod

    bvh = tmp_path / "steps.bvh"
    bvh.write_text(valid_bvh(96, 1 / 24, np.random.default_rng(0)))
    reads: list[Path] = []
    real_load = motion_mod.load_motion

    def counted(path, cfg=None):
        reads.append(Path(path))
        return real_load(path, cfg)

    monkeypatch.setattr(motion_mod, "load_motion", counted)
    humans: list[object] = []
    real_run = dance_mod.run_dance

    def run_dance(job, **kwargs):
        humans.append(job.human)
        return real_run(job, **kwargs)

    monkeypatch.setattr(dance_mod, "run_dance", run_dance)
    rows = evaluate([bvh], None, tmp_path / "report.md")
    assert reads == [bvh]
    assert len(humans) == 1 and isinstance(humans[0], motion_mod.HumanMotion)
    assert [r["name"] for r in rows] == ["steps.bvh"] and rows[0]["duration_s"] > 3.0
