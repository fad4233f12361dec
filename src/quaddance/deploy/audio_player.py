"""The song during a run: played by an external player where the machine has a sound device
(ffplay, or afplay on macOS for a song played from its start); else the robot dances silently."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path


class AudioPlayer:
    """Music from an external player where the machine has a sound device; else silence."""

    def __init__(self, song: Path | None, start_s: float = 0.0) -> None:
        self.song = song
        self.proc: subprocess.Popen | None = None
        self._cmd: list[str] | None = None
        self.status = "no song"
        if song is None:
            return
        player = None
        # afplay cannot start part-way into a song.
        players = [["ffplay", "-nodisp", "-autoexit", "-loglevel", "quiet", "-ss", f"{start_s:g}"]]
        players += [["afplay"]] if start_s == 0 else []
        if os.path.exists("/dev/snd") or sys.platform == "darwin":
            for cmd in players:
                if shutil.which(cmd[0]):
                    player = cmd
                    break
        self._cmd = None if player is None else [*player, str(song)]
        self.status = "ready" if self._cmd else "no audio device or player: dancing silently"

    def start(self) -> None:
        if self._cmd is not None:
            self.proc = subprocess.Popen(
                self._cmd,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            self.status = "played"

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
