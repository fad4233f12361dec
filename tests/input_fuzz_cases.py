"""Hostile audio files, dance.npz files and policy JSONs, for the fuzz tests and the campaign
(``scripts/fuzz_inputs_campaign.py``). Every generator is seeded: the same cases every run.

Seeds are valid files; mutations damage them at the places a reader trusts: header numbers
(sample rate, channels, block size, chunk sizes), sample values (NaN, inf, 1e30), array
dtypes, shapes and values, JSON values, keys and nesting; plus blind byte and text edits.
"""

from __future__ import annotations

import copy
import io
import json
import struct
from typing import Any

import numpy as np
from motion_fuzz_cases import mutate_bytes, mutate_text

SR = 8000  # low rate: small files, fast decoding
HOSTILE_FLOATS = (np.nan, np.inf, -np.inf, 1e30, -3e38, 1e-320, 1e308, 0.0, 4.0)
HOSTILE_INTS = (0, 1, 2, 3, 255, 3999, 65535, 2**31 - 1, 2**32 - 1, 384_001, 44100)


# --- audio --------------------------------------------------------------------------------------


def _song(seconds: float, sr: int, channels: int, rng: np.random.Generator) -> np.ndarray:
    t = np.arange(int(seconds * sr)) / sr
    clicks = (np.sin(2 * np.pi * 2.0 * t) > 0.99).astype(np.float32)  # 120 BPM
    tone = 0.3 * np.sin(2 * np.pi * rng.uniform(100, 400) * t)
    mono = (tone + 0.5 * clicks).astype(np.float32)
    return np.stack([mono * (0.5 + 0.5 * c) for c in range(channels)], axis=1)


def encode(y: np.ndarray, sr: int, fmt: str, subtype: str | None = None) -> bytes:
    import soundfile as sf

    buf = io.BytesIO()
    sf.write(buf, y, sr, format=fmt, subtype=subtype)
    return buf.getvalue()


def audio_seeds(rng: np.random.Generator) -> list[tuple[str, bytes]]:
    """(suffix, bytes) of valid songs, 2.5 s: WAV 16-bit / float / 8-bit, FLAC, OGG (MP3 when
    this libsndfile writes it)."""
    import soundfile as sf

    seeds = [
        (".wav", encode(_song(2.5, SR, 1, rng), SR, "WAV", "PCM_16")),
        (".wav", encode(_song(2.5, 22050, 2, rng), 22050, "WAV", "FLOAT")),
        (".wav", encode(_song(2.5, SR, 3, rng), SR, "WAV", "PCM_U8")),
        (".flac", encode(_song(2.5, 16000, 2, rng), 16000, "FLAC")),
        (".ogg", encode(_song(2.5, 22050, 1, rng), 22050, "OGG")),
    ]
    if "MP3" in sf.available_formats():
        seeds.append((".mp3", encode(_song(2.5, 22050, 1, rng), 22050, "MP3")))
    return seeds


# Canonical WAV header fields: (offset, struct format).
WAV_FIELDS = {
    "riff_size": (4, "<I"),
    "fmt_size": (16, "<I"),
    "format_tag": (20, "<H"),
    "channels": (22, "<H"),
    "sample_rate": (24, "<I"),
    "byte_rate": (28, "<I"),
    "block_align": (32, "<H"),
    "bits_per_sample": (34, "<H"),
}


def wav_with_header(
    samples: np.ndarray, subtype: str, fields: dict[str, int], data_size: int | None = None
) -> bytes:
    """A WAV of ``samples`` whose header fields are overwritten (values clipped to the field)."""
    raw = bytearray(encode(samples, SR, "WAV", subtype))
    for name, value in fields.items():
        offset, fmt = WAV_FIELDS[name]
        limit = 2 ** (8 * struct.calcsize(fmt)) - 1
        struct.pack_into(fmt, raw, offset, max(0, min(int(value), limit)))
    if data_size is not None:
        at = raw.find(b"data")
        if at >= 0:
            struct.pack_into("<I", raw, at + 4, max(0, min(data_size, 2**32 - 1)))
    return bytes(raw)


def mutate_audio(seeds: list[tuple[str, bytes]], rng: np.random.Generator) -> tuple[str, bytes]:
    """One damaged audio file: a header field set to a hostile number, hostile float samples,
    or blind byte edits."""
    op = int(rng.integers(0, 3))
    if op == 0:
        name = list(WAV_FIELDS)[int(rng.integers(0, len(WAV_FIELDS)))]
        value = HOSTILE_INTS[int(rng.integers(0, len(HOSTILE_INTS)))]
        size = None if rng.random() < 0.7 else int(rng.choice([0, 7, 2**31, 2**32 - 1]))
        return ".wav", wav_with_header(_song(2.5, SR, 1, rng), "PCM_16", {name: value}, size)
    if op == 1:
        y = _song(2.5, SR, int(rng.integers(1, 3)), rng)
        flat = y.reshape(-1)
        for _ in range(int(rng.integers(1, 4))):
            flat[int(rng.integers(0, flat.size))] = HOSTILE_FLOATS[
                int(rng.integers(0, len(HOSTILE_FLOATS)))
            ]
        if rng.random() < 0.2:
            flat *= rng.choice([1e6, 1e30, 2.0])
        subtype = "DOUBLE" if rng.random() < 0.5 else "FLOAT"
        with np.errstate(over="ignore"):
            return ".wav", encode(y if subtype == "DOUBLE" else y.astype(np.float32), SR, "WAV",
                                  subtype)  # fmt: skip
    suffix, raw = seeds[int(rng.integers(0, len(seeds)))]
    return suffix, mutate_bytes(raw, rng, [r for _, r in seeds])


# --- dance.npz ----------------------------------------------------------------------------------


def dance_arrays(n: int = 150) -> dict[str, np.ndarray]:
    """The arrays of a valid dance.npz (3 s at 50 Hz)."""
    t = np.arange(n) / 50.0
    feet = np.column_stack([0.1 * np.sin(3 * t) ** 2, 0.05 * np.cos(2 * t) ** 2])
    return {
        "fps": np.float64(50.0),
        "time_s": t,
        "human_feet_m": feet,
        "targets_m": np.column_stack([feet, np.zeros((n, 2))]),
        "beats_s": np.arange(0.5, 3.0, 0.5),
        "downbeats_s": np.array([0.5, 2.5]),
        "mode": np.array("feasible"),
        "source": np.array("choreographer on song.wav"),
        "seed": np.int64(0),
        "version": np.array("0.1.0"),
    }


_DTYPES = ("f8", "f4", "f2", ">f8", "i8", "u1", "?", "c16", "U8", "S4", "M8[s]", "m8[s]")


def hostile_array(rng: np.random.Generator, like: np.ndarray) -> np.ndarray:
    """An array that is wrong in dtype, shape or values."""
    op = int(rng.integers(0, 5))
    if op == 0:  # wrong dtype, same shape
        dtype = _DTYPES[int(rng.integers(0, len(_DTYPES)))]
        try:
            return np.asarray(like).astype(dtype)
        except (TypeError, ValueError):
            return np.zeros(like.shape, dtype=dtype)
    if op == 1:  # wrong shape
        shape = tuple(int(s) for s in rng.integers(0, 6, size=int(rng.integers(0, 4))))
        return rng.normal(size=shape)
    if op == 2:  # hostile values
        numeric = like.dtype.kind in "biuf"
        out = (np.array(like, dtype=np.float64) if numeric else np.zeros(like.shape)).reshape(-1)
        if out.size:
            for _ in range(int(rng.integers(1, 4))):
                out[int(rng.integers(0, out.size))] = HOSTILE_FLOATS[
                    int(rng.integers(0, len(HOSTILE_FLOATS)))
                ]
        return out.reshape(np.shape(like))
    if op == 3:  # scaled, shifted or reversed
        out = np.array(like, dtype=np.float64) if like.dtype.kind in "biuf" else np.zeros(3)
        return out[::-1] * rng.choice([-1.0, 1e6, 1e-300, 0.0]) if out.ndim else out * 1e300
    text = "x" * int(rng.choice([0, 3, 2000])) + rng.choice(["", "\n", "\x00", "é"])
    return np.array(text)


def mutate_dance(rng: np.random.Generator) -> bytes:
    """One damaged dance.npz: fields replaced, deleted or added; sometimes byte edits."""
    import zipfile

    arrays = dance_arrays(int(rng.choice([1, 2, 150])))
    for _ in range(int(rng.integers(1, 3))):
        key = list(arrays)[int(rng.integers(0, len(arrays)))]
        r = rng.random()
        if r < 0.1:
            del arrays[key]
        elif r < 0.15:
            arrays[f"extra{int(rng.integers(0, 9))}"] = rng.normal(size=3)
        else:
            arrays[key] = hostile_array(rng, arrays[key])
    buf = io.BytesIO()
    (np.savez_compressed if rng.random() < 0.5 else np.savez)(buf, **arrays)
    raw = buf.getvalue()
    if rng.random() < 0.3:
        raw = mutate_bytes(raw, rng, [raw])
    elif rng.random() < 0.1:  # a member whose header promises a huge array
        out = io.BytesIO(raw)
        with zipfile.ZipFile(out, "a") as zf, zf.open("targets_m.npy", "w") as fh:
            shape = (int(rng.choice([10**7, 2**40, 10**9])), 4)
            np.lib.format.write_array_header_1_0(
                fh, {"descr": "<f8", "fortran_order": False, "shape": shape}
            )
            fh.write(bytes(64))
        raw = out.getvalue()
    return raw


# --- policy JSON --------------------------------------------------------------------------------


def shipped_policy() -> dict[str, Any]:
    from quaddance.play.policy import shipped_policy_path

    return json.loads(shipped_policy_path().with_suffix(".json").read_text())


def _paths(obj: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key path inside a JSON value."""
    out = [prefix] if prefix else []
    if isinstance(obj, dict):
        for key, value in obj.items():
            out += _paths(value, (*prefix, key))
    elif isinstance(obj, list):
        for i, value in enumerate(obj):
            out += _paths(value, (*prefix, i))
    return out


def hostile_json_value(rng: np.random.Generator) -> Any:
    choices = [
        None, True, False, 0, -1, 2**64, 10**400, 1e308, -1e308, 5e-324, float("nan"),
        float("inf"), "", "x" * 10_000, "\u0663", [], [1, 2], {}, {"a": None}, [[[[[]]]]],
    ]  # fmt: skip
    return copy.deepcopy(choices[int(rng.integers(0, len(choices)))])


def mutate_policy(base: dict[str, Any], rng: np.random.Generator) -> str:
    """One damaged policy JSON text: values replaced by hostile ones, keys deleted or added,
    numbers nudged (so that the two copies of kp, rates, ... disagree), or text edits."""
    obj = copy.deepcopy(base)
    paths = _paths(obj)
    for _ in range(int(rng.integers(1, 4))):
        path = paths[int(rng.integers(0, len(paths)))]
        parent = obj
        try:
            for key in path[:-1]:
                parent = parent[key]
            last = path[-1]
            r = rng.random()
            if r < 0.6:
                parent[last] = hostile_json_value(rng)
            elif r < 0.75 and isinstance(parent, dict):
                del parent[last]
            elif r < 0.85 and isinstance(parent, dict):
                parent[f"new{int(rng.integers(0, 9))}"] = hostile_json_value(rng)
            elif isinstance(parent[last], int | float) and not isinstance(parent[last], bool):
                parent[last] = parent[last] * float(rng.choice([0.5, 2.0, -1.0, 1.0001]))
        except (KeyError, IndexError, TypeError, OverflowError):
            continue  # the path went away with an earlier edit, or a huge int was nudged
    text = json.dumps(obj)
    if rng.random() < 0.2:
        text = mutate_text(text, rng)
    return text


def load_policy_json(path: str) -> None:
    """The policy JSON reader, with the property checked on what it returns."""
    from quaddance.play.policy_spec import PolicySpec

    spec = PolicySpec.load(path)
    assert PolicySpec.from_json(spec.to_json(), path) == spec  # what loads, round-trips
    assert len(spec.obs_layout) <= 64 and spec.obs_history_len <= 100


def load_dance_checked(path: str) -> None:
    """The dance.npz reader, with the property checked on what it returns."""
    from quaddance.dancefile import MAX_FPS, load_dance

    dance = load_dance(path)
    n = dance.time_s.size
    assert 0 < dance.fps <= MAX_FPS and n >= 1
    assert dance.human_feet_m.shape == (n, 2) and dance.targets_m.shape == (n, 4)
    for arr in (dance.time_s, dance.human_feet_m, dance.targets_m, dance.beats_s):
        assert arr.dtype == np.float64 and np.all(np.isfinite(arr))


def load_audio_checked(path: str) -> None:
    """The audio decoder, with the property checked on what it returns."""
    from quaddance.music.audio import MAX_SONG_S, load_audio

    y, sr = load_audio(path)
    assert sr == 22050 and y.dtype == np.float32 and y.ndim == 1
    assert 2.0 * sr * 0.99 <= y.size <= MAX_SONG_S * sr * 1.01
    assert np.all(np.isfinite(y)) and float(np.max(np.abs(y))) <= 1.0
