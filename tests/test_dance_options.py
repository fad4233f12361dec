"""The dance options (--mode, --style, --seed, --moves) mean the same in choreograph, dance,
deploy and live: each one reaches the job's `DanceSpec`, and deploy and live make their dance
of that spec, in the policy's range."""

from __future__ import annotations

import dataclasses
import importlib
import sys
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

from quaddance.cli import app, main
from quaddance.deploy.job import DeployJob, run_deploy
from quaddance.errors import QuaddanceError
from quaddance.live import session
from quaddance.live.session import LiveJob, run_live
from quaddance.pipeline import DanceSpec
from quaddance.play.policy import OnnxPolicy, shipped_policy_path
from quaddance.targets import TargetConfig

MOVES_TOML = """
[moves.wiggle]
gestures = [{ column = "roll_rad", amplitude = 0.05, every_beats = 0.5, shape = "swing" }]

[styles.wiggly]
wiggle = 3.0
"""

#: Where each command's job goes: (module, function).
RUNNERS = {
    "choreograph": ("quaddance.pipeline", "run_choreograph"),
    "dance": ("quaddance.play.dance", "run_dance"),
    "deploy": ("quaddance.deploy.job", "run_deploy"),
    "live": ("quaddance.live.session", "run_live"),
}


class _RanError(Exception):
    """Raised in place of running a job; carries what it was given."""


def _song(command: str) -> list[str]:
    return ["--from-file", "song.wav"] if command == "live" else ["song.wav"]


def _job(monkeypatch, command: str, *flags: str):
    """The job that ``quaddance COMMAND SONG FLAGS`` would run."""
    module, name = RUNNERS[command]

    def run(job, *args, **kwargs):
        raise _RanError(job)

    monkeypatch.setattr(importlib.import_module(module), name, run)
    result = CliRunner().invoke(app, [command, *_song(command), *flags])
    assert isinstance(result.exception, _RanError), result.output
    return result.exception.args[0]


@pytest.mark.parametrize("command", sorted(RUNNERS))
def test_each_dance_option_reaches_the_job(monkeypatch, tmp_path, command, policy_max_height_m):
    moves = tmp_path / "moves.toml"
    moves.write_text(MOVES_TOML)
    spec = _job(monkeypatch, command).spec
    if command == "choreograph":  # the dance `dance` performs: in the shipped policy's range
        assert spec.targets.max_height_m == policy_max_height_m
        spec = dataclasses.replace(
            spec, targets=dataclasses.replace(spec.targets, max_height_m=None)
        )
    assert spec == DanceSpec()
    assert _job(monkeypatch, command, "--mode", "paper").spec.mode == "paper"
    assert _job(monkeypatch, command, "--style", "calm").spec.style == "calm"
    assert _job(monkeypatch, command, "--seed", "7").spec.seed == 7
    spec = _job(monkeypatch, command, "--moves", str(moves), "--style", "wiggly").spec
    assert spec.style == "wiggly" and spec.moves.source == "moves.toml"
    assert "wiggle" in {m.name for m in spec.moves.body_moves}
    result = CliRunner().invoke(app, [command, *_song(command), "--mode", "high"])
    assert result.exit_code == 2 and "--mode" in result.output


@pytest.fixture(scope="module")
def policy_max_height_m() -> float:
    return OnnxPolicy.load(shipped_policy_path()).meta["targets"]["max_height_m"]


def test_deploy_dances_its_spec_in_the_policy_s_range(monkeypatch, tmp_path, policy_max_height_m):
    from quaddance.deploy import job as deploy_job

    def make_dance(song, motion, spec):
        raise _RanError(spec)

    monkeypatch.setattr(deploy_job, "make_dance", make_dance)
    song = tmp_path / "song.wav"
    song.write_bytes(b"")
    asked = DanceSpec(style="calm", seed=4, targets=TargetConfig(mode="paper"))
    with pytest.raises(_RanError) as ran:
        run_deploy(DeployJob(out_dir=tmp_path / "out", song=song, spec=asked))
    spec = ran.value.args[0]
    assert (spec.style, spec.seed, spec.mode) == ("calm", 4, "paper")
    assert spec.targets.max_height_m == policy_max_height_m
    # A ready dance file is not made again: the options that would make one are refused.
    dance = tmp_path / "dance.npz"
    with pytest.raises(QuaddanceError, match="--dance"):
        run_deploy(DeployJob(out_dir=tmp_path / "out", dance=dance, spec=asked))


def test_live_plans_its_spec_in_the_policy_s_range(monkeypatch, tmp_path, policy_max_height_m):
    def process(target, args, daemon):  # not started: what the listener would get is kept
        raise _RanError(args[0])

    context = SimpleNamespace(Queue=lambda: None, Event=lambda: None, Process=process)
    monkeypatch.setattr(session, "mp", SimpleNamespace(get_context=lambda kind: context))
    song = tmp_path / "song.wav"
    song.write_bytes(b"")
    asked = DanceSpec(style="energetic", seed=2, targets=TargetConfig(mode="minmax"))
    with pytest.raises(_RanError) as ran:
        run_live(LiveJob(out_dir=tmp_path / "out", from_file=song, spec=asked))
    spec = ran.value.args[0]["dance"]
    assert (spec.style, spec.seed, spec.mode) == ("energetic", 2, "minmax")
    assert spec.targets.max_height_m == policy_max_height_m


@pytest.mark.parametrize("command", ["choreograph", "dance"])
@pytest.mark.parametrize(
    ("flags", "named"),
    [
        (["--style", "calm"], "--style"),
        (["--seed", "3"], "--seed"),
        (["--moves", "m.toml"], "--moves"),
    ],
)
def test_choreographer_options_with_a_motion_are_a_usage_error(
    tmp_path, monkeypatch, capsys, command, flags, named
):
    """A motion brings its own moves: --style, --seed and --moves changed nothing with it,
    silently (the targets were identical)."""
    (tmp_path / "m.toml").write_text("[styles.calmer]\nhold = 2.0\n")
    flags = [str(tmp_path / f) if f.endswith(".toml") else f for f in flags]
    motion = tmp_path / "walk.bvh"
    motion.write_text("HIERARCHY\n")
    monkeypatch.setattr(sys, "argv", ["quaddance", command, "--motion", str(motion), *flags])
    with pytest.raises(SystemExit) as exc:
        main()
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1, err
    assert f"{named} chooses the choreographer's dance; --motion brings its own moves" in err[0]
