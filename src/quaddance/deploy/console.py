"""The operator's console during a run: Enter on stdin starts the dance; SIGINT (Ctrl-C) or
SIGTERM asks the runner to stop, which damps the robot and still writes the log."""

from __future__ import annotations

import select
import signal
import sys


class StopSignals:
    """SIGINT / SIGTERM -> a flag the loop reads (the loop then damps and writes the log).

    Nested ``with`` blocks are one: the outer block holds the signals, so that a caller can
    keep them past the loop until the log is written (a second Ctrl-C then loses nothing)."""

    def __init__(self) -> None:
        self.signal: int | None = None
        self._old: dict[int, object] = {}
        self._depth = 0

    def __enter__(self) -> StopSignals:
        def handler(signum: int, frame: object) -> None:
            self.signal = self.signal or signum

        if self._depth == 0:
            for s in (signal.SIGINT, signal.SIGTERM):
                self._old[s] = signal.signal(s, handler)
        self._depth += 1
        return self

    def __exit__(self, *exc: object) -> None:
        self._depth -= 1
        if self._depth == 0:
            for s, h in self._old.items():
                signal.signal(s, h)  # type: ignore[arg-type]


def drain_stdin() -> None:
    """Discard lines already typed (stops at end of input: `enter_pressed` reports that)."""
    for _ in range(1000):
        try:
            ready, _, _ = select.select([sys.stdin], [], [], 0)
        except (ValueError, OSError):
            return
        if not ready:
            return
        if sys.stdin.readline() == "":
            return


def enter_pressed() -> bool | None:
    """True if a line came on stdin, False if none yet, None when stdin is closed."""
    try:
        ready, _, _ = select.select([sys.stdin], [], [], 0)
    except (ValueError, OSError):
        return None
    if not ready:
        return False
    return None if sys.stdin.readline() == "" else True
