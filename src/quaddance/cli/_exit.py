"""How a command ends: user errors as one line and exit status 2, Ctrl-C and SIGTERM as one
line and exit status 130 / 143, with outputs complete or absent."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Any

from quaddance.errors import QuaddanceError

#: Longest error line printed, characters (a message quoting a file must stay one short line).
MAX_ERROR_CHARS = 400
#: Exit status after Ctrl-C (SIGINT) or SIGTERM: 128 + the signal number, as a shell reports.
EXIT_SIGINT, EXIT_SIGTERM = 130, 143


def one_line_error(err: BaseException) -> str:
    """``quaddance: error: <message>`` on one line of at most `MAX_ERROR_CHARS`."""
    line = "quaddance: error: " + " ".join(str(err).split())
    return line if len(line) <= MAX_ERROR_CHARS else line[: MAX_ERROR_CHARS - 3] + "..."


def _stop_on_signals() -> dict[int, int]:
    """Turn SIGINT and SIGTERM into KeyboardInterrupt, so that every ``atomic_path`` removes
    its temporary file and no output is left half-written; returns {signal: exit status} of
    the first signal received (filled in by the handler). Later signals are ignored while
    the process cleans up, so a second Ctrl-C cannot cut the cleanup short."""
    import signal
    import threading

    received: dict[int, int] = {}

    def resend_soon(signum: int) -> None:
        # 50 ms later, from another thread: the handler then runs again where it can raise.
        resend = threading.Timer(0.05, os.kill, args=(os.getpid(), signum))
        resend.daemon = True
        resend.start()

    def interrupt(signum: int, frame: object) -> None:
        if received:
            return
        if _importing(frame):
            # Raising inside an import can land in an extension's initialisation, which
            # cannot pass it on: torch's (pybind11) then aborts the process with a C++
            # message. The signal comes again once the import is done.
            resend_soon(signum)
            return
        received[signum] = EXIT_SIGTERM if signum == signal.SIGTERM else EXIT_SIGINT
        raise KeyboardInterrupt(f"signal {signum}")

    default_unraisable = sys.unraisablehook

    def unraisable(info: Any) -> None:
        # A signal that lands in a ctypes callback (numba's LLVM cache, while librosa loads)
        # raises there, where ctypes can only print a traceback and drop the exception. Send
        # the signal again once this hook has returned: the handler then raises in a frame of
        # the main thread that can take it.
        if isinstance(info.exc_value, KeyboardInterrupt) and received:
            signum = next(iter(received))
            received.clear()
            resend_soon(signum)
            return
        default_unraisable(info)

    sys.unraisablehook = unraisable
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, interrupt)
    return received


def _importing(frame: Any) -> bool:
    """Whether ``frame`` (a signal handler's) runs inside an import."""
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            return True
        frame = frame.f_back
    return False


def run_command(app: Callable[[], Any]) -> None:
    """Run ``app`` (the typer app) as the console command: user errors become one line on
    stderr and exit status 2; Ctrl-C and SIGTERM one line and exit status 130 / 143."""
    import signal

    # This process never renders (video frames are drawn in worker processes, which get
    # EGL: `play.video`). Without a MUJOCO_GL, MuJoCo's import loads GLFW, whose import runs
    # a Python subprocess; a Ctrl-C in the first second of a command then printed that
    # subprocess's traceback.
    os.environ.setdefault("MUJOCO_GL", "disable")
    received = _stop_on_signals()
    try:
        try:
            _run_app(app)
        finally:
            # The work is over (done, failed or interrupted): a signal during the exit must
            # neither raise in the handlers below nor kill the process silently (at shutdown
            # Python restores the default action, which would end it with no message).
            for signum in (signal.SIGINT, signal.SIGTERM):
                signal.signal(signum, signal.SIG_IGN)
    except KeyboardInterrupt:
        _interrupted(received)
    except Exception as err:
        if received:  # the signal surfaced inside a library as another error (ctypes wraps
            _interrupted(received)  # it in an ArgumentError while converting an argument)
        if isinstance(err, QuaddanceError):
            print(one_line_error(err), file=sys.stderr)
            sys.exit(2)
        raise
    except SystemExit:
        # typer turns KeyboardInterrupt into a silent exit 130; say why we stopped.
        if received:
            _interrupted(received)
        raise


def _run_app(app: Callable[..., Any]) -> None:
    """Call ``app``; a typer app runs outside click's standalone mode, so that a bad option or
    argument is one line here rather than the usage text and a box."""
    import typer

    if not isinstance(app, typer.Typer):
        app()
        return
    try:
        code = app(prog_name="quaddance", standalone_mode=False)
    except typer.Abort as err:  # typer's wrapper of a Ctrl-C, and of an EOFError
        if isinstance(err.__context__, EOFError):  # a bug to report, not an interruption
            raise err.__context__ from None
        raise KeyboardInterrupt from None
    except typer.TyperException as err:  # a bad option or argument (click's UsageError)
        if type(err).__name__ == "NoArgsIsHelpError":  # bare `quaddance`: typer printed help
            sys.exit(2)
        ctx = getattr(err, "ctx", None)
        command = ctx.command_path if ctx is not None else "quaddance"
        message = err.format_message().rstrip(".")
        where = "" if command == "quaddance" else command.removeprefix("quaddance ") + ": "
        print(one_line_error(f"{where}{message} (see {command} --help)"), file=sys.stderr)
        sys.exit(2)
    sys.exit(code if isinstance(code, int) else 0)  # as in standalone mode


def _interrupted(received: dict[int, int]) -> None:
    # Training has written its checkpoint by now (train.py), so this is a clean stop.
    print("quaddance: interrupted", file=sys.stderr)
    sys.exit(next(iter(received.values()), EXIT_SIGINT))


def exit_without_teardown() -> None:
    """End a command whose outputs are all written and closed, skipping the interpreter's
    teardown: unloading torch alone takes 0.9 s, and the exit would wait for the helper
    process's own teardown too (`dance`: 2 s between its last line and the shell's prompt,
    measured). The helper has been told to stop and ends on its own."""
    import gc

    gc.collect()  # run multiprocessing's finalizers: the resource tracker must not warn
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)
