"""Fixtures shared by the test files."""

from __future__ import annotations

import multiprocessing
from pathlib import Path

import pytest

from quaddance.music.synth import SongTruth, render_song, write_demo_song


@pytest.fixture(scope="session")
def demo_song(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, SongTruth]:
    """The built-in demo song written once per session as wav: (path, its exact grid)."""
    path = tmp_path_factory.mktemp("demo") / "demo_song.wav"
    truth = write_demo_song(path)
    return path, truth


@pytest.fixture(scope="session")
def song_3s(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s song made by code (120 BPM), written once per session as wav."""
    import soundfile as sf

    path = tmp_path_factory.mktemp("song") / "song_3s.wav"
    y, _ = render_song(120.0, 3.0, seed=4)
    sf.write(path, y, 22050)
    return path


@pytest.fixture(autouse=True)
def no_helper_process_outlives_its_test():
    """A test that leaves a helper process running (a render worker, the live listener)
    leaks it into the rest of the run, and pytest waits for it at exit."""
    before = set(multiprocessing.active_children())
    yield
    new = [p for p in multiprocessing.active_children() if p not in before]
    for proc in new:
        proc.join(timeout=5.0)  # one told to stop ends on its own, a moment later
    left = [p for p in new if p.is_alive()]
    for proc in left:
        proc.kill()
    assert not left, f"helper processes left running: {[p.name for p in left]}"
