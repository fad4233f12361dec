"""Inputs for fuzzing the motion readers: valid seeds, crafted hostile files, mutators.

Shared by ``tests/test_fuzz_motion.py`` (small, fixed-seed runs) and
``scripts/fuzz_campaign.py`` (large runs). Everything here is deterministic given a
``numpy.random.Generator``.
"""

from __future__ import annotations

import os
import pickle
import struct

import numpy as np

# ---------------------------------------------------------------------------------------------
# valid seeds


def _stepping_poses(n_frames: int, fps: float, rng: np.random.Generator) -> np.ndarray:
    """SMPL poses (T, 72) of alternate knee lifts plus a little noise, radians."""
    phase = 2 * np.pi * np.arange(n_frames) / fps
    poses = 0.02 * rng.standard_normal((n_frames, 72))
    for side, (hip, knee) in enumerate(((1, 4), (2, 5))):
        lift = 0.8 * np.maximum((-1) ** side * np.sin(phase), 0)
        poses[:, 3 * hip] -= lift
        poses[:, 3 * knee] += 2 * lift
    return poses


def valid_motion_pickles(rng: np.random.Generator) -> list[bytes]:
    """EDGE (full_pose; SMPL parameters) and AIST++ pickles at protocols 0-5, 1.3-2 s long."""
    from quaddance.choreo.smpl import smpl_joints

    seeds = []
    for protocol in (0, 2, 4, 5):
        poses = _stepping_poses(40, 30.0, rng)
        trans = np.zeros((40, 3))
        trans[:, 1] = 0.95
        joints = smpl_joints(poses, trans)
        full_pose = np.stack([joints[..., 0], -joints[..., 2], joints[..., 1]], axis=-1)
        edge = {
            "smpl_poses": poses.astype(np.float32),
            "smpl_trans": trans,
            "full_pose": full_pose.astype(np.float32),
        }
        seeds.append(pickle.dumps(edge, protocol=protocol))
        params = {"smpl_poses": poses, "smpl_trans": trans, "fps": 30}
        seeds.append(pickle.dumps(params, protocol=protocol))
        aist_poses = _stepping_poses(70, 60.0, rng).astype(np.float32)
        aist = {
            "smpl_poses": aist_poses,
            "smpl_trans": trans.repeat(2, axis=0)[:70] * 93.5,
            "smpl_scaling": np.array([93.5]),
            "smpl_loss": np.float64(0.5),
        }
        seeds.append(pickle.dumps(aist, protocol=protocol))
    return seeds


BVH_HIERARCHY = """HIERARCHY
ROOT Hips
{
\tOFFSET 0.00 0.00 0.00
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT LeftUpLeg
\t{
\t\tOFFSET 10.0 -5.0 0.0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tJOINT LeftLeg
\t\t{
\t\t\tOFFSET 0.0 -45.0 0.0
\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\t\tJOINT LeftFoot
\t\t\t{
\t\t\t\tOFFSET 0.0 -45.0 0.0
\t\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\t\t\tEnd Site
\t\t\t\t{
\t\t\t\t\tOFFSET 0.0 -5.0 12.0
\t\t\t\t}
\t\t\t}
\t\t}
\t}
\tJOINT RightUpLeg
\t{
\t\tOFFSET -10.0 -5.0 0.0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tJOINT RightLeg
\t\t{
\t\t\tOFFSET 0.0 -45.0 0.0
\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\t\tJOINT RightFoot
\t\t\t{
\t\t\t\tOFFSET 0.0 -45.0 0.0
\t\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\t\t}
\t\t}
\t}
}
"""
BVH_CHANNELS = 6 + 6 * 3


def valid_bvh(n_frames: int, frame_time_s: float, rng: np.random.Generator) -> str:
    """The two-leg skeleton above (Y-up, cm) lifting the left thigh on alternate beats."""
    lines = [BVH_HIERARCHY + "MOTION", f"Frames: {n_frames}", f"Frame Time: {frame_time_s}"]
    for t in range(n_frames):
        hip = 60.0 * (t % 24 >= 12) + rng.normal(0, 1)
        root = [3.0 * t, 100.0, 0.0, 0.0, 0.0, 0.0]
        lines.append(" ".join(f"{v:.4f}" for v in [*root, 0.0, -hip, 0.0] + [0.0] * 15))
    return "\n".join(lines) + "\n"


def valid_bvh_texts(rng: np.random.Generator) -> list[str]:
    return [valid_bvh(n, dt, rng) for n, dt in ((48, 1 / 24), (40, 0.0333333), (130, 1 / 120))]


# ---------------------------------------------------------------------------------------------
# hostile pickles


class _Reduce:
    """Pickles as ``func(*args)``: how a malicious file calls anything."""

    def __init__(self, func: object, args: tuple[object, ...]) -> None:
        self.func, self.args = func, args

    def __reduce__(self) -> tuple[object, tuple[object, ...]]:
        return self.func, self.args


def _unicode(text: str) -> bytes:
    raw = text.encode()
    return b"X" + struct.pack("<I", len(raw)) + raw


def object_array_pickle(
    code: str = "O8", flags: int = 0, pointers: tuple[int, ...] = (0x41414141, 0x4242, 8, 16)
) -> bytes:
    """Issue 8's crash: ``{"full_pose": array}`` where the array is rebuilt with dtype
    ``code`` whose pickled state sets ``flags``, and whose raw bytes are ``pointers``.

    Only globals that the old allowlist admitted are used (_reconstruct, ndarray, dtype).
    With ``O8`` and flags 0, numpy reads the bytes as object pointers: a segfault.
    """
    raw = struct.pack(f"<{len(pointers)}Q", *pointers)
    array = (
        b"cnumpy._core.multiarray\n_reconstruct\ncnumpy\nndarray\nK\x00\x85C\x01b\x87R"
        + b"(K\x01K"
        + bytes([len(pointers)])
        + b"\x85cnumpy\ndtype\n"
        + _unicode(code)
        + b"\x89\x88\x87R(K\x03"
        + _unicode("|")
        + b"NNNJ\xff\xff\xff\xffJ\xff\xff\xff\xffK"
        + bytes([flags])
        + b"tb\x89C"
        + bytes([len(raw)])
        + raw
        + b"tb"
    )
    return b"\x80\x02}" + _unicode("full_pose") + array + b"s."


def deep_pickle(kind: str, depth: int) -> bytes:
    """Containers nested ``depth`` levels, as the value of ``full_pose`` (or a dict key).

    ``memo_chain`` builds the lists first and links them afterwards through the memo, so the
    nesting is invisible to a scan that only follows the stack.
    """
    if kind == "list":
        inner = b"]" * depth + b"a" * (depth - 1)
    elif kind == "tuple":
        inner = b"(" * depth + b"t" * depth
    elif kind == "dict":
        inner = (b"}" + _unicode("k")) * depth + b"}" + b"s" * depth
    elif kind == "tuple_key":
        # A deep tuple as a dict key: hashing it recursed in C (segfault) before the fix.
        return b"\x80\x02}" + b"(" * depth + b"t" * depth + b"K\x01s."
    elif kind == "frozenset":
        inner = b"(" * depth + b"\x91" * depth
    elif kind == "memo_chain":
        make = b"".join(b"]r" + struct.pack("<I", i) for i in range(depth)) + b"0" * depth
        link = b"".join(
            b"j" + struct.pack("<I", i) + b"j" + struct.pack("<I", i + 1) + b"a0"
            for i in range(depth - 1)
        )
        inner = make + link + b"j" + struct.pack("<I", 0)
    else:
        raise ValueError(kind)
    return b"\x80\x04}" + _unicode("full_pose") + inner + b"s."


def _array_state(shape: tuple[int, ...], raw: bytes) -> bytes:
    """``_reconstruct`` + BUILD of an f8 array with ``shape`` and raw data ``raw``."""
    shape_ops = b"(" + b"".join(b"\x8a\x08" + struct.pack("<q", d) for d in shape) + b"t"
    return (
        b"cnumpy._core.multiarray\n_reconstruct\ncnumpy\nndarray\nK\x00\x85C\x01b\x87R(K\x01"
        + shape_ops
        + b"cnumpy\ndtype\n"
        + _unicode("f8")
        + b"\x89\x88\x87R(K\x03"
        + _unicode("<")
        + b"NNNJ\xff\xff\xff\xffJ\xff\xff\xff\xffK\x00tb\x89B"
        + struct.pack("<I", len(raw))
        + raw
        + b"tb"
    )


def hostile_pickles(sentinel: str) -> dict[str, bytes]:
    """Crafted pickles, each refused by a different check. ``sentinel``: what a payload
    that ran would create."""
    key = b"\x80\x04}" + _unicode("full_pose")
    numpy_global = b"cnumpy._core.numeric\n_frombuffer\n"
    cases = {
        "object_dtype_pointers": object_array_pickle(),
        "object_dtype_o_flags": object_array_pickle("f8", flags=63),
        "complex_dtype": object_array_pickle("c16", pointers=(0, 0, 0, 0)),
        "unicode_dtype": object_array_pickle("U2", pointers=(0, 0, 0, 0)),
        "os_system": pickle.dumps(_Reduce(os.system, (f"touch {sentinel}",)), protocol=2),
        "eval": pickle.dumps(
            {"full_pose": _Reduce(eval, (f"open({sentinel!r}, 'w').close()",))}, protocol=4
        ),
        "object_array_payload": pickle.dumps(
            {"full_pose": np.array([1.0, _Reduce(os.system, (f"touch {sentinel}",))], object)},
            protocol=5,
        ),
        "ndarray_call_80gb": key + b"cnumpy\nndarray\n\x8a\x05\x00\xe4\x0bT\x02\x85\x85Rs.",
        "reconstruct_huge_shape": key + _array_state((10**9, 24, 3), b"\x00" * 8) + b"s.",
        "reconstruct_negative_shape": key + _array_state((-5, 24, 3), b"") + b"s.",
        "frombuffer_huge_shape": key
        + numpy_global
        + b"(\x96\x08\x00\x00\x00\x00\x00\x00\x00"
        + b"\x00" * 8
        + b"cnumpy\ndtype\n"
        + _unicode("f8")
        + b"\x89\x88\x87R(\x8a\x06\x00\x00\x00\x00\x00\x01t"
        + _unicode("C")
        + b"tRs.",
        "bytearray_size": key + b"cbuiltins\nbytearray\n\x8a\x05\x00\x00\x00\x00\x10\x85Rs.",
        "huge_long4": key + b"\x8b" + struct.pack("<I", 100_000) + b"\x01" * 100_000 + b"s.",
        "huge_long_text": b"(dVfull_pose\nL" + b"9" * 5000 + b"L\ns.",
        "huge_int_fps": b"\x80\x04}" + _unicode("fps") + b"\x8a\x0a" + b"\xff" * 9 + b"\x7fs.",
        "memo_index_4g": key + b"]r\xff\xff\xff\xffs.",
        "unicode8_length": key + b"\x8d" + struct.pack("<Q", 1 << 60) + b"abcs.",
        "frame_length": b"\x80\x04\x95" + struct.pack("<Q", 1 << 60) + b"}.",
        "codecs_other": key
        + b"c_codecs\nencode\n"
        + _unicode("x")
        + _unicode("rot13")
        + b"\x86Rs.",
        "set_value": key + b"cbuiltins\nset\n]K\x01a\x85Rs.",
        "persistent_id": key + _unicode("storage") + b"Qs.",
        "newobj": key + b"cbuiltins\nset\n)\x81s.",
        "cycle": b"\x80\x04}" + _unicode("full_pose") + b"]\x94h\x00as.",
    }
    for kind in ("list", "tuple", "dict", "tuple_key", "frozenset", "memo_chain"):
        cases[f"deep_{kind}"] = deep_pickle(kind, 300_000 if kind != "memo_chain" else 100_000)
    return cases


# ---------------------------------------------------------------------------------------------
# mutators

_EXTREME_INTS = (0, 1, 0x7F, 0x80, 0xFF, 0x7FFF, 0xFFFF, 0x7FFFFFFF, 0xFFFFFFFF, 1 << 63)
_EXTREME_FLOATS = (
    float("nan"),
    float("inf"),
    -float("inf"),
    1e308,
    -1e308,
    5e-324,
    1e-320,
    -0.0,
    0.0,
    1e20,
)


def mutate_bytes(data: bytes, rng: np.random.Generator, corpus: list[bytes]) -> bytes:
    """``data`` with 1-4 random edits: bit flips, random or extreme bytes, insertions,
    deletions, duplicated runs, splices from another corpus item, truncation, and float64s
    replaced with NaN / inf / 1e308 / denormals."""
    out = bytearray(data)
    for _ in range(int(rng.integers(1, 5))):
        if not out:
            out = bytearray(rng.bytes(8))
        n = len(out)
        at = int(rng.integers(0, n))
        op = int(rng.integers(0, 9))
        if op == 0:
            out[at] ^= 1 << int(rng.integers(0, 8))
        elif op == 1:
            out[at] = int(rng.integers(0, 256))
        elif op == 2:
            out[at:at] = rng.bytes(int(rng.integers(1, 16)))
        elif op == 3:
            del out[at : at + int(rng.integers(1, 32))]
        elif op == 4:
            length = int(rng.integers(1, 64))
            out[at:at] = out[at : at + length] * int(rng.integers(1, 4))
        elif op == 5:
            other = corpus[int(rng.integers(0, len(corpus)))]
            start = int(rng.integers(0, len(other)))
            out[at:] = other[start : start + int(rng.integers(1, 256))] + out[at:]
        elif op == 6:
            width = (1, 2, 4, 8)[int(rng.integers(0, 4))]
            value = _EXTREME_INTS[int(rng.integers(0, len(_EXTREME_INTS)))]
            out[at : at + width] = (value & ((1 << (8 * width)) - 1)).to_bytes(width, "little")
        elif op == 7:
            value = _EXTREME_FLOATS[int(rng.integers(0, len(_EXTREME_FLOATS)))]
            order = "<d" if rng.integers(0, 2) else ">d"
            out[at : at + 8] = struct.pack(order, value)
        else:
            del out[int(rng.integers(0, n + 1)) :]
    return bytes(out)


_HOSTILE_TOKENS = (
    "1e-320",
    "5e-324",
    "1e308",
    "-1e308",
    "nan",
    "inf",
    "-0",
    "0",
    "99999999999999",
    "1" * 5000,
    "\u0663",  # Arabic-Indic 3
    "\u00b3",  # superscript 3
    "1_0",
    "0x10",
    "{",
    "}",
    "",
    "JOINT",
    "End Site",
    "CHANNELS 7",
    "-",
)


def mutate_text(text: str, rng: np.random.Generator) -> str:
    """``text`` with 1-4 token or line edits: hostile numbers, duplicated / deleted lines,
    swapped tokens, truncation."""
    lines = text.split("\n")
    for _ in range(int(rng.integers(1, 5))):
        op = int(rng.integers(0, 6))
        i = int(rng.integers(0, len(lines))) if lines else 0
        if not lines:
            lines = [""]
        tokens = lines[i].split(" ")
        if op in (0, 1):
            j = int(rng.integers(0, len(tokens)))
            tokens[j] = _HOSTILE_TOKENS[int(rng.integers(0, len(_HOSTILE_TOKENS)))]
            lines[i] = " ".join(tokens)
        elif op == 2:
            lines[i:i] = lines[i : i + int(rng.integers(1, 4))] * int(rng.integers(1, 3))
        elif op == 3:
            del lines[i : i + int(rng.integers(1, 4))]
        elif op == 4 and len(tokens) > 1:
            j, k = rng.integers(0, len(tokens), size=2)
            tokens[j], tokens[k] = tokens[k], tokens[j]
            lines[i] = " ".join(tokens)
        else:
            lines = lines[: i + 1]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# large inputs: algorithmic blow-ups (quadratic searches, per-item bookkeeping) show only here


def _chain_bvh(n_joints: int, n_frames: int) -> str:
    """A skeleton of two legs and a spine of ``n_joints`` joints, ``n_frames`` zero frames."""
    spine = "".join(
        f"JOINT s{i}\n{{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
        for i in range(n_joints)
    )
    spine += "End Site\n{\nOFFSET 0 1 0\n}\n" + "}\n" * n_joints
    hierarchy = BVH_HIERARCHY.rstrip().removesuffix("}") + spine + "}\n"
    row = " ".join(["0"] * (BVH_CHANNELS + 3 * n_joints))
    return f"{hierarchy}MOTION\nFrames: {n_frames}\nFrame Time: 0.01\n" + (row + "\n") * n_frames


def shared_dag_pickle(depth: int, width: int) -> bytes:
    """``full_pose`` = a list of ``width`` references to one list of ``width`` references ...
    ``depth`` levels down to a float: tiny file, width**depth numbers when expanded."""
    # Built with the memo: each level memoizes the previous and repeats it width times.
    ops = bytearray(b"G\x3f\xf0\x00\x00\x00\x00\x00\x00\x940")  # value, memo 0, pop
    for level in range(depth):
        ops += b"(" + (b"j" + struct.pack("<I", level)) * width + b"l\x940"
    ops += b"j" + struct.pack("<I", depth)
    return b"\x80\x04}" + _unicode("full_pose") + bytes(ops) + b"s."


def large_cases(rng: np.random.Generator) -> dict[str, bytes]:
    """Big or expansion-heavy motion files, each a few MB at most on disk."""
    valid_long = valid_bvh(20_000, 1 / 120, rng)
    head = valid_bvh(10, 1 / 120, rng).split("MOTION")[0]
    floats = [[[float(v) for v in frame] for frame in rng.normal(0, 0.3, (24, 3))]] * 3000
    return {
        "bvh_blank_lines.bvh": b"HIERARCHY\n" + b"\n" * 2_000_000 + b"ROOT x",
        "bvh_blank_lines_motion.bvh": (head + "MOTION" + "\n" * 2_000_000).encode(),
        "bvh_long_valid.bvh": valid_long.encode(),
        "bvh_long_mutated.bvh": mutate_text(valid_long, rng).encode(),
        "bvh_one_line.bvh": (head + "MOTION\nFrames: 200000\nFrame Time: 0.005\n").encode()
        + b"0.5 " * 4_800_000,
        "bvh_header_claims_1m_frames.bvh": (head + "MOTION\nFrames: 1000000\n").encode()
        + b"Frame Time: 0.001\n0 0 0\n",
        "bvh_500_joints.bvh": _chain_bvh(480, 1000).encode(),
        "bvh_600_joints.bvh": _chain_bvh(600, 10).encode(),
        "bvh_spaces.bvh": b"HIERARCHY" + b" " * 20_000_000 + b"\nMOTION\n",
        "bvh_frame_words.bvh": b"HIERARCHY\nMOTION\n" + b"Frame " * 2_000_000,
        "pickle_float_lists.pkl": pickle.dumps({"full_pose": floats}, protocol=2),
        "pickle_float_lists_p0.pkl": pickle.dumps({"full_pose": floats[:300]}, protocol=0),
        "pickle_shared_dag.pkl": shared_dag_pickle(60, 2),
        "pickle_shared_dag_wide.pkl": shared_dag_pickle(20, 16),
        "pickle_many_keys.pkl": pickle.dumps({i: i for i in range(1_000_000)}, protocol=4),
        "pickle_too_many_opcodes.pkl": b"\x80\x04(" + b"N" * 3_100_000 + b"l.",
        "pickle_big_bytes.pkl": pickle.dumps({"x": bytes(20 << 20)}, protocol=4),
        "pickle_long_list.pkl": pickle.dumps({"full_pose": [0.5] * 2_900_000}, protocol=4),
    }
