"""Run file readers on hostile inputs in child processes and classify what happened.

A reader that segfaults, eats all memory or hangs on a crafted file would take the test run
down with it, so every case runs in a child process (this file run as a script) under an
address-space limit and a per-case timeout. Many cases share one child, because starting
Python with numpy costs about a second; when a case kills its child, the next child carries
on with the case after it.

Outcome kinds:

- ``ok``: the reader returned.
- ``refused``: it raised `QuaddanceError` (e.g. `InputFileError`) with one short line that
  names the file - what the CLI turns into ``quaddance: error: ...`` and exit 2.
- ``bad_message``: a `QuaddanceError` whose message is multi-line, too long or lacks the name.
- ``traceback``: any other exception (a bug: the user would see a traceback).
- ``crash``: the child died from a signal (SIGSEGV, SIGABRT, ...) or exited mid-case.
- ``killed``: out of memory (MemoryError under the limit, or SIGKILL from the OOM killer).
- ``hang``: no answer within the timeout.
- ``code_ran``: the case created the ``sentinel`` file (a payload ran).

Used by the fuzz tests and ``scripts/fuzz_campaign.py``::

    from fuzz_harness import run_reader_batch
    outcomes = run_reader_batch("quaddance.choreo.motion:load_motion", paths)
    assert not [o for o in outcomes if not o.clean]
"""

from __future__ import annotations

import json
import os
import resource
import selectors
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

OK, REFUSED, BAD_MESSAGE, TRACEBACK = "ok", "refused", "bad_message", "traceback"
CRASH, KILLED, HANG, CODE_RAN = "crash", "killed", "hang", "code_ran"
CLEAN_KINDS = frozenset({OK, REFUSED})

#: Address-space limit of a child, bytes: far above what a valid motion, song or dance.npz
#: needs, far below what the machine has, so a blow-up is caught and not the machine's problem.
DEFAULT_MEMORY_BYTES = 2 << 30
#: Seconds one case may take before it counts as a hang (2 shared cores: be generous).
DEFAULT_TIMEOUT_S = 30.0
#: Seconds a child may take to import the reader's module (torch alone takes ~4 s).
STARTUP_TIMEOUT_S = 120.0
#: Longest error message counted as one short line (the path is part of it).
MAX_MESSAGE_CHARS = 500
#: Characters of tracebacks and stderr kept in an outcome's detail.
_DETAIL_CHARS = 2000

_HERE = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Outcome:
    """What one case did: its index in the batch, the case (as given), kind and detail."""

    index: int
    case: str
    kind: str
    detail: str = ""

    @property
    def clean(self) -> bool:
        """True for ``ok`` and ``refused``: what a user may see."""
        return self.kind in CLEAN_KINDS


def summarize(outcomes: Iterable[Outcome]) -> dict[str, int]:
    """Count of outcomes per kind."""
    return dict(Counter(o.kind for o in outcomes))


def message_problem(message: str, path: str | Path | None) -> str | None:
    """Why an error message is not one short line naming ``path``, or None if it is."""
    if "\n" in message or "\r" in message:
        return "message spans several lines"
    if len(message) > MAX_MESSAGE_CHARS:
        return f"message is {len(message)} characters long"
    if path is not None and Path(path).name not in message:
        return "message does not name the file"
    return None


# ---------------------------------------------------------------------------------------------
# parent side


def _target_spec(target: str | Any) -> str:
    """'module:qualname' for a callable given by name or as an importable function."""
    if isinstance(target, str):
        return target
    return f"{target.__module__}:{target.__qualname__}"


class _Lines:
    """Lines from a child's pipe, with a timeout per line."""

    def __init__(self, stream: Any) -> None:
        self._fd = stream.fileno()
        self._buffer = b""
        self._selector = selectors.DefaultSelector()
        self._selector.register(self._fd, selectors.EVENT_READ)
        self._eof = False

    def next(self, timeout_s: float) -> bytes | None:
        """The next line; None at EOF; raises TimeoutError after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while b"\n" not in self._buffer:
            if self._eof:
                return None
            left = deadline - time.monotonic()
            if left <= 0 or not self._selector.select(left):
                raise TimeoutError
            chunk = os.read(self._fd, 1 << 16)
            if not chunk:
                self._eof = True
                if not self._buffer:
                    return None
                self._buffer += b"\n"  # a last line without newline is a cut-off answer
            self._buffer += chunk
        line, self._buffer = self._buffer.split(b"\n", 1)
        return line

    def close(self) -> None:
        self._selector.close()


def _death(returncode: int, we_killed: bool, stderr_tail: str) -> tuple[str, str]:
    """(kind, detail) for a child that died in the middle of a case."""
    if we_killed:
        return HANG, "no answer within the timeout"
    if returncode < 0:
        sig = signal.Signals(-returncode)
        kind = KILLED if sig == signal.SIGKILL else CRASH
        return kind, f"{sig.name}; stderr: {stderr_tail}"
    return CRASH, f"child exited with status {returncode} mid-case; stderr: {stderr_tail}"


def _tail(path: Path) -> str:
    try:
        data = path.read_bytes()[-_DETAIL_CHARS:]
    except OSError:
        return ""
    return data.decode("utf-8", "replace").strip()


def run_batch(
    target: str | Any,
    cases: Sequence[Sequence[Any]],
    *,
    mode: str = "reader",
    timeout_s: float = DEFAULT_TIMEOUT_S,
    memory_bytes: int = DEFAULT_MEMORY_BYTES,
    sentinel: str | Path | None = None,
    kwargs: dict[str, Any] | None = None,
    warnings_as_errors: bool = False,
) -> list[Outcome]:
    """Call ``target(*case, **kwargs)`` for every case in child processes; classify each.

    Parameters
    ----------
    target : str or function
        ``"module:function"`` (the module importable in a fresh interpreter; this folder is on
        its path) or an importable function.
    cases : sequence of argument lists
        JSON-serialisable positional arguments, one list per case.
    mode : "reader" or "call"
        ``reader``: the first argument is the file read, and a refusal must name it.
        ``call``: no file name is required in a refusal (e.g. a Hypothesis test run whole).
    timeout_s : float
        Seconds one case may run before it is a hang.
    memory_bytes : int
        RLIMIT_AS of the child, bytes.
    sentinel : path, optional
        A file that a payload would create; if it exists after a case, that case is
        ``code_ran`` (the file is then removed so later cases are judged on their own).
    kwargs : dict, optional
        JSON-serialisable keyword arguments for every call.
    warnings_as_errors : bool
        Turn Python warnings into exceptions (then ``traceback``): a warning is a second
        line on the user's terminal.

    Returns
    -------
    list of Outcome, one per case, in order.
    """
    spec = {
        "target": _target_spec(target),
        "mode": mode,
        "kwargs": kwargs or {},
        "memory_bytes": int(memory_bytes),
        "sentinel": None if sentinel is None else str(sentinel),
        "sys_path": [str(_HERE)],
        "warnings_as_errors": warnings_as_errors,
    }
    outcomes: list[Outcome] = []
    start = 0
    while start < len(cases):
        batch = [list(case) for case in cases[start:]]
        outcomes += _run_child(spec, batch, start, timeout_s)
        start = len(outcomes)
    return outcomes


def run_reader_batch(
    reader: str | Any,
    paths: Iterable[str | Path],
    **options: Any,
) -> list[Outcome]:
    """`run_batch` for a reader taking one path: ``reader(path)`` per file."""
    return run_batch(reader, [[str(p)] for p in paths], mode="reader", **options)


def run_call(target: str | Any, *args: Any, **options: Any) -> Outcome:
    """Run ``target(*args)`` once in a child (``mode="call"``), e.g. a whole Hypothesis test."""
    return run_batch(target, [list(args)], mode="call", **options)[0]


def _run_child(
    spec: dict[str, Any], batch: list[list[Any]], first: int, timeout_s: float
) -> list[Outcome]:
    """Outcomes of ``batch`` from one child, up to and including the case that ended it."""
    outcomes: list[Outcome] = []
    with tempfile.NamedTemporaryFile(prefix="fuzz_stderr_", suffix=".txt") as err_file:
        proc = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--child"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=err_file,
            cwd=tempfile.gettempdir(),
        )
        lines = _Lines(proc.stdout)
        we_killed = False
        try:
            assert proc.stdin is not None
            proc.stdin.write(json.dumps({**spec, "cases": batch}).encode())
            proc.stdin.close()
            try:
                ready = lines.next(STARTUP_TIMEOUT_S)
            except TimeoutError:
                ready = None
            if ready is None or json.loads(ready).get("ready") is not True:
                proc.kill()
                proc.wait()
                raise RuntimeError(
                    f"fuzz child for {spec['target']} did not start: {_tail(Path(err_file.name))}"
                )
            while len(outcomes) < len(batch):
                index = first + len(outcomes)
                case_text = json.dumps(batch[len(outcomes)])[:200]
                try:
                    line = lines.next(timeout_s)
                except TimeoutError:
                    proc.kill()
                    we_killed = True
                    line = None
                if line is None:
                    proc.wait()
                    kind, detail = _death(proc.returncode, we_killed, _tail(Path(err_file.name)))
                    outcomes.append(Outcome(index, case_text, kind, detail[:_DETAIL_CHARS]))
                    break
                answer = json.loads(line)
                outcomes.append(Outcome(index, case_text, answer["kind"], answer["detail"]))
        finally:
            lines.close()
            if proc.poll() is None:
                proc.kill()
            proc.wait()
            if proc.stdout is not None:
                proc.stdout.close()
    return outcomes


def run_cli(
    args: Sequence[str | Path],
    *,
    file: str | Path | None = None,
    timeout_s: float = 300.0,
    memory_bytes: int = DEFAULT_MEMORY_BYTES,
) -> tuple[Outcome, subprocess.CompletedProcess[str] | None]:
    """Run ``quaddance ARGS`` and classify it; ``file`` must be named by a refusal.

    ``refused`` means exit status 2 and exactly one stderr line ``quaddance: error: ...``.
    Returns the outcome and the finished process (None after a hang).
    """
    command = [sys.executable, "-m", "quaddance.cli", *map(str, args)]
    case = " ".join(map(str, args))[:200]

    def limit_memory() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))

    try:
        done = subprocess.run(
            command,
            capture_output=True,
            text=True,
            errors="replace",
            timeout=timeout_s,
            preexec_fn=limit_memory,  # the caller is single-threaded: safe
        )
    except subprocess.TimeoutExpired:
        return Outcome(0, case, HANG, f"no exit within {timeout_s:g} s"), None
    stderr = done.stderr.strip()
    tail = stderr[-_DETAIL_CHARS:]
    if done.returncode < 0:
        kind, detail = _death(done.returncode, False, tail)
    elif "Traceback (most recent call last)" in stderr:
        kind, detail = (KILLED if "MemoryError" in stderr else TRACEBACK), tail
    elif done.returncode == 0:
        kind, detail = OK, ""
    elif done.returncode == 2 and stderr.startswith("quaddance: error: "):
        problem = message_problem(stderr, file)
        kind, detail = (REFUSED, stderr) if problem is None else (BAD_MESSAGE, problem)
    else:
        kind, detail = CRASH, f"exit status {done.returncode}; stderr: {tail}"
    return Outcome(0, case, kind, detail[:_DETAIL_CHARS]), done


# ---------------------------------------------------------------------------------------------
# child side


def _child_main() -> None:
    """Read the batch from stdin, answer one JSON line per case on the original stdout."""
    # Anything the reader prints goes to stderr; fd 1 is ours for answers.
    answers = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)
    spec = json.loads(sys.stdin.read())
    memory = spec["memory_bytes"]
    resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # a crash must not write a core file
    sys.path[:0] = spec["sys_path"]
    import importlib
    import traceback

    module_name, _, qualname = spec["target"].partition(":")
    target: Any = importlib.import_module(module_name)
    for part in qualname.split("."):
        target = getattr(target, part)
    from quaddance.errors import QuaddanceError

    sentinel = Path(spec["sentinel"]) if spec["sentinel"] else None
    if spec["warnings_as_errors"]:
        import warnings

        warnings.simplefilter("error")
    answers.write(json.dumps({"ready": True}) + "\n")
    for args in spec["cases"]:
        named = args[0] if spec["mode"] == "reader" and args else None
        try:
            target(*args, **spec["kwargs"])
            kind, detail = OK, ""
        except QuaddanceError as err:
            message = str(err)
            problem = message_problem(message, named)
            kind, detail = (REFUSED, message) if problem is None else (BAD_MESSAGE, problem)
        except MemoryError:
            kind, detail = KILLED, "MemoryError under the address-space limit"
        except BaseException as err:  # every other exception is the finding
            kind = TRACEBACK
            detail = "".join(traceback.format_exception(err))[-_DETAIL_CHARS:]
        if sentinel is not None and sentinel.exists():
            sentinel.unlink()
            kind, detail = CODE_RAN, f"the sentinel {sentinel} was created"
        answers.write(json.dumps({"kind": kind, "detail": detail}) + "\n")
    answers.close()


if __name__ == "__main__" and sys.argv[1:] == ["--child"]:
    _child_main()
