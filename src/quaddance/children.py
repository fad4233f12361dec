"""Helper processes that a terminal's Ctrl-C does not interrupt.

Ctrl-C sends SIGINT to the whole process group: the command's helpers (render workers, the
song's analysis) as well as the command. The command handles it (one line, exit 130, outputs
complete or absent) and stops its helpers; a helper that took it itself would print a
traceback of its own, often from the middle of an import. A signal ignored when a process
starts stays ignored in the new program, and Python keeps it so, so helpers started inside
`sigint_ignored_by_children` never see Ctrl-C. Its main thread blocks SIGINT meanwhile as
well: a Ctrl-C that comes while SIGINT is ignored then waits (Linux keeps a signal pending
while the thread it is for blocks it, even an ignored one) and arrives when the block ends,
instead of being lost. A test's group Ctrl-C one second into `dance`, while the song's helper
started, went unnoticed in 2 of 7 runs before, in 1 of 68 since: another thread of this
process (numpy's BLAS threads already run then) can still take such a Ctrl-C and drop it.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from typing import Any


@contextlib.contextmanager
def sigint_ignored_by_children() -> Iterator[None]:
    """Start helper processes inside this block. This process ignores and blocks SIGINT
    meanwhile (a few milliseconds) and takes a Ctrl-C that came at the end; outside the main
    thread, where handlers cannot change, it does nothing."""
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    ):
        # Nothing to change; and inside another such block, setting SIG_IGN again at the end
        # would drop a Ctrl-C that is waiting for the outer block's end.
        yield
        return
    from multiprocessing import resource_tracker

    # Starting multiprocessing's resource tracker unblocks SIGINT, which would drop a pending
    # Ctrl-C while SIGINT is ignored: have it running first (it ignores Ctrl-C on its own).
    resource_tracker.ensure_running()
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)  # a Ctrl-C that came arrives now


class HelperProcess:
    """A fresh ('spawn') process that runs functions for this one, one call at a time.

    What multiprocessing's pool would do, with two differences that a one-off command needs
    (`dance`): it talks over a pipe, so there is no semaphore for the resource tracker to
    report as leaked when the command ends with `os._exit`; and it ends with `os._exit`
    itself when told to stop (or when this process is gone), skipping an interpreter
    teardown that takes it most of a second with librosa loaded.

    ``fn`` and its arguments and results travel pickled between two processes of this
    program, never from a file.
    """

    def __init__(self) -> None:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self._conn, child_conn = ctx.Pipe()
        self._proc = ctx.Process(target=_helper_main, args=(child_conn,), daemon=True)
        with sigint_ignored_by_children():
            self._proc.start()
        child_conn.close()
        self._waiting = 0  # calls sent whose answers are not read yet

    def submit(self, fn: Callable[..., Any], **kwargs: Any) -> None:
        """Start ``fn(**kwargs)`` there; `result` returns it. Calls run in order. Raises
        `HelperError` where the helper has died."""
        try:
            self._conn.send((fn, kwargs))
        except (OSError, ValueError) as err:  # a dead reader, or closed here
            raise HelperError(f"the helper process ended ({err})") from None
        self._waiting += 1

    def result(self) -> Any:
        """The oldest unread call's value; raises `HelperError` where it raised there or
        the helper died."""
        if self._waiting == 0:
            raise HelperError("no call is waiting for its result")
        self._waiting -= 1
        try:
            ok, value = self._conn.recv()
        except (EOFError, OSError) as err:
            raise HelperError(f"the helper process ended ({err or 'no answer'})") from None
        if not ok:
            raise HelperError(value)
        return value

    def ready(self) -> bool:
        """Whether the oldest unread call's answer has arrived (`result` will not wait); also
        True where the helper has died, since `result` then raises at once."""
        if self._waiting == 0:
            return False
        try:
            return self._conn.poll(0)
        except (OSError, ValueError):
            return True

    def call(self, fn: Callable[..., Any], **kwargs: Any) -> Any:
        self.submit(fn, **kwargs)
        return self.result()

    def close(self) -> None:
        """Tell it to stop (it ends on its own); does not wait."""
        with contextlib.suppress(OSError, ValueError):
            self._conn.send(None)
        self._conn.close()


class HelperError(Exception):
    """A `HelperProcess` call raised, or the process died; the message says which."""


def _helper_main(conn: Any) -> None:
    import os
    import traceback

    code = 0
    try:
        while (job := conn.recv()) is not None:
            fn, kwargs = job
            try:
                conn.send((True, fn(**kwargs)))
            except Exception as err:  # raised by fn, or its value would not pickle
                conn.send((False, f"{type(err).__name__}: {err}\n{traceback.format_exc()}"))
    except (EOFError, OSError):
        code = 1  # the caller is gone
    os._exit(code)
