"""Helper processes that a terminal's Ctrl-C does not interrupt.

Ctrl-C sends SIGINT to the whole process group: the command's helpers (render workers, the
song's analysis, the live listener) as well as the command. The command handles it (one
line, exit 130, outputs complete or absent) and stops its helpers; a helper that took it
itself would print a traceback of its own, often from the middle of an import.

So helpers start inside `sigint_blocked_for_children` and call `ignore_sigint` first thing.
A signal mask survives fork and exec: a helper starts with SIGINT blocked, a Ctrl-C that
reaches it while it imports waits, and `ignore_sigint` then drops it and ignores the next.
This process keeps a handler meanwhile. The earlier design ignored SIGINT here while helpers
started, so that they inherited the ignore; a Ctrl-C in that window reached this process as
well, and when Linux handed it to another thread (numpy's BLAS threads run by then) it was
dropped: `dance` missed a group Ctrl-C 1 second in, in 1 of 68 tries.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from typing import Any

_inside = threading.local()  # per thread: inside `sigint_blocked_for_children`


@contextlib.contextmanager
def sigint_blocked_for_children() -> Iterator[None]:
    """Start helper processes inside this block (they must call `ignore_sigint`). The
    calling thread blocks SIGINT meanwhile, so the helpers inherit the block. In the main
    thread a Ctrl-C that comes meanwhile is held and handed to this process's handler at
    the end, so it cannot interrupt a helper's start half-way."""
    if getattr(_inside, "depth", 0):
        yield  # the outer block holds and hands over
        return
    from multiprocessing import resource_tracker

    # Starting multiprocessing's resource tracker unblocks SIGINT in the calling thread:
    # have it running first, or helpers started after it would not inherit the block.
    resource_tracker.ensure_running()
    held: list[int] = []
    # Handlers change only in the main thread, and one not set from Python (None) could
    # not be put back.
    hold = (
        threading.current_thread() is threading.main_thread()
        and signal.getsignal(signal.SIGINT) is not None
    )
    previous = (
        signal.signal(signal.SIGINT, lambda signum, frame: held.append(signum)) if hold else None
    )
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    _inside.depth = 1
    try:
        yield
    finally:
        _inside.depth = 0
        if hold:
            signal.signal(signal.SIGINT, previous)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)  # one sent to this thread arrives
        if held:
            signal.raise_signal(signal.SIGINT)  # one that another thread took


def ignore_sigint() -> None:
    """First thing in a helper started inside `sigint_blocked_for_children`: ignore SIGINT
    (which also drops one that came while the helper started) and unblock it. SIGTERM gets
    its default action back: an ignored signal survives exec, and a helper started by a
    process that ignores SIGTERM (a command that has returned, inside a longer-lived
    caller) could not be stopped by `terminate`, nor by multiprocessing at exit."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


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
        with sigint_blocked_for_children():
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

    ignore_sigint()
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
