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


class OutputFileError(QuaddanceError):
    """An output path cannot be written (it is a device, a folder where a file goes, the disk
    is full, ...); the message names the path and the problem."""

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")
