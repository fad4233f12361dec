"""User body moves and styles from a TOML file (``--moves FILE``).

Format (every key optional except a move's ``gestures``)::

    [moves.shimmy_fast]            # a new body move (or a built-in name, to replace it)
    n_beats = 2                    # length, beats (1-32; default 4)
    weight_quiet = 0.2             # choice weight at energy 0 and 1 (>= 0; default 1)
    weight_loud = 2.0
    gestures = [                   # what the trunk does; [] = stand still
      { column = "roll_rad", amplitude = 0.08, every_beats = 0.5, shape = "swing" },
      { column = "height_offset_m", amplitude = -0.02 },   # shape "dip", every beat
    ]

    [styles.party]                 # a style: weights of body and paw move names (a
                                   # built-in style's name changes its body weights if it
                                   # names a body move, its paw weights if it names a paw one)
    shimmy_fast = 3.0
    bounce = 2.0
    run = 2.0                      # a paw move of quaddance.choreo.choreographer.MOVES

Columns are `quaddance.layout.BODY_COLUMNS`; amplitudes are in robot units (m, rad) and
must lie inside the robot's four-feet range (`RobotCfg.body_four_feet` of the robot the
dance is for). Every error is one line naming the file and the problem.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

from quaddance.choreo.body import BODY_MOVES, BODY_STYLES, SHAPES, BodyMove, Gesture, MoveSet
from quaddance.choreo.choreographer import MOVES
from quaddance.errors import InputFileError, not_a_file
from quaddance.layout import BODY_COLUMNS
from quaddance.robots import GO1, BodyLimits

MAX_MOVES_FILE_BYTES = 1 << 20
MAX_MOVES = 200
MAX_GESTURES = 8
_MOVE_KEYS = {"n_beats", "weight_quiet", "weight_loud", "gestures"}
_GESTURE_KEYS = {"column", "amplitude", "every_beats", "shape", "width_beats"}


def _names(names: Any) -> str:
    return ", ".join(sorted(names))


def _number(path: Path, where: str, value: Any, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputFileError(path, f"{where} must be a number, got {type(value).__name__}")
    if not (math.isfinite(value) and low <= value <= high):
        raise InputFileError(path, f"{where} is {value}, expected {low:g} to {high:g}")
    return float(value)


def _known_keys(path: Path, where: str, raw: dict, allowed: set[str]) -> None:
    unknown = sorted(set(raw) - allowed)
    if unknown:
        raise InputFileError(
            path, f"{where}: unknown key {unknown[0]!r}; allowed: {_names(allowed)}"
        )


def _gesture(path: Path, where: str, raw: Any, limits: BodyLimits) -> Gesture:
    if not isinstance(raw, dict):
        raise InputFileError(path, f"{where} must be a table {{column = ..., amplitude = ...}}")
    _known_keys(path, where, raw, _GESTURE_KEYS)
    for key in ("column", "amplitude"):
        if key not in raw:
            raise InputFileError(path, f"{where}: missing {key!r}")
    column = raw["column"]
    if column not in BODY_COLUMNS:
        raise InputFileError(
            path, f"{where}: unknown column {column!r}; one of {', '.join(BODY_COLUMNS)}"
        )
    c = BODY_COLUMNS.index(column)
    lo, hi = limits.low[c], limits.high[c]
    amplitude = _number(path, f"{where}.amplitude", raw["amplitude"], -1e9, 1e9)
    # A swing goes to both sides; a dip only to the amplitude's side.
    reach = (
        (-abs(amplitude), abs(amplitude))
        if raw.get("shape") == "swing"
        else (min(amplitude, 0.0), max(amplitude, 0.0))
    )
    if reach[0] < lo - 1e-12 or reach[1] > hi + 1e-12:
        raise InputFileError(
            path,
            f"{where}.amplitude {amplitude:g} is beyond the robot's {column} range "
            f"[{lo:g}, {hi:g}]",
        )
    shape = raw.get("shape", "dip")
    if shape not in SHAPES:
        raise InputFileError(path, f"{where}.shape must be one of {_names(SHAPES)}, got {shape!r}")
    every = _number(path, f"{where}.every_beats", raw.get("every_beats", 1.0), 0.25, 16.0)
    width = _number(path, f"{where}.width_beats", raw.get("width_beats", 0.9), 0.1, 16.0)
    return Gesture(column, amplitude, every, shape, width)


def _move(path: Path, name: str, raw: Any, limits: BodyLimits) -> BodyMove:
    where = f"moves.{name}"
    if not isinstance(raw, dict):
        raise InputFileError(path, f"{where} must be a table")
    _known_keys(path, where, raw, _MOVE_KEYS)
    if "gestures" not in raw:
        raise InputFileError(path, f"{where}: missing 'gestures' (a list; [] = stand still)")
    gestures = raw["gestures"]
    if not isinstance(gestures, list) or len(gestures) > MAX_GESTURES:
        raise InputFileError(path, f"{where}.gestures must be a list of at most {MAX_GESTURES}")
    n_beats = _number(path, f"{where}.n_beats", raw.get("n_beats", 4), 1, 32)
    if n_beats != int(n_beats):
        raise InputFileError(path, f"{where}.n_beats must be a whole number, got {n_beats}")
    return BodyMove(
        name=name,
        n_beats=int(n_beats),
        gestures=tuple(
            _gesture(path, f"{where}.gestures[{k}]", g, limits) for k, g in enumerate(gestures)
        ),
        weight_quiet=_number(path, f"{where}.weight_quiet", raw.get("weight_quiet", 1.0), 0, 1e3),
        weight_loud=_number(path, f"{where}.weight_loud", raw.get("weight_loud", 1.0), 0, 1e3),
    )


def load_moves(path: str | Path, limits: BodyLimits = GO1.body_four_feet) -> MoveSet:
    """Read a moves file: the built-in body moves plus (or replaced by) the file's, and the
    file's styles; amplitudes within ``limits`` (the four-feet range of the robot the dance
    is for). Raise `InputFileError` (one line) for anything wrong."""
    path = Path(path)
    if not path.is_file():
        raise not_a_file(path)
    if path.stat().st_size > MAX_MOVES_FILE_BYTES:
        raise InputFileError(path, f"is larger than {MAX_MOVES_FILE_BYTES >> 20} MB")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))  # a BOM is not TOML
    except UnicodeDecodeError:
        raise InputFileError(path, "is not UTF-8 text") from None
    except tomllib.TOMLDecodeError as err:
        raise InputFileError(path, f"is not valid TOML ({' '.join(str(err).split())})") from None
    except OSError as err:
        raise InputFileError(path, f"cannot be read ({err.strerror or err})") from None
    unknown = sorted(set(data) - {"moves", "styles"})
    if unknown:
        raise InputFileError(
            path, f"unknown section {unknown[0]!r}; a moves file has [moves.NAME] and [styles.NAME]"
        )
    raw_moves, raw_styles = data.get("moves", {}), data.get("styles", {})
    if not isinstance(raw_moves, dict) or not isinstance(raw_styles, dict):
        raise InputFileError(path, "'moves' and 'styles' must be tables")
    if len(raw_moves) > MAX_MOVES:
        raise InputFileError(path, f"{len(raw_moves)} moves, at most {MAX_MOVES}")
    new = {name: _move(path, name, raw, limits) for name, raw in raw_moves.items()}
    body_moves = tuple(new.pop(m.name, m) for m in BODY_MOVES) + tuple(new.values())

    known = {m.name for m in body_moves} | {m.name for m in MOVES}
    styles: dict[str, dict[str, float]] = {}
    for style, weights in raw_styles.items():
        if not isinstance(weights, dict):
            raise InputFileError(path, f"styles.{style} must be a table of move = weight")
        for move, weight in weights.items():
            if move not in known:
                raise InputFileError(
                    path, f"styles.{style}: unknown move {move!r}; known: {_names(known)}"
                )
            _number(path, f"styles.{style}.{move}", weight, 0.0, 1e3)
        styles[style] = {k: float(v) for k, v in weights.items()}
        # A paw move the style does not name keeps weight 1 (`choreographer.choreograph`).
        if all(styles[style].get(m.name, 1.0) == 0.0 for m in MOVES):
            raise InputFileError(
                path,
                f"styles.{style} gives every paw move weight 0; give one a weight above 0 "
                "(hold keeps the paws down)",
            )
    return MoveSet(body_moves=body_moves, styles=styles, source=path.name, path=path)


__all__ = ["BODY_STYLES", "load_moves"]
