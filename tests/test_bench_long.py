"""`bench long`: the 20-minute song is danced `--repeats` times and judged on the median wall
time and the largest peak memory (the commands themselves are replaced here by a stand-in
that reports given figures; the bench's own run takes minutes)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import benchmarks.long as long_bench


def _run_with(walls: list[float], peaks: list[float]):
    """A stand-in for `_run`: the dances report ``walls`` and ``peaks`` in turn, each writing
    the metrics.json a real dance writes; the 2-hour file is refused."""
    calls = iter(zip(walls, peaks, strict=True))

    def fake(cmd: list[str]) -> dict:
        if "analyze" in cmd:
            return {"exit_code": 2, "wall_s": 0.5, "cpu_s": 0.5, "peak_rss_mb": 40.0}
        wall, peak = next(calls)
        out = Path(cmd[cmd.index("--out") + 1])
        out.mkdir(parents=True)
        metrics = {
            "timings_s": {"choreography_s": 5.0, "simulation_s": wall - 8.0, "total_s": wall},
            "duration_s": 1200.0,
            "realtime_factor_sim": 1200.0 / (wall - 8.0),
            "falls_s": [],
        }
        (out / "metrics.json").write_text(json.dumps(metrics))
        return {
            "exit_code": 0,
            "wall_s": wall,
            "cpu_s": wall,
            "peak_rss_mb": peak,
            "load_avg_1min_before": 0.1,
        }

    return fake


@pytest.fixture
def no_files(monkeypatch):
    monkeypatch.setattr(long_bench, "_make_in_child", lambda writer, path, s: path.touch())


@pytest.mark.parametrize(
    ("walls", "peaks", "median", "met"),
    [
        ([70.0, 95.0, 80.0], [500.0, 510.0, 505.0], 80.0, True),
        ([95.0, 70.0, 92.0], [500.0, 510.0, 505.0], 92.0, False),  # median over the goal
        ([70.0, 71.0, 72.0], [500.0, 1100.0, 505.0], 71.0, False),  # one run over 1 GB
    ],
)
def test_the_long_song_is_judged_on_the_median_of_its_runs(
    tmp_path, monkeypatch, no_files, walls, peaks, median, met
):
    monkeypatch.setattr(long_bench, "_run", _run_with(walls, peaks))
    out = tmp_path / "long.json"
    long_bench.run_long_bench(out, repeats=3)
    dance = json.loads(out.read_text())["dance_20min_no_video"]
    assert len(dance["runs"]) == 3
    assert dance["wall_median_s"] == median
    assert dance["peak_rss_max_mb"] == max(peaks)
    assert dance["met"] is met
    assert dance["runs"][0]["split_s"]["rest_s"] == pytest.approx(3.0)


def test_repeats_sets_the_number_of_runs(tmp_path, monkeypatch, no_files):
    monkeypatch.setattr(long_bench, "_run", _run_with([60.0], [400.0]))
    result = long_bench.run_long_bench(tmp_path / "long.json", repeats=1)
    assert [r["wall_s"] for r in result["dance_20min_no_video"]["runs"]] == [60.0]
    assert result["limits"]["repeats"] == 1


def test_a_failed_run_is_never_met(tmp_path, monkeypatch, no_files):
    def failing(cmd: list[str]) -> dict:
        return {"exit_code": 1, "wall_s": 3.0, "cpu_s": 3.0, "peak_rss_mb": 90.0}

    monkeypatch.setattr(long_bench, "_run", failing)
    dance = long_bench.run_long_bench(tmp_path / "long.json", repeats=2)["dance_20min_no_video"]
    assert dance["met"] is False and len(dance["runs"]) == 2


def test_bench_long_repeats_on_the_command_line(tmp_path, monkeypatch, no_files):
    from typer.testing import CliRunner

    from quaddance.cli import app

    monkeypatch.setattr(long_bench, "_run", _run_with([61.0, 62.0], [400.0, 401.0]))
    out = tmp_path / "long.json"
    result = CliRunner().invoke(app, ["bench", "long", "--repeats", "2", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "median 61.5 s (goal 90), peak 401 MB (goal 1024): met" in result.output
    assert len(json.loads(out.read_text())["dance_20min_no_video"]["runs"]) == 2
