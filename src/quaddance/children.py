"""Helper processes that a terminal's Ctrl-C does not interrupt.

Ctrl-C sends SIGINT to the whole process group: the command's helpers (render workers, the
song's analysis) as well as the command. The command handles it (one line, exit 130, outputs
complete or absent) and stops its helpers; a helper that took it itself would print a
traceback of its own, often from the middle of an import. A signal ignored when a process
starts stays ignored in the new program, and Python keeps it so, so helpers started inside
`sigint_ignored_by_children` never see Ctrl-C.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator


@contextlib.contextmanager
def sigint_ignored_by_children() -> Iterator[None]:
    """Start helper processes inside this block. This process ignores SIGINT meanwhile (a
    few milliseconds); outside the main thread, where handlers cannot change, it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
