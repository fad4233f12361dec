"""Load a pickle without letting it run code or crash: real-valued numpy arrays and containers.

A pickle is a program for a small stack machine; it names the callables that rebuild its
objects (``module.name`` globals) and the unpickler calls them. A plain ``pickle.load`` of a
user's file can therefore run anything (``os.system``), and even numpy's own callables are
dangerous: a dtype's pickled state sets its flags, so a file can build an object array whose
raw bytes are read as pointers (a segfault), and ``numpy.ndarray((10**10,))`` allocates 80 GB
from a few bytes. Loading here takes three steps:

1. **Scan** the opcodes (`pickletools.genops`) before anything is built: refuse globals off
   the allowlist, persistent ids, class instantiation opcodes, integers over 64 bits, memo
   indices and containers beyond the limits below, and nesting deeper than `MAX_DEPTH` (a
   tuple nested 300 000 deep makes ``hash`` recurse in C and overflow the stack).
2. **Load** with an unpickler whose numpy globals are stand-ins: a dtype is remembered as
   its type string and byte order (kinds b, i, u, f only), an array or scalar as its dtype,
   shape and raw bytes, each checked (size against `MAX_ARRAY_ELEMENTS`, raw length
   against the shape) before any memory is allocated.
3. **Rebuild** the object graph iteratively (no recursion, cycles refused): every stand-in
   becomes a fresh array or scalar of a dtype built from its type string, never from the
   file's state, and every array is checked once more.

A refusal is an `InputFileError` naming the file; nothing the file names is called before
step 2, and only the stand-ins and builtin container types are called then.
"""

from __future__ import annotations

import _codecs
import io
import pickle
import pickletools
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import InputFileError

#: Largest pickle read, bytes. A 20-minute AIST++ motion at 60 fps is about 40 MB.
MAX_PICKLE_BYTES = 256 << 20
#: Most opcodes in one pickle: arrays are one opcode of raw bytes each, so only a motion
#: written as Python lists of numbers comes near this (3 M numbers: 11 min of 72 values at
#: 60 fps). Scanning 3 M opcodes takes a few seconds.
MAX_OPCODES = 3_000_000
#: Deepest container nesting; motion files nest 3 levels (dict -> array state -> shape).
MAX_DEPTH = 64
#: Most items one container may hold (bounded anyway by the opcode count).
MAX_CONTAINER_ITEMS = 3_000_000
#: Largest integer magnitude (bits); motion files hold frame counts and rates.
MAX_INT_BITS = 64
#: Most elements of one array (the raw bytes must be in the file as well).
MAX_ARRAY_ELEMENTS = 1 << 26
#: Most dimensions of one array.
MAX_ARRAY_NDIM = 8
#: Array element types admitted: bool, signed and unsigned integers, IEEE floats.
ALLOWED_DTYPES = frozenset(["b1", "i1", "i2", "i4", "i8", "u1", "u2", "u4", "u8", "f2", "f4", "f8"])


class _Refused(pickle.UnpicklingError):
    """A check failed; the message becomes ``refused: <message>``."""


# ---------------------------------------------------------------------------------------------
# stand-ins for numpy's callables (step 2) and their conversion to real objects (step 3)


class _DtypeSpec:
    """A dtype as the pickle asked for it: an allowed type string plus a byte order."""

    __hash__ = None  # type: ignore[assignment]  # never a dict key or set member

    def __init__(self, type_string: object, align: object = False, copy: object = True) -> None:
        if not isinstance(type_string, str) or type_string not in ALLOWED_DTYPES:
            kind = repr(type_string)[:40]
            raise _Refused(
                f"array dtype {kind} is not a real number or bool (complex, object, text and "
                "structured arrays are not motion data)"
            )
        self.type_string = type_string
        self.byte_order = "="
        self._used = False

    def __setstate__(self, state: object) -> None:
        # numpy writes (version, byte order, subarray, names, fields, elsize, alignment, flags);
        # only the byte order is taken, the flags never (they are what made object arrays).
        if self._used or not isinstance(state, tuple) or len(state) < 5:
            raise _Refused("dtype state is not that of a plain number type")
        order, extra = state[1], state[2:5]
        if order not in ("<", ">", "|", "=") or any(item is not None for item in extra):
            raise _Refused("dtype state is not that of a plain number type")
        self.byte_order = order

    def resolve(self) -> np.dtype:
        """A fresh dtype built from the type string (never from the file's state)."""
        self._used = True
        dtype = np.dtype(self.type_string)
        return dtype if self.byte_order in ("=", "|") else dtype.newbyteorder(self.byte_order)


def _as_dtype(value: object) -> np.dtype:
    if not isinstance(value, _DtypeSpec):
        raise _Refused("array dtype was not built from a type string")
    return value.resolve()


def _checked_shape(shape: object) -> tuple[int, ...]:
    """``shape`` as a tuple of non-negative ints whose product is within the limits."""
    if not isinstance(shape, tuple) or len(shape) > MAX_ARRAY_NDIM:
        raise _Refused(f"array shape {repr(shape)[:60]} is not a tuple of <= {MAX_ARRAY_NDIM} ints")
    count = 1
    for dim in shape:
        if type(dim) is not int or dim < 0:
            raise _Refused(f"array shape {repr(shape)[:60]} has a dimension that is not a size")
        count *= dim
        if count > MAX_ARRAY_ELEMENTS:
            raise _Refused(
                f"array of shape {repr(shape)[:60]} exceeds {MAX_ARRAY_ELEMENTS} elements"
            )
    return shape


def _raw_bytes(raw: object) -> bytes | bytearray:
    """Array bytes as pickled: bytes, bytearray, or latin-1 text from Python 2 pickles."""
    if isinstance(raw, str):
        return raw.encode("latin1")
    if isinstance(raw, bytes | bytearray):
        return raw
    raise _Refused("array data is not raw bytes")


def _array_from(
    dtype: np.dtype, shape: tuple[int, ...], raw: bytes | bytearray, fortran: bool
) -> np.ndarray:
    """A new writeable array; its byte count is checked against the shape first."""
    count = int(np.prod(shape, dtype=np.int64)) if shape else 1
    if len(raw) != count * dtype.itemsize:
        raise _Refused(
            f"array data has {len(raw)} bytes, shape {shape} of {dtype.str} needs "
            f"{count * dtype.itemsize}"
        )
    flat = np.frombuffer(raw, dtype=dtype, count=count)
    # A copy in native byte order: writeable, and the same dtype whatever the writer's machine.
    array = flat.reshape(shape, order="F" if fortran else "C").astype(
        dtype.newbyteorder("="), order="K"
    )
    if dtype.kind == "b":
        # Any byte other than 0 / 1 in a bool array is undefined behaviour for numpy.
        array = array.view(np.uint8).astype(bool)
    return array


class _ArraySpec:
    """An array from ``_reconstruct`` (then ``__setstate__``) or ``_frombuffer``."""

    __hash__ = None  # type: ignore[assignment]

    def __init__(self) -> None:
        self.array: np.ndarray | None = None

    def __setstate__(self, state: object) -> None:
        if self.array is not None or not isinstance(state, tuple) or len(state) not in (4, 5):
            raise _Refused("array state is not (version, shape, dtype, fortran, data)")
        shape, dtype, fortran, raw = state[-4:]
        if len(state) == 5 and state[0] != 1:
            raise _Refused(f"array state version {repr(state[0])[:20]} is not 1")
        if not isinstance(fortran, bool | int):
            raise _Refused("array state's order flag is not a bool")
        self.array = _array_from(
            _as_dtype(dtype), _checked_shape(shape), _raw_bytes(raw), bool(fortran)
        )

    def resolve(self) -> np.ndarray:
        if self.array is None:
            raise _Refused("array was never given its data")
        return self.array


class _ScalarSpec:
    """A numpy scalar from ``scalar(dtype, raw bytes)``."""

    __hash__ = None  # type: ignore[assignment]

    def __init__(self, value: np.generic) -> None:
        self.value = value

    def __setstate__(self, state: object) -> None:
        raise _Refused("numpy scalar given a state")

    def resolve(self) -> np.generic:
        return self.value


class _NdarrayToken:
    """What the global numpy.ndarray stands for: an argument of `_reconstruct` only."""

    def __call__(self, *args: object) -> None:
        # numpy.ndarray((10**10,)) would allocate 80 GB from a few bytes of file.
        raise _Refused("numpy.ndarray(...) is not allowed (it allocates memory)")


_NDARRAY = _NdarrayToken()


def _reconstruct(cls: object, shape: object = (0,), dtype_code: object = b"b") -> _ArraySpec:
    """Stand-in for ``numpy._core.multiarray._reconstruct``: an empty array to be set."""
    if cls is not _NDARRAY:
        raise _Refused("_reconstruct of something other than numpy.ndarray")
    return _ArraySpec()


def _scalar(dtype: object, raw: object = b"") -> _ScalarSpec:
    """Stand-in for ``numpy._core.multiarray.scalar``."""
    return _ScalarSpec(_array_from(_as_dtype(dtype), (), _raw_bytes(raw), False)[()])


def _frombuffer(buffer: object, dtype: object, shape: object, order: object) -> _ArraySpec:
    """Stand-in for ``numpy._core.numeric._frombuffer`` (protocol-5 arrays)."""
    if order not in ("C", "F"):
        raise _Refused("array order is not C or F")
    spec = _ArraySpec()
    spec.array = _array_from(
        _as_dtype(dtype), _checked_shape(shape), _raw_bytes(buffer), order == "F"
    )
    return spec


def _latin1_encode(text: object, encoding: object = "utf-8", errors: object = "strict") -> bytes:
    """``_codecs.encode`` limited to the latin-1 round trip that protocol 0-2 pickles use."""
    # Any other codec name makes the codec registry import a module; latin-1 is all pickles need.
    if (
        not isinstance(encoding, str)
        or encoding.replace("_", "-").lower() not in ("latin1", "latin-1")
        or not isinstance(text, str)
        or errors != "strict"
    ):
        raise _Refused("_codecs.encode other than latin-1 text is not allowed")
    return _codecs.encode(text, "latin1")


def _bytes_like(kind: type) -> Callable[..., Any]:
    """``bytes`` / ``bytearray`` that refuse a bare size, so a pickle cannot ask for 100 GB."""

    def build(*args: Any) -> Any:
        if args and isinstance(args[0], int):
            raise _Refused(f"{kind.__name__}(<size>) is not allowed")
        return kind(*args)

    return build


# (module, name) -> what the unpickler gets. Modules are spelled as numpy 2.x and Python 3
# spell them; `_canonical_module` maps the numpy 1.x / Python 2 spellings first.
_ALLOWED: dict[tuple[str, str], Any] = {
    ("numpy", "ndarray"): _NDARRAY,
    ("numpy", "dtype"): _DtypeSpec,
    # Arrays at protocols 0-4: _reconstruct(ndarray, (0,), b"b") then __setstate__.
    ("numpy._core.multiarray", "_reconstruct"): _reconstruct,
    # Array scalars (np.float64(1.0), ...): scalar(dtype, raw bytes).
    ("numpy._core.multiarray", "scalar"): _scalar,
    # Arrays at protocol 5: _frombuffer(buffer, dtype, shape, order).
    ("numpy._core.numeric", "_frombuffer"): _frombuffer,
    # Protocol 0-2 pickles store bytes as _codecs.encode(<latin-1 text>, "latin1").
    ("_codecs", "encode"): _latin1_encode,
    ("builtins", "bytes"): _bytes_like(bytes),
    ("builtins", "bytearray"): _bytes_like(bytearray),
    # Sets at protocols 0-3 are set([items]) / frozenset([items]).
    ("builtins", "set"): set,
    ("builtins", "frozenset"): frozenset,
}


def _canonical_module(module: str) -> str:
    """Map numpy 1.x (``numpy.core``) and Python 2 (``__builtin__``) spellings to today's."""
    if module == "__builtin__":
        return "builtins"
    if module == "numpy.core" or module.startswith("numpy.core."):
        return "numpy._core" + module[len("numpy.core") :]
    return module


def _check_global(module: str, name: str) -> Any:
    found = _ALLOWED.get((_canonical_module(module), name))
    if found is None and (_canonical_module(module), name) == ("builtins", "complex"):
        raise _Refused("pickle holds a complex number (motion data is real-valued)")
    if found is None:
        # Escaped: a name from the file may hold newlines, and the error must stay one line.
        shown = repr(f"{_canonical_module(module)}.{name}"[:100])[1:-1]
        raise _Refused(f"pickle references {shown}, which could run code")
    return found


# ---------------------------------------------------------------------------------------------
# step 1: the opcode scan


class _Box:
    """A container on the scanned stack: nesting depth and item count so far."""

    __slots__ = ("depth", "items")

    def __init__(self, depth: int, items: int = 0) -> None:
        self.depth = depth
        self.items = items


_MARK = object()
_STRING_OPS = frozenset(
    [
        "STRING",
        "BINSTRING",
        "SHORT_BINSTRING",
        "UNICODE",
        "SHORT_BINUNICODE",
        "BINUNICODE",
        "BINUNICODE8",
    ]
)
_INT_OPS = frozenset(["INT", "BININT", "BININT1", "BININT2", "LONG", "LONG1", "LONG4"])
_SCALAR_OPS = _INT_OPS | frozenset(
    [
        "NONE",
        "NEWTRUE",
        "NEWFALSE",
        "FLOAT",
        "BINFLOAT",
        "BINBYTES",
        "SHORT_BINBYTES",
        "BINBYTES8",
        "BYTEARRAY8",
    ]
)
_EMPTY_OPS = frozenset(["EMPTY_LIST", "EMPTY_DICT", "EMPTY_SET", "EMPTY_TUPLE"])
_PUT_OPS = frozenset(["PUT", "BINPUT", "LONG_BINPUT"])
_GET_OPS = frozenset(["GET", "BINGET", "LONG_BINGET"])
_REFUSED_OPS = {
    "PERSID": "pickle uses persistent ids (a torch file?)",
    "BINPERSID": "pickle uses persistent ids (a torch file?)",
    "NEXT_BUFFER": "pickle uses out-of-band buffers",
    "EXT1": "pickle uses the copyreg extension registry",
    "EXT2": "pickle uses the copyreg extension registry",
    "EXT4": "pickle uses the copyreg extension registry",
    "INST": "pickle instantiates a class",
    "OBJ": "pickle instantiates a class",
    "NEWOBJ": "pickle instantiates a class",
    "NEWOBJ_EX": "pickle instantiates a class",
}


def _depth(item: object) -> int:
    return item.depth if isinstance(item, _Box) else 0


def scan_pickle(raw: bytes) -> None:
    """Refuse a pickle whose opcodes break a limit, before anything in it is built.

    Runs the pickle's stack machine on stand-ins that keep only nesting depths, item counts
    and strings (for STACK_GLOBAL). Containers changed through the memo after being nested
    can end up deeper than counted here; the rebuild step checks the real depth, and only
    tuples and frozensets (which cannot change) are hashed while loading.

    Raises
    ------
    pickle.UnpicklingError
        Naming the broken limit; ValueError from `pickletools.genops` for a corrupt pickle.
    """
    stack: list[Any] = []
    memo: dict[int, Any] = {}

    def pop_mark() -> list[Any]:
        items: list[Any] = []
        while stack:
            item = stack.pop()
            if item is _MARK:
                if len(items) > MAX_CONTAINER_ITEMS:
                    raise _Refused(f"a container holds more than {MAX_CONTAINER_ITEMS} items")
                return items
            items.append(item)
        raise pickle.UnpicklingError("MARK missing")

    def pop(count: int = 1) -> list[Any]:
        if len(stack) < count or any(item is _MARK for item in stack[-count:]):
            raise pickle.UnpicklingError("stack underflow")
        items = stack[-count:]
        del stack[-count:]
        return items

    def push_container(children: list[Any], count: int) -> None:
        depth = 1 + max((_depth(c) for c in children), default=0)
        if depth > MAX_DEPTH:
            raise _Refused(f"containers nest deeper than {MAX_DEPTH} levels")
        stack.append(_Box(depth, count))

    def add_to_top(children: list[Any], count: int) -> None:
        if not stack or not isinstance(stack[-1], _Box):
            raise pickle.UnpicklingError("items added to something that is not a container")
        box = stack[-1]
        box.depth = max(box.depth, 1 + max((_depth(c) for c in children), default=0))
        box.items += count
        if box.depth > MAX_DEPTH:
            raise _Refused(f"containers nest deeper than {MAX_DEPTH} levels")
        if box.items > MAX_CONTAINER_ITEMS:
            raise _Refused(f"a container holds more than {MAX_CONTAINER_ITEMS} items")

    for n_ops, (op, arg, _pos) in enumerate(pickletools.genops(raw)):
        if n_ops >= MAX_OPCODES:
            raise _Refused(f"pickle has more than {MAX_OPCODES} opcodes")
        name = op.name
        if name in _REFUSED_OPS:
            raise _Refused(_REFUSED_OPS[name])
        if name in _INT_OPS and isinstance(arg, int) and abs(arg).bit_length() > MAX_INT_BITS:
            raise _Refused(f"pickle holds an integer of more than {MAX_INT_BITS} bits")
        if name in _STRING_OPS:
            stack.append(arg if isinstance(arg, str) else None)
        elif name in _SCALAR_OPS:
            stack.append(None)
        elif name in _EMPTY_OPS:
            stack.append(_Box(1))
        elif name == "MARK":
            stack.append(_MARK)
        elif name in ("TUPLE", "LIST", "DICT", "FROZENSET"):
            items = pop_mark()
            push_container(items, len(items))
        elif name in ("TUPLE1", "TUPLE2", "TUPLE3"):
            count = int(name[-1])
            push_container(pop(count), count)
        elif name == "APPEND":
            add_to_top(pop(), 1)
        elif name == "SETITEM":
            add_to_top(pop(2), 1)
        elif name in ("APPENDS", "SETITEMS", "ADDITEMS"):
            items = pop_mark()
            add_to_top(items, len(items) // (2 if name == "SETITEMS" else 1))
        elif name == "POP":
            pop()
        elif name == "POP_MARK":
            pop_mark()
        elif name == "DUP":
            stack.append(pop()[0])
            stack.append(stack[-1])
        elif name in _PUT_OPS or name == "MEMOIZE":
            index = len(memo) if name == "MEMOIZE" else arg
            if not isinstance(index, int) or not 0 <= index <= MAX_OPCODES:
                raise _Refused(f"pickle memo index {str(index)[:20]} is out of range")
            if not stack or stack[-1] is _MARK:
                raise pickle.UnpicklingError("memo of an empty stack")
            memo[index] = stack[-1]
        elif name in _GET_OPS:
            if arg not in memo:
                raise pickle.UnpicklingError(f"memo key {str(arg)[:20]} missing")
            stack.append(memo[arg])
        elif name == "GLOBAL":
            module, _, attr = str(arg).partition(" ")
            _check_global(module, attr)
            stack.append(None)
        elif name == "STACK_GLOBAL":
            module, attr = pop(2)
            if not isinstance(module, str) or not isinstance(attr, str):
                raise _Refused("STACK_GLOBAL with names that are not strings")
            _check_global(module, attr)
            stack.append(None)
        elif name == "REDUCE":
            args, _call = pop(2)[::-1]
            stack.append(_Box(_depth(args)) if isinstance(args, _Box) else None)
        elif name == "BUILD":
            (state,) = pop()
            add_to_top([state], 0)
        elif name == "FRAME":
            if not isinstance(arg, int) or arg > len(raw):
                raise _Refused("pickle frame is longer than the file")
        elif name in ("PROTO", "READONLY_BUFFER", "STOP"):
            pass
        else:
            raise _Refused(f"pickle opcode {name} is not supported")


# ---------------------------------------------------------------------------------------------
# step 3: rebuild the object graph


_LEAF_TYPES = (str, bytes, bytearray, int, float, bool, type(None))


def _check_array(array: np.ndarray) -> np.ndarray:
    """Refuse an array whose dtype is not a fresh allowed one, or which is too big."""
    fresh = np.dtype(array.dtype.str)
    if (
        array.dtype.str[1:] not in ALLOWED_DTYPES
        or array.dtype.hasobject
        or array.dtype.flags != fresh.flags
        or array.dtype != fresh
        or array.size > MAX_ARRAY_ELEMENTS
        or array.ndim > MAX_ARRAY_NDIM
    ):
        raise _Refused(f"array of dtype {array.dtype.str} and shape {array.shape} not allowed")
    return array


def _rebuild(root: object) -> object:
    """``root`` with every stand-in replaced by its array / scalar / dtype; checks all nodes.

    Iterative post-order walk: refuses cycles and nesting beyond `MAX_DEPTH`. Lists and dict
    values are replaced in place, tuples rebuilt, shared objects converted once. Leaves
    (numbers, text, bytes) are passed over without bookkeeping: there may be millions.
    """
    if isinstance(root, _LEAF_TYPES):
        return root
    done: dict[int, object] = {}  # id -> converted object
    originals: list[object] = []  # keeps every converted original alive, so ids stay unique
    on_path: set[int] = set()  # ids of the containers from the root to the current one
    stack: list[tuple[object, bool]] = [(root, False)]

    def converted(child: object) -> object:
        return child if isinstance(child, _LEAF_TYPES) else done[id(child)]

    while stack:
        obj, children_done = stack.pop()
        key = id(obj)
        if key in done:
            continue
        if isinstance(obj, _DtypeSpec | _ArraySpec | _ScalarSpec):
            value = obj.resolve()
            done[key] = _check_array(value) if isinstance(value, np.ndarray) else value
            originals.append(obj)
            continue
        if not isinstance(obj, list | tuple | dict | set | frozenset):
            raise _Refused(f"pickle holds a {type(obj).__name__}")
        if not children_done:
            if len(on_path) >= MAX_DEPTH:
                raise _Refused(f"containers nest deeper than {MAX_DEPTH} levels")
            children = [*obj.values(), *obj] if isinstance(obj, dict) else obj
            inner = [c for c in children if not isinstance(c, _LEAF_TYPES)]
            if not inner:  # numbers and text only: nothing to convert
                done[key] = obj
                originals.append(obj)
                continue
            on_path.add(key)
            stack.append((obj, True))
            for child in inner:
                if id(child) in on_path:
                    raise _Refused("pickle holds a container that contains itself")
                if id(child) not in done:
                    stack.append((child, False))
            continue
        on_path.discard(key)
        originals.append(obj)
        if isinstance(obj, list):
            obj[:] = [converted(c) for c in obj]
        elif isinstance(obj, dict):
            for k in obj:
                obj[k] = converted(obj[k])
        elif isinstance(obj, tuple):
            obj = tuple(converted(c) for c in obj)
        # Sets and frozensets hold only hashable leaves and tuples of them: no stand-ins.
        done[key] = obj
    return done[id(root)]


# ---------------------------------------------------------------------------------------------
# the unpickler


class _RestrictedUnpickler(pickle.Unpickler):
    """An unpickler whose globals come only from `_ALLOWED`."""

    def __init__(self, file: Any) -> None:
        # latin1 lets Python 2 pickles of numpy arrays load (numpy's own advice for them).
        super().__init__(file, encoding="latin1")

    def find_class(self, module: str, name: str) -> Any:
        return _check_global(module, name)

    def persistent_load(self, pid: Any) -> Any:
        raise _Refused("pickle uses persistent ids (a torch file?)")


_ZIP_MAGIC = b"PK\x03\x04"


def safe_load_pickle(path: str | Path) -> object:
    """Unpickle ``path`` admitting only real-valued numpy arrays, scalars and containers.

    Parameters
    ----------
    path : str or Path
        A pickle file, e.g. an EDGE output or an AIST++ motion file.

    Returns
    -------
    object
        The unpickled object (usually a dict of numpy arrays). Arrays and numpy scalars have
        dtype bool, int, uint or float (`ALLOWED_DTYPES`) in native byte order and are new,
        writeable objects.

    Raises
    ------
    InputFileError
        If the file is missing, too big, not a pickle, truncated or corrupt, references any
        global outside the allowlist (``os.system``, a class, torch ...), or breaks a limit
        (`MAX_DEPTH`, `MAX_OPCODES`, `MAX_INT_BITS`, `MAX_ARRAY_ELEMENTS`, dtypes other than
        `ALLOWED_DTYPES`). Globals and limits are checked before anything is built.
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            raw = f.read(MAX_PICKLE_BYTES + 1)
    except OSError as err:
        raise InputFileError(path, f"cannot be read ({err.strerror or err})") from None
    if raw.startswith(_ZIP_MAGIC):
        raise InputFileError(path, "is a zip archive (a torch.save or .npz file?), not a pickle")
    if not raw:
        raise InputFileError(path, "is empty, not a pickle")
    if len(raw) > MAX_PICKLE_BYTES:
        raise InputFileError(path, f"is larger than {MAX_PICKLE_BYTES >> 20} MB, too big a motion")
    try:
        try:
            scan_pickle(raw)
        except ValueError as err:
            if "Exceeds the limit" in str(err):  # int("9" * 5000) in a LONG opcode
                raise _Refused(
                    f"pickle holds an integer of more than {MAX_INT_BITS} bits"
                ) from None
            raise
        loaded = _RestrictedUnpickler(io.BytesIO(raw)).load()
        return _rebuild(loaded)
    except _Refused as err:
        raise InputFileError(path, "refused: " + re.sub(r"\s+", " ", str(err))) from None
    except RecursionError:
        raise InputFileError(path, f"refused: containers nest deeper than {MAX_DEPTH}") from None
    except MemoryError:
        raise  # every allocation is bounded before it happens: running out is a bug to see
    except Exception as err:  # any other failure inside the unpickler means a bad file
        detail = re.sub(r"\s+", " ", f"{type(err).__name__}: {err}")[:120]
        raise InputFileError(
            path, f"is not a valid pickle or is truncated/corrupt ({detail})"
        ) from None
