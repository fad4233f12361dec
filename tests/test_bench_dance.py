"""`bench dance --no-video` times the simulation as users see it: metrics.json's real-time
factor of a fresh `dance --no-video` process, written to the results file."""

from __future__ import annotations

import json

from benchmarks.dance import dance_command, run_dance_bench


def test_dance_command_adds_no_video_only_when_asked(tmp_path):
    song, out = tmp_path / "song.wav", tmp_path / "out"
    assert "--no-video" not in dance_command(song, out)
    assert dance_command(song, out, video=False)[-1] == "--no-video"


def test_bench_dance_no_video_records_the_simulations_real_time_factor(tmp_path):
    out = tmp_path / "dance.json"
    lines: list[str] = []
    result = run_dance_bench(
        out, song_lengths_s=(2.0,), repeats=1, warmup=False, progress=lines.append, video=False
    )
    saved = json.loads(out.read_text())
    assert saved["command"].endswith("--no-video (a fresh process per run, video off)")
    (song,) = saved["songs"]
    (run,) = song["runs"]
    assert run["realtime_factor_sim"] > 0
    assert song["realtime_factor_sim_median"] == run["realtime_factor_sim"]
    # No video was made: the command's own phase timings have no rendering in them.
    assert not any("render" in k for k in run["timings_s"])
    assert "sim" in lines[0] and result["songs"][0]["song_s"] == 2.0
