"""Fuzzing the audio decoder, the dance.npz reader and the policy JSON reader (issue 12).

Every reader call runs in a child process under a memory limit and a timeout
(`fuzz_harness`): a crash, a blow-up or a hang fails the test instead of the run. The promise
checked: a file either loads into values that pass the property checks of
`input_fuzz_cases` (finite, in range, consistent shapes; a policy round-trips), or is refused
with one short line naming the file; never a traceback.
"""

from __future__ import annotations

import json
import os
import socket
from pathlib import Path

import numpy as np
import pytest
from fuzz_harness import REFUSED, Outcome, run_call, run_reader_batch, summarize
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from input_fuzz_cases import (
    HOSTILE_FLOATS,
    WAV_FIELDS,
    audio_seeds,
    dance_arrays,
    mutate_audio,
    mutate_dance,
    mutate_policy,
    shipped_policy,
    wav_with_header,
)

AUDIO = "input_fuzz_cases:load_audio_checked"
DANCE = "input_fuzz_cases:load_dance_checked"
POLICY = "input_fuzz_cases:load_policy_json"


def _report(outcomes: list[Outcome]) -> str:
    bad = [o for o in outcomes if not o.clean]
    lines = [f"{summarize(outcomes)}"] + [f"#{o.index} {o.kind}: {o.detail[:600]}" for o in bad]
    return "\n".join(lines[:12])


def _fuzz(
    reader: str, seeds: list[tuple[str, bytes | str]], cases: list, folder: Path
) -> dict[str, int]:
    """Run ``reader`` over the valid ``seeds`` (each must load) and the damaged ``cases``
    (each must load or be refused) in one child; counts of the cases' outcomes."""
    paths = []
    for i, (suffix, content) in enumerate([*seeds, *cases]):
        paths.append(folder / f"case{i}{suffix}")
        if isinstance(content, str):
            paths[-1].write_text(content, encoding="utf-8", errors="surrogatepass")
        else:
            paths[-1].write_bytes(content)
    outcomes = run_reader_batch(reader, paths)
    assert {o.kind for o in outcomes[: len(seeds)]} == {"ok"}, _report(outcomes[: len(seeds)])
    counts = summarize(outcomes[len(seeds) :])
    assert set(counts) <= {"ok", REFUSED}, _report(outcomes)
    return counts


# --- mutation fuzz: damaged copies of valid files ---------------------------------------------


def test_mutated_audio_files(tmp_path):
    rng = np.random.default_rng(20261201)
    seeds = audio_seeds(rng)
    cases = [mutate_audio(seeds, rng) for _ in range(300)]
    counts = _fuzz(AUDIO, seeds, cases, tmp_path)
    assert counts.get("ok", 0) >= 30 and counts.get(REFUSED, 0) >= 100, counts


def test_mutated_dance_files(tmp_path):
    rng = np.random.default_rng(20261202)
    seed = tmp_path / "seed.npz"
    np.savez(seed, **dance_arrays())
    cases = [(".npz", mutate_dance(rng)) for _ in range(400)]
    counts = _fuzz(DANCE, [(".npz", seed.read_bytes())], cases, tmp_path)
    assert counts.get("ok", 0) >= 20 and counts.get(REFUSED, 0) >= 200, counts


def test_mutated_policy_json(tmp_path):
    rng = np.random.default_rng(20261203)
    base = shipped_policy()
    cases = [(".json", mutate_policy(base, rng)) for _ in range(400)]
    counts = _fuzz(POLICY, [(".json", json.dumps(base))], cases, tmp_path)
    assert counts.get("ok", 0) >= 10 and counts.get(REFUSED, 0) >= 300, counts


# --- Hypothesis properties, each run whole in a child process ---------------------------------

_SETTINGS = settings(
    max_examples=150,
    deadline=None,  # shared CPUs: time is a benchmark's business
    database=None,  # nothing written into the checkout
    derandomize=True,  # the same examples on every run: a failure reproduces
    suppress_health_check=list(HealthCheck),
)


def _refused_or_checked(check, path: Path) -> None:
    from quaddance.errors import InputFileError

    try:
        check(str(path))
    except InputFileError as err:
        message = str(err)
        assert "\n" not in message and len(message) < 500 and path.name in message, message


@st.composite
def wav_files(draw: st.DrawFn) -> bytes:
    """WAVs with drawn header numbers, sample values and lengths."""
    seconds = draw(st.sampled_from([0.0, 0.5, 2.5]))
    channels = draw(st.integers(1, 3))
    values = hnp.arrays(
        np.float64,
        (int(seconds * 8000), channels),
        elements=st.one_of(st.floats(-1, 1), st.sampled_from(HOSTILE_FLOATS)),
        fill=st.floats(-1, 1),
    )
    samples = draw(values)
    subtype = draw(st.sampled_from(["PCM_16", "PCM_U8", "FLOAT", "DOUBLE"]))
    if subtype == "FLOAT":
        with np.errstate(over="ignore"):
            samples = samples.astype(np.float32)
    elif subtype.startswith("PCM"):
        samples = np.nan_to_num(np.clip(samples, -1, 1))
    names = draw(st.lists(st.sampled_from(list(WAV_FIELDS)), max_size=3, unique=True))
    fields = {name: draw(st.integers(0, 2**32 - 1)) for name in names}
    data_size = draw(st.none() | st.integers(0, 2**32 - 1))
    return wav_with_header(samples, subtype, fields, data_size)


def hypothesis_audio(workdir: str, max_examples: int) -> None:
    """Property over drawn WAV files (run in a child by the test below)."""
    from input_fuzz_cases import load_audio_checked

    path = Path(workdir) / "case.wav"

    @settings(_SETTINGS, max_examples=max_examples)
    @given(wav_files())
    def check(raw: bytes) -> None:
        path.write_bytes(raw)
        _refused_or_checked(load_audio_checked, path)

    check()


_ARRAYS = hnp.arrays(
    st.sampled_from(["f8", "f4", "i4", "u1", "?", "c8", "U4"]).map(np.dtype),
    hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=6),
)


def hypothesis_dance(workdir: str, max_examples: int) -> None:
    """Property over dance.npz files with drawn arrays in place of the real ones."""
    from input_fuzz_cases import load_dance_checked

    path = Path(workdir) / "case.npz"

    @settings(_SETTINGS, max_examples=max_examples)
    @given(
        st.dictionaries(st.sampled_from(list(dance_arrays())), _ARRAYS, max_size=3),
        st.sets(st.sampled_from(list(dance_arrays())), max_size=2),
        st.sampled_from([1, 2, 150]),
    )
    def check(replaced: dict, deleted: set, n: int) -> None:
        arrays = {**dance_arrays(n), **replaced}
        for key in deleted:
            arrays.pop(key, None)
        np.savez(path, **arrays)
        _refused_or_checked(load_dance_checked, path)

    check()


_JSON = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**70), 2**70)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4)
    ),
    max_leaves=12,
)


def hypothesis_policy(workdir: str, max_examples: int) -> None:
    """Property over policy JSONs with drawn values at drawn places of the shipped one."""
    from input_fuzz_cases import _paths, load_policy_json

    base = shipped_policy()
    paths = _paths(base)
    path = Path(workdir) / "case.json"

    @settings(_SETTINGS, max_examples=max_examples)
    @given(st.lists(st.tuples(st.sampled_from(paths), _JSON), min_size=1, max_size=3))
    def check(edits: list) -> None:
        obj = json.loads(json.dumps(base))
        for where, value in edits:
            parent = obj
            try:
                for key in where[:-1]:
                    parent = parent[key]
                parent[where[-1]] = value
            except (KeyError, IndexError, TypeError):
                pass
        path.write_text(json.dumps(obj))
        _refused_or_checked(load_policy_json, path)

    check()


@pytest.mark.parametrize("prop", ["hypothesis_audio", "hypothesis_dance", "hypothesis_policy"])
def test_hypothesis_properties_hold_in_a_child_process(tmp_path, prop):
    outcome = run_call(f"test_fuzz_inputs:{prop}", str(tmp_path), 150, timeout_s=240)
    # A failure leaves the case that caused it in tmp_path (case.wav / .npz / .json).
    assert outcome.kind == "ok", f"{outcome.kind}: {outcome.detail}"


# --- outputs: every writer refuses every path that is not a regular file -----------------------


def _writers(tmp_path: Path):
    from quaddance.dancefile import Dance, save_dance
    from quaddance.fileio import write_json
    from quaddance.music.synth import write_demo_song
    from quaddance.play.plots import plot_feet
    from quaddance.play.policy_spec import PolicySpec

    a = dance_arrays(10)
    dance = Dance(
        **{k: (v.item() if v.ndim == 0 and v.dtype.kind != "U" else v) for k, v in a.items()}
        | {"mode": "feasible", "source": "s", "version": "0"}
    )
    spec = PolicySpec.from_dict(shipped_policy())
    t, feet = a["time_s"], a["targets_m"]
    return {
        "write_json": lambda p: write_json(p, {"a": 1}),
        "save_dance": lambda p: save_dance(p, dance),
        "policy_json": spec.save,
        "plot_feet": lambda p: plot_feet(p, t, feet, feet, a["beats_s"]),
        "demo_song": write_demo_song,
    }


def test_every_writer_refuses_every_path_that_is_not_a_regular_file(tmp_path):
    from quaddance.errors import OutputFileError

    nodes = tmp_path / "nodes"
    nodes.mkdir()
    (nodes / "folder").mkdir()
    os.mkfifo(nodes / "fifo")
    (nodes / "file").write_text("x")
    (nodes / "to_null").symlink_to("/dev/null")
    (nodes / "broken").symlink_to(nodes / "absent" / "x")
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(nodes / "sock"))
    suffix = {"demo_song": ".wav", "plot_feet": ".png", "save_dance": ".npz"}
    try:
        for name, write in _writers(tmp_path).items():
            ext = suffix.get(name, ".json")
            for node in ("folder", "fifo", "to_null", "broken", "sock"):
                with pytest.raises(OutputFileError, match=node):
                    write(nodes / node)
            with pytest.raises(OutputFileError, match="is a file, not a folder"):
                write(nodes / "file" / f"out{ext}")
            write(tmp_path / f"ok{ext}")  # and a regular path works
            assert (tmp_path / f"ok{ext}").stat().st_size > 0
    finally:
        sock.close()
    assert (nodes / "fifo").is_fifo() and os.readlink(nodes / "to_null") == "/dev/null"
    assert not [p for p in tmp_path.rglob("*") if ".tmp" in p.name]
