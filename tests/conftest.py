"""Fixtures shared by the test files."""

from __future__ import annotations

from pathlib import Path

import pytest

from quaddance.music.synth import SongTruth, write_demo_song


@pytest.fixture(scope="session")
def demo_song(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, SongTruth]:
    """The built-in demo song written once per session as wav: (path, its exact grid)."""
    path = tmp_path_factory.mktemp("demo") / "demo_song.wav"
    truth = write_demo_song(path)
    return path, truth
