"""Errors a user can act on: each names the file (or setting) and what is wrong with it.

The CLI prints these as one line and exits with status 2; anything else is a bug.
"""

from __future__ import annotations

from pathlib import Path


class QuaddanceError(Exception):
    """Base class for errors caused by the user's input, shown without a traceback."""


class InputFileError(QuaddanceError):
    """A file given by the user cannot be used; the message names the file and the problem."""

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


def not_a_file(path: str | Path) -> InputFileError:
    """The error for an input ``path`` that is not a regular file: it is missing, a folder, or
    another kind of file (a FIFO, a device)."""
    path = Path(path)
    if not path.exists():
        return InputFileError(path, "no such file")
    if path.is_dir():
        return InputFileError(path, "is a folder, not a file")
    return InputFileError(path, "is not a regular file")


class OutputFileError(QuaddanceError):
    """An output path cannot be written (it is a device, a folder where a file goes, the disk
    is full, ...); the message names the path and the problem."""

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")
