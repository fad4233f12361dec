"""Load a pickle without letting it run code: only numpy arrays and builtin containers.

A pickle names the callables that rebuild its objects (``module.name`` globals) and the
unpickler calls them, so a plain ``pickle.load`` of a user's file can run anything
(``os.system``, ``builtins.eval``). This unpickler resolves a global only if it is on a short
allowlist of callables that build data and nothing else: exactly those numpy 1.x and 2.x write
for arrays, dtypes and scalars at protocols 0-5, and builtin container types. Every other
global is refused before anything is called. Elements of object arrays and values inside
dicts are unpickled by the same machine, so the allowlist covers them too.
"""

from __future__ import annotations

import _codecs
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy._core import multiarray as _np_multiarray
from numpy._core import numeric as _np_numeric

from quaddance.errors import InputFileError


def _latin1_encode(text: str, encoding: str = "utf-8", errors: str = "strict") -> bytes:
    """``_codecs.encode`` limited to the latin-1 round trip that protocol 0-2 pickles use."""
    # Any other codec name makes the codec registry import a module; latin-1 is all pickles need.
    if encoding.replace("_", "-").lower() not in ("latin1", "latin-1") or not isinstance(text, str):
        raise pickle.UnpicklingError(f"_codecs.encode with encoding {encoding!r} is not allowed")
    return _codecs.encode(text, "latin1", errors)


def _bytes_like(kind: type) -> Callable[..., Any]:
    """``bytes`` / ``bytearray`` that refuse a bare size, so a pickle cannot ask for 100 GB."""

    def build(*args: Any) -> Any:
        if args and isinstance(args[0], int):
            raise pickle.UnpicklingError(f"{kind.__name__}(<size>) is not allowed")
        return kind(*args)

    return build


# (module, name) -> the object the unpickler gets. Modules are spelled as numpy 2.x and
# Python 3 spell them; `_canonical_module` maps the numpy 1.x / Python 2 spellings first.
_ALLOWED: dict[tuple[str, str], Any] = {
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
    # Arrays at protocols 0-4: _reconstruct(ndarray, (0,), b"b") then ndarray.__setstate__.
    ("numpy._core.multiarray", "_reconstruct"): _np_multiarray._reconstruct,
    # Array scalars (np.float64(1.0), ...): scalar(dtype, raw bytes).
    ("numpy._core.multiarray", "scalar"): _np_multiarray.scalar,
    # Arrays at protocol 5: _frombuffer(buffer, dtype, shape, order); refuses object dtype.
    ("numpy._core.numeric", "_frombuffer"): _np_numeric._frombuffer,
    # Protocol 0-2 pickles store bytes as _codecs.encode(<latin-1 text>, "latin1").
    ("_codecs", "encode"): _latin1_encode,
    ("builtins", "bytes"): _bytes_like(bytes),
    ("builtins", "bytearray"): _bytes_like(bytearray),
    **{
        ("builtins", kind.__name__): kind
        for kind in (dict, list, tuple, set, frozenset, complex, int, float, str, bool)
    },
}


def _canonical_module(module: str) -> str:
    """Map numpy 1.x (``numpy.core``) and Python 2 (``__builtin__``) spellings to today's."""
    if module == "__builtin__":
        return "builtins"
    if module == "numpy.core" or module.startswith("numpy.core."):
        return "numpy._core" + module[len("numpy.core") :]
    return module


class _RestrictedUnpickler(pickle.Unpickler):
    """An unpickler whose globals come only from `_ALLOWED`."""

    def __init__(self, file: Any, path: Path) -> None:
        # latin1 lets Python 2 pickles of numpy arrays load (numpy's own advice for them).
        super().__init__(file, encoding="latin1")
        self._path = path

    def find_class(self, module: str, name: str) -> Any:
        module = _canonical_module(module)
        found = _ALLOWED.get((module, name))
        if found is None:
            raise InputFileError(
                self._path, f"refused: pickle references {module}.{name}, which could run code"
            )
        return found

    def persistent_load(self, pid: Any) -> Any:
        raise InputFileError(self._path, "refused: pickle uses persistent ids (a torch file?)")


_ZIP_MAGIC = b"PK\x03\x04"


def safe_load_pickle(path: str | Path) -> object:
    """Unpickle ``path`` admitting only numpy arrays, dtypes, scalars and builtin containers.

    Parameters
    ----------
    path : str or Path
        A pickle file, e.g. an EDGE output or an AIST++ motion file.

    Returns
    -------
    object
        The unpickled object (usually a dict of numpy arrays).

    Raises
    ------
    InputFileError
        If the file is missing, is not a pickle, is truncated or corrupt, or references any
        global outside the allowlist (``os.system``, ``builtins.eval``, a class, torch ...). In
        the last case nothing from the file has been called.
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            head = f.read(4)
            if head.startswith(_ZIP_MAGIC):
                raise InputFileError(
                    path, "is a zip archive (a torch.save or .npz file?), not a pickle"
                )
            if not head:
                raise InputFileError(path, "is empty, not a pickle")
            f.seek(0)
            return _RestrictedUnpickler(f, path).load()
    except InputFileError:
        raise
    except OSError as err:
        raise InputFileError(path, f"cannot be read ({err.strerror or err})") from None
    except Exception as err:  # any failure inside the unpickler means a bad file
        raise InputFileError(
            path, f"is not a valid pickle or is truncated/corrupt ({type(err).__name__}: {err})"
        ) from None
