"""Hostile motion files never crash quaddance: crafted pickles, hostile numbers, fuzzing.

Every reader call here runs in a child process under a memory limit and a timeout
(`fuzz_harness`), so a segfault, a blow-up or a hang fails the test instead of the run. The
promise checked: a motion file either loads into finite foot heights, or is refused with one
short line naming the file (exit 2 from the CLI); never a traceback, never code run.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
from fuzz_harness import REFUSED, Outcome, run_call, run_cli, run_reader_batch, summarize
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from motion_fuzz_cases import (
    BVH_CHANNELS,
    BVH_HIERARCHY,
    hostile_pickles,
    mutate_bytes,
    mutate_text,
    object_array_pickle,
    shared_dag_pickle,
    valid_bvh_texts,
    valid_motion_pickles,
)

LOAD_MOTION = "quaddance.choreo.motion:load_motion"


def _report(outcomes: list[Outcome]) -> str:
    """The outcomes that break the promise, for the assertion message."""
    bad = [o for o in outcomes if not o.clean]
    lines = [f"{summarize(outcomes)}"] + [f"#{o.index} {o.kind}: {o.detail[:600]}" for o in bad]
    return "\n".join(lines[:12])


# ---------------------------------------------------------------------------------------------
# crafted files


@pytest.mark.parametrize(
    ("name", "problem"),
    [
        ("object_dtype_pointers", "not a real number"),  # issue 8: SIGSEGV before the fix
        ("deep_tuple_key", "nest deeper"),  # issue 12: SIGSEGV before the fix
        ("reconstruct_huge_shape", "exceeds"),  # issue 12: killed for memory before the fix
        ("huge_int_fps", "integer of more than 64 bits"),  # issue 12: traceback before the fix
    ],
)
def test_crafted_pickles_get_one_line_and_exit_2_from_the_cli(tmp_path, name, problem):
    path = tmp_path / f"{name}.pkl"
    path.write_bytes(hostile_pickles(str(tmp_path / "SENTINEL"))[name])
    out = tmp_path / "dance.npz"
    outcome, done = run_cli(["choreograph", "--motion", path, "-o", out], file=path, timeout_s=120)
    assert outcome.kind == REFUSED, outcome
    assert done is not None and done.returncode == 2
    assert done.stderr.startswith(f"quaddance: error: {path}: refused: ")
    assert done.stderr.count("\n") == 1 and problem in done.stderr
    assert not out.exists()


def test_every_crafted_pickle_is_refused_without_running_anything(tmp_path):
    sentinel = tmp_path / "SENTINEL"
    crafted = hostile_pickles(str(sentinel))
    paths = []
    for name, raw in crafted.items():
        paths.append(tmp_path / f"{name}.pkl")
        paths[-1].write_bytes(raw)
    outcomes = run_reader_batch(LOAD_MOTION, paths, sentinel=sentinel, warnings_as_errors=True)
    assert all(o.kind == REFUSED for o in outcomes), _report(outcomes)
    by_name = dict(zip(crafted, outcomes, strict=True))
    # Each is refused by the check made for it, not by an accident further on.
    assert "nest deeper" in by_name["deep_memo_chain"].detail  # found after loading
    assert "contains itself" in by_name["cycle"].detail
    assert "allocates memory" in by_name["ndarray_call_80gb"].detail
    assert "memo index" in by_name["memo_index_4g"].detail
    assert "which could run code" in by_name["object_array_payload"].detail
    assert not sentinel.exists()


def test_dtype_flags_in_the_file_are_ignored(tmp_path):
    # An f8 dtype whose pickled state claims object flags is rebuilt from "f8" alone.
    from quaddance.choreo.safe_pickle import safe_load_pickle

    path = tmp_path / "flags.pkl"
    path.write_bytes(object_array_pickle("f8", flags=63, pointers=(0, 1, 2, 3)))
    array = safe_load_pickle(path)["full_pose"]
    assert array.dtype == np.float64 and array.dtype.flags == np.dtype("f8").flags
    assert array.view(np.uint64).tolist() == [0, 1, 2, 3]


def _edge(n_frames: int = 60, **extra: object) -> dict[str, object]:
    return {"smpl_poses": np.zeros((n_frames, 72)), "smpl_trans": np.zeros((n_frames, 3)), **extra}


def _bvh(frames: str = "48", frame_time: str = "0.0416667", channels: str = "3") -> str:
    text = valid_bvh_texts(np.random.default_rng(0))[0]
    text = text.replace("Frames: 48", f"Frames: {frames}").replace(
        "Frame Time: 0.041666666666666664", f"Frame Time: {frame_time}"
    )
    return text.replace("CHANNELS 3 Zrotation", f"CHANNELS {channels} Zrotation", 1)


# (file name, content, what the one-line error must say): every number read is checked.
_HOSTILE_NUMBERS: list[tuple[str, object, str]] = [
    ("fps_hugeint.pkl", _edge(fps=2**63), "'fps' is 9.22337e+18, expected 1 to 1000"),
    ("fps_denormal.pkl", _edge(fps=1e-320), "'fps' is 9.99989e-321"),
    ("fps_text.pkl", _edge(fps="30"), "'fps' must be one number"),
    ("fps_bool.pkl", _edge(fps=True), "'fps' must be one number"),
    ("fps_nan.pkl", _edge(fps=float("nan")), "'fps' is nan"),
    ("scaling_denormal.pkl", _edge(smpl_scaling=1e-320), "'smpl_scaling' is 9.99989e-321"),
    ("scaling_inf.pkl", _edge(smpl_scaling=np.array([np.inf])), "'smpl_scaling' is inf"),
    (
        "trans_1e308.pkl",
        {**_edge(), "smpl_trans": np.full((60, 3), 1e308)},
        "'smpl_trans' has values up to 1e+308",
    ),
    ("pose_1e300.pkl", {**_edge(), "smpl_poses": np.full((60, 72), 1e300)}, "'smpl_poses'"),
    ("full_pose_list.pkl", {"full_pose": [[[1e308] * 3] * 24] * 60}, "'full_pose' has values"),
    ("full_pose_bool.pkl", {"full_pose": np.ones((60, 24, 3), bool)}, "not real numbers"),
    ("complex.pkl", {"full_pose": np.zeros((60, 24, 3), complex)}, "not a real number"),
    ("list_of_text.pkl", {"full_pose": [["1.5"] * 3] * 24}, "not a numeric array"),
    (
        "too_long.pkl",
        {"full_pose": np.zeros((30 * 1201, 24, 3), np.float32)},
        "motion is too long: 36030 frames at 30 fps = 1201 s",
    ),
    ("many_keys.pkl", {f"key{i:06d}" * 50: 0 for i in range(20_000)}, "keys found: key000000"),
    ("frame_time_denormal.bvh", _bvh(frame_time="1e-320"), "Frame Time 9.99989e-321 s"),
    ("frame_time_huge.bvh", _bvh(frame_time="1e300"), "Frame Time 1e+300 s is out of range"),
    ("frame_time_nan.bvh", _bvh(frame_time="nan"), "Frame Time 'nan' is not a number"),
    ("frames_billions.bvh", _bvh(frames="999999999999"), "longer than the 1200 s allowed"),
    ("frames_arabic.bvh", _bvh(frames="\u0664\u0668"), "is not a count"),
    ("channels_arabic.bvh", _bvh(channels="\u0663"), "CHANNELS count '\u0663' is not a number"),
    ("channels_superscript.bvh", _bvh(channels="\u00b3"), "is not a number"),
    ("channels_many.bvh", _bvh(channels="4000000000"), "more than 6"),
    ("too_long.bvh", _bvh(frames="28801", frame_time="0.0416667"), "longer than the 1200 s"),
    ("huge_value.bvh", _bvh().replace("100.0000", "1e300", 1), "value beyond +-1e+07"),
    ("arabic_value.bvh", _bvh().replace("100.0000", "\u0661\u0660\u0660", 1), "non-ASCII"),
    ("long_name.bvh", _bvh().replace("LeftFoot", "x" * 900_000), "joints: Hips"),
    # 2**60 numbers when expanded, from a 500-byte file of shared lists.
    ("shared_lists.pkl", shared_dag_pickle(60, 2), "'full_pose' is not a numeric array"),
    # Blank lines made the MOTION search quadratic: 300 000 of them hung for hours.
    ("blank_lines.bvh", "HIERARCHY\n" + "\n" * 300_000 + "x", "no MOTION block"),
    ("huge_hierarchy.bvh", "HIERARCHY\n" + "ab " * 400_000 + "\nMOTION\n", "longer than 1 MB"),
]


def test_hostile_numbers_are_refused_with_a_short_line_naming_the_field(tmp_path):
    paths = []
    for name, content, _ in _HOSTILE_NUMBERS:
        path = tmp_path / name
        if isinstance(content, str):
            path.write_text(content, encoding="utf-8")
        elif isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_bytes(pickle.dumps(content, protocol=4))
        paths.append(path)
    outcomes = run_reader_batch(LOAD_MOTION, paths, warnings_as_errors=True)
    for (name, _, problem), outcome in zip(_HOSTILE_NUMBERS, outcomes, strict=True):
        assert outcome.kind == REFUSED, (name, outcome)
        assert problem in outcome.detail, (name, outcome.detail)
        assert len(outcome.detail) < 400, (name, len(outcome.detail))  # never the file echoed


def test_valid_seeds_load(tmp_path):
    # The fuzz seeds are good files: the mutation fuzz starts from motions that load.
    rng = np.random.default_rng(1)
    paths = []
    for i, raw in enumerate(valid_motion_pickles(rng)):
        paths.append(tmp_path / f"seed{i}.pkl")
        paths[-1].write_bytes(raw)
    for i, text in enumerate(valid_bvh_texts(rng)):
        paths.append(tmp_path / f"seed{i}.bvh")
        paths[-1].write_text(text)
    outcomes = run_reader_batch(LOAD_MOTION, paths, warnings_as_errors=True)
    assert {o.kind for o in outcomes} == {"ok"}, _report(outcomes)


# ---------------------------------------------------------------------------------------------
# mutation fuzz: thousands of damaged EDGE / AIST++ pickles and BVH files, one child


def test_mutated_motion_files_never_crash_trace_back_or_run_code(tmp_path):
    rng = np.random.default_rng(20261201)
    sentinel = tmp_path / "SENTINEL"
    hostile = hostile_pickles(str(sentinel))
    small_hostile = [raw for raw in hostile.values() if len(raw) < 10_000]
    corpus = valid_motion_pickles(rng) + small_hostile
    bvh_corpus = valid_bvh_texts(rng)
    paths = []
    for i in range(2400):
        raw = mutate_bytes(corpus[i % len(corpus)], rng, corpus)
        paths.append(tmp_path / f"m{i}.pkl")
        paths[-1].write_bytes(raw)
    for i in range(600):
        text = mutate_text(bvh_corpus[i % len(bvh_corpus)], rng)
        paths.append(tmp_path / f"m{i}.bvh")
        paths[-1].write_text(text, encoding="utf-8")
    outcomes = run_reader_batch(LOAD_MOTION, paths, sentinel=sentinel, warnings_as_errors=True)
    counts = summarize(outcomes)
    assert set(counts) <= {"ok", REFUSED}, _report(outcomes)
    # The fuzz reaches past the first check: some damaged files still load.
    assert counts.get("ok", 0) >= 50, counts
    assert not sentinel.exists()


# ---------------------------------------------------------------------------------------------
# Hypothesis properties, each run whole in a child process

_SETTINGS = settings(
    max_examples=250,
    deadline=None,  # shared CPUs: time is a benchmark's business
    database=None,  # nothing written into the checkout
    derandomize=True,  # the same examples on every run: a failure reproduces
    suppress_health_check=list(HealthCheck),
)


def _check_motion_file(path: Path) -> None:
    """The property: a motion loads into finite heights, or is refused in one short line."""
    from quaddance.choreo.motion import MAX_FPS_HZ, MAX_MOTION_S, MIN_FPS_HZ, load_motion
    from quaddance.errors import InputFileError

    try:
        motion = load_motion(path)
    except InputFileError as err:
        message = str(err)
        assert "\n" not in message and len(message) < 500 and path.name in message, message
        return
    assert MIN_FPS_HZ <= motion.fps <= MAX_FPS_HZ
    assert motion.duration_s <= MAX_MOTION_S
    assert motion.feet_m.ndim == 2 and motion.feet_m.shape[1] == 2
    assert np.all(np.isfinite(motion.feet_m)) and np.all(motion.feet_m >= 0)


_NUMBER_TEXT = st.one_of(
    st.floats(-300, 300).map(lambda v: f"{v:.4f}"),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**30), 10**30).map(str),
    st.sampled_from(["1e-320", "5e-324", "1e308", "nan", "-inf", "\u0663", "\u00b3", "1_0", ""]),
)


@st.composite
def bvh_texts(draw: st.DrawFn) -> str:
    """BVH files of the two-leg skeleton with drawn numbers, counts and frame times: a
    well-formed file (so the numbers reach the code after the parser) or one broken in
    one to all of its parts."""
    # Which parts are hostile; 0 = none. Hypothesis favours small draws, so well-formed
    # files stay common.
    broken = draw(st.integers(0, 31))
    hierarchy = BVH_HIERARCHY
    if broken & 1:  # numbers in the skeleton
        for _ in range(draw(st.integers(1, 3))):
            hierarchy = hierarchy.replace("-45.0", draw(_NUMBER_TEXT), 1)
    if broken & 2:  # a channel count
        channels = draw(st.sampled_from(["0", "7", "99", "\u0663", "-3", "3.0", "x"]))
        hierarchy = hierarchy.replace("CHANNELS 3", f"CHANNELS {channels}", 1)
    n_frames = draw(st.integers(30, 150) if not broken & 4 else st.integers(0, 200))
    frames_text = str(n_frames)
    if broken & 4 and draw(st.booleans()):
        frames_text = draw(st.one_of(st.integers(0, 10**15).map(str), _NUMBER_TEXT))
    frame_time = draw(st.sampled_from(["0.0333333", "0.0416667", "0.008333", "0.01"]))
    if broken & 8:
        frame_time = draw(st.one_of(st.floats(1e-4, 2.0).map(repr), _NUMBER_TEXT))
    # Values from a drawn seed and scale (fast), then drawn tokens put in.
    per_line = BVH_CHANNELS + (draw(st.sampled_from([0, -1, 1])) if broken & 16 else 0)
    scale = draw(st.sampled_from([30.0, 0.0, 1.0, 180.0, 1e4, 1e8]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    rows = [[f"{v:.3f}" for v in row] for row in rng.normal(0, scale, (n_frames, per_line))]
    for _ in range(draw(st.integers(1, 5)) if broken & 16 and rows else 0):
        row, col = draw(st.integers(0, n_frames - 1)), draw(st.integers(0, per_line - 1))
        rows[row][col] = draw(_NUMBER_TEXT)
    head = f"{hierarchy}MOTION\nFrames: {frames_text}\nFrame Time: {frame_time}\n"
    return head + "\n".join(" ".join(row) for row in rows) + "\n"


def hypothesis_bvh(workdir: str, max_examples: int, derandomize: bool = True) -> None:
    """Property over drawn BVH files (run in a child by the test below)."""
    path = Path(workdir) / "case.bvh"

    @settings(_SETTINGS, max_examples=max_examples, derandomize=derandomize)
    @given(bvh_texts())
    def check(text: str) -> None:
        path.write_text(text, encoding="utf-8")
        _check_motion_file(path)

    check()


_FLOATS = st.floats(allow_nan=True, allow_infinity=True, width=64)
_SCALARS = st.one_of(
    st.integers(-(2**70), 2**70),
    _FLOATS,
    st.text(max_size=4),
    st.none(),
    st.booleans(),
    st.complex_numbers(max_magnitude=10),
)
_DTYPES = st.sampled_from(["f4", "f8", "f8", "f8", ">f8", "i4", "u1", "?", "c16", "U3", "f2"])


@st.composite
def motion_pickle_bytes(draw: st.DrawFn) -> bytes:
    """EDGE / AIST++ dicts with drawn shapes, dtypes, values and fields, at any protocol;
    sometimes with a few bytes overwritten."""
    n_frames = draw(st.integers(0, 80))
    dtype = draw(_DTYPES)
    elements = {
        "f8": st.one_of(st.floats(-3, 3), _FLOATS),
        ">f8": st.one_of(st.floats(-3, 3), _FLOATS),
        "f4": st.one_of(st.floats(-3, 3, width=32), st.floats(width=32)),
    }.get(dtype)

    def array(shape: tuple[int, ...]) -> st.SearchStrategy[np.ndarray]:
        return hnp.arrays(dtype, shape, elements=elements)

    kind = draw(st.sampled_from(["edge", "params", "aist"]))
    if kind == "edge":
        data: dict[str, object] = {"full_pose": draw(array((n_frames, 24, 3)))}
    else:
        width = draw(st.sampled_from([72, 72, 72, 69]))
        data = {
            "smpl_poses": draw(array((n_frames, width))),
            "smpl_trans": draw(array((n_frames, 3))),
        }
    if kind == "aist":
        data["smpl_scaling"] = draw(st.one_of(_SCALARS, hnp.arrays("f8", 1, elements=_FLOATS)))
    if draw(st.booleans()):
        data["fps"] = draw(_SCALARS)
    extra = st.recursive(_SCALARS, lambda inner: st.lists(inner, max_size=4), max_leaves=20)
    if draw(st.booleans()):
        data["extra"] = draw(extra)
    raw = bytearray(pickle.dumps(data, protocol=draw(st.integers(0, 5))))
    for _ in range(draw(st.sampled_from([0, 0, 0, 1, 2, 3]))):
        at = draw(st.integers(0, len(raw) - 1))
        raw[at : at + 1] = draw(st.binary(min_size=0, max_size=4))
    return bytes(raw)


def hypothesis_pickles(workdir: str, max_examples: int, derandomize: bool = True) -> None:
    """Property over drawn motion pickles and raw pickle-like bytes (run in a child)."""
    path = Path(workdir) / "case.pkl"

    @settings(_SETTINGS, max_examples=max_examples, derandomize=derandomize)
    @given(
        st.one_of(
            motion_pickle_bytes(),
            st.binary(max_size=200).map(lambda b: b"\x80\x04" + b),
        )
    )
    def check(raw: bytes) -> None:
        path.write_bytes(raw)
        _check_motion_file(path)

    check()


@pytest.mark.parametrize("prop", ["hypothesis_bvh", "hypothesis_pickles"])
def test_hypothesis_properties_hold_in_a_child_process(tmp_path, prop):
    outcome = run_call(f"test_fuzz_motion:{prop}", str(tmp_path), 250, timeout_s=240)
    # A crash leaves the case that caused it in tmp_path (case.bvh / case.pkl).
    assert outcome.kind == "ok", f"{outcome.kind}: {outcome.detail}"
