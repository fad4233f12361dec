"""Writing outputs safely: a crash, an error or Ctrl-C never leaves a half-written output.

Only regular files and folders are written. An output path that already exists as something
else (a folder where a file goes, a file where a folder goes, a device, a FIFO, a socket, a
broken symbolic link) is refused with `OutputFileError`, before anything is written: the
atomic rename would otherwise replace a device node such as ``/dev/full`` with a file. A
symbolic link to a regular file is written through (the link stays a link).
"""

from __future__ import annotations

import contextlib
import json
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from quaddance.errors import OutputFileError

_KINDS = (
    (stat.S_ISDIR, "a folder"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
)


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def check_output_file(path: str | Path) -> Path:
    """Refuse ``path`` as a file output unless it is absent or a regular file.

    Returns the path to write: ``path`` itself, or the regular file a symbolic link points to.

    Raises:
        OutputFileError: ``path`` exists and is a folder, device, FIFO, socket or broken link,
            or a parent of it is not a folder.
    """
    path = Path(path)
    if path.is_symlink():
        target = Path(os.path.realpath(path))
        if not target.exists():
            raise OutputFileError(path, "is a broken symbolic link; remove it or pick another name")
        path_to_write = target
    else:
        path_to_write = path
    try:
        mode = path_to_write.stat().st_mode
    except FileNotFoundError:
        _check_parent(path_to_write.parent, path)
        return path_to_write
    except NotADirectoryError:
        raise OutputFileError(path, "a parent of this path is a file, not a folder") from None
    except OSError as err:
        raise OutputFileError(path, f"cannot be checked ({err.strerror or err})") from None
    if not stat.S_ISREG(mode):
        raise OutputFileError(
            path, f"exists and is {_kind(mode)}; quaddance writes only regular files here"
        )
    return path_to_write


def _check_parent(folder: Path, named: Path) -> None:
    """The first existing ancestor of ``folder`` must be a folder we may write in (we create
    the rest, and the atomic rename writes in the folder, not the file)."""
    for parent in (folder, *folder.parents):
        if parent.exists():
            if not parent.is_dir():
                raise OutputFileError(named, f"{parent} is a file, not a folder")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise OutputFileError(named, f"cannot write in the folder {parent}")
            return


def _same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name one file (through links), existing or not."""
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return Path(os.path.realpath(a)) == Path(os.path.realpath(b))


def check_outputs(outputs: dict[str, Path], inputs: dict[str, Path | None]) -> None:
    """Check each output as `check_output_file` does, and refuse an output that is one of the
    inputs, or two outputs that are one file: the input would be replaced, or one output
    would be lost under the other. Call it before the work.

    Args:
        outputs: each output path by the option that names it (for the message).
        inputs: each input path by its option; None where not given.

    Raises:
        OutputFileError: naming the output and what is wrong with it.
    """
    given = {what: path for what, path in inputs.items() if path is not None}
    seen: dict[str, Path] = {}
    for what, out in outputs.items():
        check_output_file(out)
        for in_what, path in given.items():
            if _same_file(out, path):
                raise OutputFileError(
                    out, f"is also the input ({in_what}); writing {what} would replace it"
                )
        for other, path in seen.items():
            if _same_file(out, path):
                raise OutputFileError(out, f"is given for both {other} and {what}")
        seen[what] = out


def ensure_dir(path: str | Path) -> Path:
    """Create the output folder ``path`` (and its parents) unless it exists as a folder.

    Raises:
        OutputFileError: ``path`` (or a parent) exists and is not a folder, or cannot be made.
    """
    path = Path(path)
    if path.is_dir():
        return path
    if path.exists():
        mode = path.stat().st_mode
        what = "a file" if stat.S_ISREG(mode) else _kind(mode)
        raise OutputFileError(path, f"exists and is {what}, not a folder for the outputs")
    if path.is_symlink():
        raise OutputFileError(path, "is a broken symbolic link, not a folder for the outputs")
    _check_parent(path.parent, path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputFileError(path, f"cannot create the folder ({err.strerror or err})") from None
    return path


def earlier_outputs(out_dir: Path, names: Iterable[str], written: Iterable[Path]) -> list[Path]:
    """The files ``names`` in ``out_dir`` that a run did not write (``written``): left by an
    earlier run (``--no-video`` after a run with video, a run stopped before its dance). They
    are kept, as someone's work, and named, so that nobody takes them for this run's."""
    done = {Path(p).resolve() for p in written}
    found = (Path(out_dir) / name for name in names)
    return [p for p in found if p.is_file() and p.resolve() not in done]


def remove_empty_dir(path: str | Path) -> None:
    """Remove the folder ``path`` if it exists and is empty; leave it otherwise."""
    with contextlib.suppress(OSError):
        Path(path).rmdir()


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` in one step.

    The temporary file keeps the target's suffix so that libraries which pick a format by
    extension (numpy, matplotlib, ffmpeg) still work. On error or interrupt the temporary is
    removed and any existing ``path`` is left untouched. ``path`` must be absent or a regular
    file (see `check_output_file`); an OS error while writing (disk full, no permission)
    becomes an `OutputFileError` naming ``path``.
    """
    named = Path(path)
    path = check_output_file(named)
    tmp_path: Path | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(
            prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent
        )
        tmp_path = Path(tmp)
        os.close(fd)
        yield tmp_path
        # mkstemp makes the file private (0600); outputs get the usual umask-based mode.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)
        # Checked again: the path may have become a device or FIFO while we were writing.
        check_output_file(named)
        os.replace(tmp_path, path)
    except OSError as err:
        raise OutputFileError(named, f"cannot write ({err.strerror or err})") from None
    finally:
        if tmp_path is not None:
            tmp_path.unlink(missing_ok=True)


def write_json(path: str | Path, obj: Any) -> None:
    """Write ``obj`` as indented JSON, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=2, sort_keys=False) + "\n")
