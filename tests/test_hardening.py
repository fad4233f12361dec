"""Hostile input (issue 12): audio headers and samples, output paths, signals, arguments.

Each bad input must end as one `QuaddanceError` naming the file (the CLI prints it as one
line, exit 2) or as a usage error (exit 2); never a traceback, never a write over something
that is not a regular file.
"""

from __future__ import annotations

import os
import random
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
import typer
from typer.testing import CliRunner

from quaddance import fileio
from quaddance.cli import EXIT_SIGINT, EXIT_SIGTERM, app, one_line_error
from quaddance.errors import InputFileError, OutputFileError
from quaddance.music import audio
from quaddance.music.audio import MAX_SONG_S, load_audio

SR = 22050


def _tone(seconds: float, sr: int = SR, peak: float = 0.5) -> np.ndarray:
    t = np.arange(int(seconds * sr)) / sr
    return (peak * np.sin(2 * np.pi * 220.0 * t)).astype(np.float32)


def _wav_bytes(y: np.ndarray, sr: int = SR, subtype: str = "FLOAT") -> bytearray:
    import io

    buf = io.BytesIO()
    sf.write(buf, y, sr, format="WAV", subtype=subtype)
    return bytearray(buf.getvalue())


# --- audio: header numbers ----------------------------------------------------------------------


# Offsets in a canonical WAV header: channels at 22 (u16), sample rate at 24 (u32).
@pytest.mark.parametrize(
    ("offset", "fmt", "value"),
    [(24, "<I", 0), (24, "<I", 1), (24, "<I", 3999), (24, "<I", 4_000_000_000),
     (22, "<H", 0), (22, "<H", 1000)],
)  # fmt: skip
def test_wav_header_numbers_out_of_range_are_refused(tmp_path, offset, fmt, value) -> None:
    data = _wav_bytes(_tone(3.0), subtype="PCM_16")
    struct.pack_into(fmt, data, offset, value)
    path = tmp_path / "bad_header.wav"
    path.write_bytes(bytes(data))
    with pytest.raises(InputFileError, match=r"bad_header.wav"):
        load_audio(path)


def test_a_low_but_valid_sample_rate_is_resampled(tmp_path) -> None:
    path = tmp_path / "phone.wav"
    sf.write(path, _tone(3.0, sr=8000), 8000)
    y, sr = load_audio(path)
    assert sr == SR and abs(y.size - 3 * SR) <= 0.01 * SR


def test_too_long_song_is_refused_from_the_header_before_decoding(tmp_path, monkeypatch) -> None:
    # 8-bit mono at the lowest accepted rate: a 21-minute song in 5 MB.
    seconds = MAX_SONG_S + 60
    path = tmp_path / "long.wav"
    quiet = np.zeros(int(seconds * audio.MIN_FILE_SR_HZ), dtype=np.float32)
    sf.write(path, quiet, audio.MIN_FILE_SR_HZ, subtype="PCM_U8")

    def no_decoding(path):
        raise AssertionError("decoding started")

    monkeypatch.setattr(audio, "_soundfile_blocks", no_decoding)
    with pytest.raises(InputFileError, match=r"long.wav: is too long: 21.0 min .* at most 20 min"):
        load_audio(path)


def test_decoding_stops_at_the_limit_when_the_header_gave_no_length(tmp_path) -> None:
    consumed = []

    def endless():  # a stream whose header said nothing about its length
        while True:
            consumed.append(1)
            yield np.full((4000, 2), 0.1, dtype=np.float32)

    with pytest.raises(InputFileError, match="too long"):
        audio._decode(tmp_path / "x.mp3", endless(), 4000, SR, 2.0, max_duration_s=10.0)
    assert len(consumed) == 11  # 11 one-second blocks pass 10 s


@pytest.mark.parametrize(
    ("value", "words"),
    [(np.nan, "NaN"), (np.inf, "infinity"), (-np.inf, "infinity"), (1e30, "beyond full scale")],
)
def test_bad_float_samples_are_refused(tmp_path, value, words) -> None:
    y = _tone(3.0)
    y[SR] = value
    path = tmp_path / "float.wav"
    path.write_bytes(bytes(_wav_bytes(y)))
    with pytest.raises(InputFileError, match=f"float.wav: .*{words}"):
        load_audio(path)


def test_float_master_past_full_scale_is_normalised(tmp_path) -> None:
    path = tmp_path / "hot.wav"
    sf.write(path, np.stack([_tone(3.0, peak=4.0), _tone(3.0, peak=2.0)], axis=1), SR,
             subtype="FLOAT")  # fmt: skip
    y, _ = load_audio(path)
    assert np.all(np.isfinite(y))
    assert np.max(np.abs(y)) == pytest.approx(1.0)  # the mono mix, peak 3, scaled to 1


def test_audioread_fallback_checks_its_header(tmp_path, monkeypatch) -> None:
    import audioread

    class FakeReader:
        def __init__(self, samplerate: int) -> None:
            self.samplerate, self.channels, self.duration = samplerate, 2, 3.0

        def __iter__(self):
            pcm = (np.tile(_tone(3.0, sr=8000)[:, None], (1, 2)) * 32767).astype("<i2")
            raw = pcm.tobytes()
            yield from (raw[i : i + 4001] for i in range(0, len(raw), 4001))  # odd cuts

        def close(self) -> None:
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc) -> None:
            pass

    path = tmp_path / "song.mp3"
    path.write_bytes(b"not something libsndfile reads" * 10)
    monkeypatch.setattr(audioread, "audio_open", lambda p: FakeReader(0))
    with pytest.raises(InputFileError, match=r"song.mp3: sample rate 0 Hz"):
        load_audio(path)
    monkeypatch.setattr(audioread, "audio_open", lambda p: FakeReader(8000))
    y, sr = load_audio(path)
    assert sr == SR and abs(y.size - 3 * SR) <= 0.01 * SR and 0.45 < np.max(np.abs(y)) < 0.55


# --- outputs ------------------------------------------------------------------------------------


def _write_through(path: Path, text: str = "new") -> None:
    with fileio.atomic_path(path) as tmp:
        tmp.write_text(text)


def test_fifo_is_refused_and_left_alone(tmp_path) -> None:
    fifo = tmp_path / "out.json"
    os.mkfifo(fifo)
    with pytest.raises(OutputFileError, match=r"out.json: exists and is a FIFO"):
        _write_through(fifo)
    assert fifo.is_fifo()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]  # no temporary left


def test_symlink_to_a_device_is_refused(tmp_path) -> None:
    link = tmp_path / "dance.npz"
    link.symlink_to("/dev/null")
    with pytest.raises(OutputFileError, match=r"dance.npz: exists and is a character device"):
        _write_through(link)
    assert link.is_symlink() and os.readlink(link) == "/dev/null"


def test_socket_and_broken_link_are_refused(tmp_path) -> None:
    sock_path = tmp_path / "s.json"
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(str(sock_path))
        with pytest.raises(OutputFileError, match="a socket"):
            _write_through(sock_path)
    broken = tmp_path / "b.json"
    broken.symlink_to(tmp_path / "absent" / "x.json")
    with pytest.raises(OutputFileError, match="broken symbolic link"):
        _write_through(broken)


def test_symlink_to_a_regular_file_is_written_through(tmp_path) -> None:
    target = tmp_path / "real.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    _write_through(link, "new")
    assert link.is_symlink() and target.read_text() == "new"


def test_folder_and_file_in_the_wrong_place_are_refused(tmp_path) -> None:
    (tmp_path / "adir").mkdir()
    with pytest.raises(OutputFileError, match="adir: exists and is a folder"):
        _write_through(tmp_path / "adir")
    (tmp_path / "afile").write_text("x")
    with pytest.raises(OutputFileError, match="afile: exists and is a file, not a folder"):
        fileio.ensure_dir(tmp_path / "afile")
    with pytest.raises(OutputFileError, match="is a file, not a folder"):
        _write_through(tmp_path / "afile" / "sub" / "x.json")
    with pytest.raises(OutputFileError, match="is a file, not a folder"):
        fileio.ensure_dir(tmp_path / "afile" / "sub")
    assert fileio.ensure_dir(tmp_path / "new" / "sub").is_dir()


@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), KeyboardInterrupt()])
def test_failed_or_interrupted_write_keeps_the_old_file(tmp_path, error) -> None:
    path = tmp_path / "metrics.json"
    path.write_text("old")
    expected = OutputFileError if isinstance(error, OSError) else KeyboardInterrupt
    with pytest.raises(expected), fileio.atomic_path(path) as tmp:
        tmp.write_text("half")
        raise error
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["metrics.json"]


def test_cli_refuses_output_paths_before_the_work(tmp_path) -> None:
    runner = CliRunner()
    song = tmp_path / "song.wav"
    sf.write(song, _tone(3.0), SR)
    (tmp_path / "afile").write_text("x")
    os.mkfifo(tmp_path / "fifo.npz")
    cases = [
        (["dance", str(song), "--no-video", "--out", str(tmp_path / "afile")], "afile"),
        (["choreograph", str(song), "-o", str(tmp_path)], tmp_path.name),
        (["choreograph", str(song), "-o", str(tmp_path / "fifo.npz")], "fifo.npz"),
        (["analyze", str(song), "-o", str(tmp_path / "afile" / "a.json")], "afile"),
    ]
    for args, name in cases:
        result = runner.invoke(app, args)
        assert isinstance(result.exception, OutputFileError), (args, result.output)
        assert name in str(result.exception)
    assert (tmp_path / "fifo.npz").is_fifo() and (tmp_path / "afile").read_text() == "x"


def test_an_output_never_replaces_an_input_or_another_output(tmp_path) -> None:
    runner = CliRunner()
    song = tmp_path / "song.wav"
    sf.write(song, _tone(3.0), SR)
    before = song.read_bytes()
    (tmp_path / "link.wav").symlink_to(song)
    beats = tmp_path / "beats.txt"
    beats.write_text("0.5\n1.0\n1.5\n2.0\n")
    moves = tmp_path / "moves.toml"
    moves.write_text("[styles.calmer]\nhold = 2.0\n")
    cases = [
        (["analyze", str(song), "-o", str(song)], "is also the input (SONG)"),
        (["analyze", str(song), "--click", str(tmp_path / "link.wav")], "input (SONG)"),
        (
            [
                "analyze",
                str(song),
                "-o",
                str(tmp_path / "x.wav"),
                "--click",
                str(tmp_path / "x.wav"),
            ],
            "is given for both --out and --click",
        ),
        (["choreograph", str(song), "-o", str(song)], "input (SONG); writing --out"),
        (["choreograph", str(song), "--beats", str(beats), "-o", str(beats)], "input (--beats)"),
        (["choreograph", str(song), "--moves", str(moves), "-o", str(moves)], "input (--moves)"),
    ]
    for args, words in cases:
        result = runner.invoke(app, args)
        assert isinstance(result.exception, OutputFileError), (args, result.output)
        assert words in str(result.exception), str(result.exception)
    assert song.read_bytes() == before and beats.read_text().startswith("0.5")
    assert moves.read_text().startswith("[styles.calmer]")
    names = ["beats.txt", "link.wav", "moves.toml", "song.wav"]
    assert sorted(p.name for p in tmp_path.iterdir()) == names


def test_an_unwritable_folder_is_refused_before_any_output(tmp_path, monkeypatch) -> None:
    """`analyze -o OUT --click CLICK` where CLICK's folder cannot be written: nothing is
    written, not OUT either. (Root may write anywhere, so the folder's refusal is simulated.)"""
    song = tmp_path / "song.wav"
    sf.write(song, _tone(3.0), SR)
    locked = tmp_path / "locked"
    locked.mkdir()
    real_access = os.access
    monkeypatch.setattr(
        fileio.os, "access", lambda p, mode: Path(p) != locked and real_access(p, mode)
    )
    out = tmp_path / "a.json"
    result = CliRunner().invoke(
        app, ["analyze", str(song), "-o", str(out), "--click", str(locked / "c.wav")]
    )
    assert isinstance(result.exception, OutputFileError), result.output
    assert str(result.exception) == f"{locked / 'c.wav'}: cannot write in the folder {locked}"
    assert not out.exists() and list(locked.iterdir()) == []


def test_a_folder_given_as_an_input_file_is_called_a_folder(tmp_path) -> None:
    folder = tmp_path / "song.wav"
    folder.mkdir()
    song = tmp_path / "real.wav"
    sf.write(song, _tone(3.0), SR)
    cases = [
        ["dance", str(folder), "--no-video", "--out", str(tmp_path / "o")],
        ["choreograph", str(folder), "-o", str(tmp_path / "d.npz")],
        ["choreograph", str(song), "--moves", str(folder), "-o", str(tmp_path / "d.npz")],
        ["choreograph", str(song), "--beats", str(folder), "-o", str(tmp_path / "d.npz")],
        ["dance", "--policy", str(folder), str(song), "--out", str(tmp_path / "o")],
    ]
    for args in cases:
        result = CliRunner().invoke(app, args)
        assert isinstance(result.exception, InputFileError), (args, result.output)
        assert str(result.exception) == f"{folder}: is a folder, not a file", args
    assert sorted(p.name for p in tmp_path.iterdir()) == ["real.wav", "song.wav"]


def test_a_refused_dance_leaves_no_empty_output_folder(tmp_path) -> None:
    song = tmp_path / "silent.wav"
    sf.write(song, np.zeros(3 * SR, dtype=np.float32), SR)
    kept = tmp_path / "kept"
    kept.mkdir()
    for out in (tmp_path / "new", kept):
        result = CliRunner().invoke(app, ["dance", str(song), "--no-video", "--out", str(out)])
        assert isinstance(result.exception, InputFileError), result.output
        assert "silent" in str(result.exception)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept", "silent.wav"]


def test_error_line_is_one_short_line() -> None:
    line = one_line_error(InputFileError("f.wav", "bad\nvalue " + "x" * 5000))
    assert "\n" not in line and len(line) <= 400 and line.startswith("quaddance: error: f.wav")


# --- Ctrl-C and SIGTERM -------------------------------------------------------------------------


def _interrupt(
    args: list[str], sig: int, delay_s: float, wait_for: str | None = None, group: bool = False
):
    """Run ``quaddance ARGS``, send ``sig`` ``delay_s`` after it starts (or after it prints
    ``wait_for`` on stderr); return (returncode, stderr). ``group``: to its whole process
    group, helpers included, as Ctrl-C in a terminal does."""
    cmd = [sys.executable, "-c", "from quaddance.cli import main; main()", *args]
    env = {**os.environ, "COLUMNS": "200"}
    proc = subprocess.Popen(
        cmd,
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        env=env,
        start_new_session=group,
    )
    err = b""
    if wait_for is not None:
        while wait_for.encode() not in err:
            line = proc.stderr.readline()
            if not line:
                break
            err += line
    time.sleep(delay_s)
    if group:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    _, rest = proc.communicate(timeout=120)
    return proc.returncode, (err + rest).decode(errors="replace")


def _check_interrupted(returncode: int, stderr: str, sig: int, folder: Path) -> None:
    expected = EXIT_SIGTERM if sig == signal.SIGTERM else EXIT_SIGINT
    # Words with a slash are the output paths it lists, and pytest's folder names say
    # "interrupted" too: look at the other words only.
    words = [" ".join(w for w in line.split() if "/" not in w) for line in stderr.splitlines()]
    lines = [line for line in words if "interrupted" in line or "rror" in line]
    if returncode == 0:  # it finished before the signal came: complete outputs
        assert lines == [], stderr
    else:
        assert returncode == expected and lines == ["quaddance: interrupted"], stderr
    assert "Traceback" not in stderr
    assert not [p for p in folder.rglob("*") if ".tmp" in p.name], "temporary file left"


_SIGNAL_IN_A_CTYPES_CALLBACK = """
import ctypes, os, signal, sys, time
from quaddance.cli import main
import quaddance.cli as cli

def work():
    # qsort calls this comparator from C: the signal's handler runs inside a ctypes callback.
    @ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)
    def compare(a, b):
        os.kill(os.getpid(), SIGNUM)
        for _ in range(1000):
            pass
        return 0
    class Number:  # ctypes converts it by calling from_param, in Python
        @classmethod
        def from_param(cls, value):
            os.kill(os.getpid(), SIGNUM)
            for _ in range(1000):
                pass
            return ctypes.c_int(value)

    libc = ctypes.CDLL(None)
    if MODE == "callback":
        items = (ctypes.c_int * 2)(2, 1)
        libc.qsort(items, 2, ctypes.sizeof(ctypes.c_int), compare)
    else:  # ctypes wraps the KeyboardInterrupt in an ArgumentError
        libc.abs.argtypes = [Number]
        libc.abs(-3)
    time.sleep(5.0)  # the work goes on: the interrupt must still stop it
    print("not interrupted")

cli.app = work
main()
"""


@pytest.mark.parametrize("mode", ["callback", "argument"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_inside_a_ctypes_callback_still_stops_the_command_in_one_line(sig, mode):
    """Seen in `choreograph` and `dance`: Ctrl-C landed while numba loaded its LLVM cache (a
    ctypes callback), where the KeyboardInterrupt could only be printed, with a traceback,
    and dropped; or while PyOpenGL converted a ctypes argument, where it became an
    ArgumentError with a traceback."""
    code = _SIGNAL_IN_A_CTYPES_CALLBACK.replace("SIGNUM", str(int(sig)))
    code = code.replace("MODE", repr(mode))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    expected = EXIT_SIGTERM if sig == signal.SIGTERM else EXIT_SIGINT
    assert proc.returncode == expected, proc.stderr
    assert proc.stderr.strip() == "quaddance: interrupted"
    assert "not interrupted" not in proc.stdout


_SIGNAL_DURING_AN_IMPORT = """
import os, sys, tempfile, time
from pathlib import Path
import quaddance.cli as cli
from quaddance.cli import main

folder = tempfile.mkdtemp()
Path(folder, "slow_extension.py").write_text(
    "import os, time\\n"
    "os.kill(os.getpid(), SIGNUM)\\n"
    "time.sleep(0.3)\\n"
    "print('imported', flush=True)\\n"
)
sys.path.insert(0, folder)

def work():
    import slow_extension  # noqa: F401
    time.sleep(5.0)  # the work goes on: the interrupt must still stop it
    print("not interrupted")

cli.app = work
main()
"""


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_an_import_stops_the_command_once_the_import_is_done(sig):
    """Seen once in `dance` (Ctrl-C 1 s in): the KeyboardInterrupt raised while torch imported
    torch.distributed, inside its pybind11 initialisation, which cannot pass it on, and the
    process aborted with a C++ message. A signal inside an import now waits for its end."""
    code = _SIGNAL_DURING_AN_IMPORT.replace("SIGNUM", str(int(sig)))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    expected = EXIT_SIGTERM if sig == signal.SIGTERM else EXIT_SIGINT
    assert proc.returncode == expected, proc.stderr
    assert proc.stderr.strip() == "quaddance: interrupted"
    assert proc.stdout.split() == ["imported"]


def test_commands_do_not_load_glfw():
    """Without a MUJOCO_GL, MuJoCo's import loads GLFW, and GLFW's import runs a Python
    subprocess: a Ctrl-C in the first second of `dance` printed its traceback (1 in 40 tries
    at 0.45-0.6 s). Commands render only in EGL worker processes, so they turn GL off for
    themselves."""
    code = (
        "import sys\nimport quaddance.cli as cli\n"
        "def work():\n    import mujoco\n    print('glfw' in sys.modules)\n"
        "cli.app = work\ncli.main()\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "False"


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_interrupted_choreograph_leaves_a_complete_dance_or_none(tmp_path, demo_song, sig):
    from quaddance.dancefile import load_dance

    rng = random.Random(f"choreograph-{sig}")  # a random but repeatable moment
    out = tmp_path / "dance.npz"
    code, stderr = _interrupt(
        ["choreograph", str(demo_song[0]), "-o", str(out)], sig, rng.uniform(1.5, 5.0)
    )
    _check_interrupted(code, stderr, sig, tmp_path)
    if out.exists():
        load_dance(out)


@pytest.mark.parametrize("delay_s", [1.0, 2.5])
def test_ctrl_c_to_the_process_group_while_the_helpers_work(tmp_path, demo_song, delay_s):
    """A terminal's Ctrl-C reaches `dance`'s helper processes too (the song's analysis, the
    render workers): one line, exit 130, no traceback from any of them."""
    args = ["dance", str(demo_song[0]), "--out", str(tmp_path / "out")]
    code, stderr = _interrupt(args, signal.SIGINT, delay_s, group=True)
    _check_interrupted(code, stderr, signal.SIGINT, tmp_path)
    assert code == EXIT_SIGINT  # the 30 s song takes longer than this


def test_interrupted_dance_leaves_complete_outputs(tmp_path) -> None:
    from quaddance.dancefile import load_dance
    from quaddance.music.synth import render_song

    # A 30 s song's simulation can end within a second on a fast machine: 150 s of music
    # keep the signal inside the simulation.
    y, _ = render_song(120.0, 150.0, seed=3)
    song = tmp_path / "long_song.wav"
    sf.write(str(song), y, 22050)
    out = tmp_path / "out"
    args = ["dance", str(song), "--no-video", "--out", str(out)]
    delay_s = random.Random("dance").uniform(0.0, 1.0)
    code, stderr = _interrupt(args, signal.SIGTERM, delay_s, wait_for="dancing (simulation)")
    _check_interrupted(code, stderr, signal.SIGTERM, tmp_path)
    assert code == EXIT_SIGTERM, "the signal should land during the simulation"
    load_dance(out / "dance.npz")  # written before the simulation, complete
    assert not (out / "metrics.json").exists()


# --- arguments ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["choreograph", "s.wav", "--seed", "12345678901234567890"], "--seed"),
        (["choreograph", "s.wav", "--seed", "-1"], "--seed"),
        (["choreograph", "s.wav", "--h0", "nan"], "--h0"),
        (["choreograph", "s.wav", "--scale", "inf"], "--scale"),
        (["choreograph", "s.wav", "--max-height", "0"], "--max-height"),
        (["dance", "s.wav", "--seed", "99999999999999999999"], "--seed"),
        (["eval", "s.wav", "--seed", "99999999999"], "--seed"),
        (["train", "--num-envs", "0"], "--num-envs"),
        (["train", "--iterations", "0"], "--iterations"),
        (["train", "--minutes", "nan"], "--minutes"),
        (["train", "--max-height", "-inf"], "--max-height"),
        (["train", "--checkpoint-every", "1e400"], "--checkpoint-every"),
        (["train", "--bank-size", "0"], "--bank-size"),
        (["bench", "reach", "--height", "nan"], "--height"),
        (["bench", "reach", "--tolerance", "0"], "--tolerance"),
        (["bench", "choreograph", "--repeats", "0"], "--repeats"),
        (["bench", "train", "--num-envs", "-4"], "--num-envs"),
        (["deploy", "--seconds", "nan"], "--seconds"),
    ],
)
def test_out_of_range_options_are_usage_errors(args, option) -> None:
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and option in result.output, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["dance", "--mode", "bogus"], "dance: Invalid value: --mode must be one of"),
        (["analyze"], "analyze: Missing argument 'song'"),
        (["dance", "s.wav", "--seed", "abc"], "dance: Invalid value for '--seed'"),
        (["bench", "reach", "--bogus"], "bench reach: No such option: --bogus"),
        (["bogus"], "No such command 'bogus'"),
    ],
)
def test_the_console_command_reports_a_usage_error_in_one_line(args, words) -> None:
    """The installed command (not CliRunner): a bad option or argument is one line
    ``quaddance: error: ...`` with exit status 2, as every other bad input is."""
    proc = subprocess.run(
        [sys.executable, "-m", "quaddance.cli", *args], capture_output=True, text=True, timeout=60
    )
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("quaddance: error: ") and words in lines[0], lines[0]
    assert lines[0].endswith("--help)") and proc.stdout == ""


def test_the_bare_console_command_prints_its_help() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "quaddance.cli"], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 2 and "Usage: quaddance" in proc.stdout and "dance" in proc.stdout


def _commands(group, prefix: tuple[str, ...] = ()):
    ctx = group.make_context("quaddance", [], resilient_parsing=True)
    for name in group.list_commands(ctx):  # `bench` loads its commands when listed
        command = group.get_command(ctx, name)
        yield (*prefix, name)
        if hasattr(command, "list_commands"):  # a group (typer bundles its own click)
            yield from _commands(command, (*prefix, name))


def test_every_command_has_working_help() -> None:
    commands = list(_commands(typer.main.get_command(app)))
    assert {("dance",), ("choreograph",), ("bench", "reach")} <= set(commands)
    for path in [(), *commands]:
        result = CliRunner().invoke(app, [*path, "--help"])
        assert result.exit_code == 0 and "Usage" in result.output, (path, result.output)


@pytest.mark.parametrize(
    "args", [["bench"], ["bench", "reach", "--height", "0.1"], ["bench", "--help"]]
)
def test_bench_outside_a_checkout_is_one_line_and_exit_2(args, tmp_path, monkeypatch, capsys):
    """A wheel install has no benchmarks/ beside its package: `quaddance bench ...` says so
    in one line, whatever follows it."""
    import quaddance.cli.bench as bench
    from quaddance.cli import main

    monkeypatch.setattr(bench, "checkout_root", lambda: tmp_path)  # no benchmarks/ there
    monkeypatch.setattr(sys, "argv", ["quaddance", *args])
    with pytest.raises(SystemExit) as stop:
        main()
    assert stop.value.code == 2
    assert capsys.readouterr().err == f"quaddance: error: {bench.MISSING}\n"


# --- dance.npz ----------------------------------------------------------------------------------


def _dance_arrays(n: int = 100) -> dict[str, np.ndarray]:
    t = np.arange(n) / 50.0
    feet = np.column_stack([0.1 * np.sin(t) ** 2, 0.05 * np.cos(t) ** 2])
    return {
        "fps": np.float64(50.0),
        "time_s": t,
        "human_feet_m": feet,
        "targets_m": np.column_stack([feet, np.zeros((n, 2))]),
        "beats_s": np.array([0.5, 1.0, 1.5]),
        "downbeats_s": np.array([0.5]),
        "mode": np.array("feasible"),
        "source": np.array("song.wav"),
        "seed": np.int64(3),
        "version": np.array("0.1.0"),
    }


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"fps": np.float64(1e9)}, "fps must be > 0 and at most 1000"),
        ({"fps": np.complex128(50)}, "fps must be a single number"),
        ({"time_s": np.arange(100) / 25.0}, "time_s is not sampled at fps = 50"),
        ({"time_s": np.arange(100) / 50.0 + 1e6}, "time_s has values"),
        ({"targets_m": np.full((100, 4), 1e308)}, "targets_m has values"),
        ({"targets_m": np.zeros((100, 4), complex)}, "targets_m must be a 2-D array of real"),
        ({"human_feet_m": np.ones((100, 2), bool)}, "human_feet_m must be a 2-D array of real"),
        ({"beats_s": np.array([1.0, 0.5])}, "beats_s is not in time order"),
        ({"downbeats_s": np.array([np.inf])}, "downbeats_s contains NaN or infinite"),
        ({"mode": np.array("dance!")}, "mode must be one of feasible, paper, minmax"),
        ({"source": np.array("x" * 5000)}, "source: text of 5000 characters"),
        ({"version": np.array("a\nb")}, "version must be printable text"),
        ({"seed": np.uint64(2**64 - 1)}, "seed must be in"),
        ({"beats_s": np.zeros(200_000)}, "beats_s: 2e+05 values"),
        ({"time_s": np.zeros(0)}, "time_s is empty"),
    ],
)
def test_dance_file_fields_are_checked(tmp_path, change, words) -> None:
    from quaddance.dancefile import load_dance

    path = tmp_path / "bad.npz"
    np.savez(path, **{**_dance_arrays(), **change})
    with pytest.raises(InputFileError) as err:
        load_dance(path)
    message = str(err.value)
    assert words in message and message.startswith(str(path)) and len(message) < 300, message


def test_dance_file_array_sizes_are_checked_before_allocating(tmp_path) -> None:
    """A zip bomb: 400 MB of zeros in a small archive is refused from its header."""
    import zipfile

    from quaddance.dancefile import load_dance

    path = tmp_path / "bomb.npz"
    np.savez_compressed(path, **_dance_arrays())
    header = {"descr": "<f8", "fortran_order": False, "shape": (50_000_000, 4)}
    with (
        zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as zf,
        zf.open("targets_m.npy", "w", force_zip64=True) as fh,
    ):  # a second member of the same name: np.load reads the last
        np.lib.format.write_array_header_1_0(fh, header)
        fh.write(bytes(1 << 20))  # only the start of the data: the header alone is checked
    with pytest.raises(InputFileError, match="targets_m: 2e\\+08 values"):
        load_dance(path)


# --- the policy JSON ----------------------------------------------------------------------------


def _shipped_json() -> tuple[Path, dict]:
    import json

    from quaddance.play.policy import shipped_policy_path

    path = shipped_policy_path().with_suffix(".json")
    return path, json.loads(path.read_text())


def _shipped_json_v2() -> dict:
    """The shipped policy's JSON in the current format: its task's reward terms as entries."""
    import json

    from quaddance.play.policy_spec import FORMAT, PolicySpec
    from quaddance.sim.records import task_record

    path, meta = _shipped_json()
    task = task_record(PolicySpec.load(path).task_cfg)
    return dict(meta, format=FORMAT, task=json.loads(json.dumps(task)))


def test_shipped_policy_json_round_trips_unchanged() -> None:
    from quaddance.play.policy_spec import FLAT_REWARDS_FORMAT, PolicySpec
    from quaddance.sim import tasks

    path, _ = _shipped_json()
    spec = PolicySpec.load(path)
    # The shipped policy is the whole-body dancer: 192 paw inputs + 16 body-target inputs +
    # the heading error.
    assert spec.format == FLAT_REWARDS_FORMAT and spec.obs_dim == 209
    assert spec.task_cfg.obs.history_len == 3
    assert spec.task_cfg.whole_body and spec.task_cfg.obs.heading
    assert spec.obs_layout[-1].name == "heading_error_rad"
    assert spec.to_json() == path.read_text()  # byte for byte
    assert PolicySpec.from_json(spec.to_json()) == spec
    # Its flat reward weights are the whole-body task's reward terms, curriculum included.
    want = tasks.whole_body()
    assert spec.task_cfg.rewards == want.rewards
    assert spec.task_cfg.base_height_target_m == want.base_height_target_m


def test_policy_json_with_reward_terms_round_trips(tmp_path) -> None:
    import json

    from quaddance.play.policy_spec import FORMAT, PolicySpec

    path, _ = _shipped_json()
    new = tmp_path / "policy.json"
    new.write_text(json.dumps(_shipped_json_v2(), indent=2) + "\n")
    spec = PolicySpec.load(new)
    assert spec.format == FORMAT and spec.task_cfg == PolicySpec.load(path).task_cfg
    assert spec.to_json() == new.read_text()


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("task.rewards.torques.fn", "open", "task.rewards.torques.fn: 'open' is not a reward"),
        ("task.rewards.torques.fn", "TrackingErrors", "'TrackingErrors' is not a reward"),
        ("task.rewards.torques.weight", "-1", "task.rewards.torques.weight: must be a number"),
        ("task.rewards.torques.per_step", 1, "task.rewards.torques.per_step: must be true or"),
        ("task.rewards.torques.scale", 1, "task.rewards.torques: unknown field 'scale'"),
        ("task.rewards.termination.params", [], "termination.params: must be a JSON object"),
        ("task.rewards.front_tracking.params.c", 1.0, "front_tracking's parameters: got an"),
        ("task.rewards.form", "paper", "task.rewards.form: must be a JSON object"),
        ("task.curriculum_env_steps", [5, 2], "the range's low end is above its high end"),
    ],
)
def test_policy_json_reward_terms_are_checked(tmp_path, field, value, words) -> None:
    message = _refused(tmp_path, _shipped_json_v2(), field, value)
    assert words in message, message


def _set(meta: dict, dotted: str, value) -> None:
    *parents, last = dotted.split(".")
    for key in parents:
        meta = meta[int(key)] if isinstance(meta, list) else meta[key]
    if value is KeyError:
        del meta[last]
    else:
        meta[last] = value


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("format", "quaddance-policy/3", "format: 'quaddance-policy/3' is not a policy format"),
        ("kp", float("nan"), "kp: nan is not a finite number"),
        ("kp", 10**400, "kp: 1000000000"),
        ("kd", True, "kd: must be a number, got true/false"),
        ("decimation", 4.5, "decimation: must be a whole number"),
        ("policy_hz", 60.0, "policy_hz: 60 disagrees with task.policy_hz = 50"),
        ("nominal_joint_pos_rad", [0.0] * 11, "nominal_joint_pos_rad: must be a list of 12"),
        ("action_scale", [0.25] * 11 + [1e300], "action_scale[11]: 1e+300"),
        ("joint_names", ["x"] * 12, "joint_names: must be the unitree_go1 joints"),
        ("version", "v" * 1000, "version: text of 1000 characters"),
        ("obs.history_len", 10**9, "obs.history_len: 1000000000 is not in [0, 100]"),
        ("obs.terms", [{"name": "a", "size": -1, "source": "imu"}], "obs.terms[0].size: -1 is not"),
        ("obs.terms", [{"name": "a", "size": 3}], "obs.terms[0]: missing field source"),
        ("obs.terms.0.source", "lidar", "obs.terms[0].source: 'lidar' is not one of imu"),
        ("obs.terms.5.name", "proprio.foot_height_sim_m", "obs.terms[5]: is not the actor term"),
        ("task.obs.history_len", 4, "obs.history_len: disagrees with task.obs.history_len"),
        ("task.domain_rand.num_variants", 10**8, "task.domain_rand.num_variants: 100000000"),
        ("task.domain_rand.friction", [3.0, 0.1], "friction: the range's low end is above"),
        ("task.rewards.form", "exp", "task.rewards.form: 'exp' is not one of paper, l2"),
        (
            "task.rewards.curriculum_terms",
            ["foot_slide", "body_heigth_tracking"],
            "'body_heigth_tracking' is no reward term; did you mean 'body_height_tracking'?",
        ),
        ("task.scene.warp", 1, "task.scene: unknown field 'warp'"),
        ("task.front_feedforward", "yes", "task.front_feedforward: must be true or false"),
        ("front_feedforward", KeyError, "the file: missing field front_feedforward"),
        ("front_feedforward.heights_m", [0.0] * 46, "front_feedforward.heights_m: must be"),
        ("targets.max_height_m", -0.1, "targets.max_height_m: -0.1 is not a finite"),
        ("training.notes", {"a": 1}, "training.'notes': must be text, a number or null"),
        ("surprise", 1, "the file: unknown field 'surprise'"),
    ],
)
def test_policy_json_fields_are_checked(tmp_path, field, value, words) -> None:
    message = _refused(tmp_path, _shipped_json()[1], field, value)
    assert words in message, message


def _refused(tmp_path, meta: dict, field: str, value) -> str:
    """The one-line error that loading ``meta`` with ``field`` set to ``value`` raises."""
    import json

    from quaddance.play.policy_spec import PolicySpec

    _set(meta, field, value)
    path = tmp_path / "policy.json"
    path.write_text(json.dumps(meta))
    with pytest.raises(InputFileError) as err:
        PolicySpec.load(path)
    message = str(err.value)
    assert message.startswith(f"{path}: ") and len(message) < 300, message
    return message


@pytest.mark.parametrize(
    "text", ["[" * 100_000, '{"a": 1e999999}', "9" * 5000, "\ud800", '{"kp": NaN}']
)
def test_policy_json_that_is_not_json_or_not_an_object(tmp_path, text) -> None:
    from quaddance.play.policy_spec import PolicySpec

    path = tmp_path / "policy.json"
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    with pytest.raises(InputFileError) as err:
        PolicySpec.load(path)
    assert str(err.value).startswith(str(path)) and len(str(err.value)) < 300


def test_dance_file_with_an_unparsable_array_header(tmp_path) -> None:
    """Found by the fuzz campaign: an unbalanced bracket made numpy raise TokenError."""
    import warnings
    import zipfile

    from quaddance.dancefile import load_dance

    path = tmp_path / "tok.npz"
    np.savez(path, **_dance_arrays())
    header = b"{'descr': '<f8', 'fortran_order': False, 'shape': ((3,), }".ljust(118) + b"\n"
    member = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + bytes(24)
    with warnings.catch_warnings(), zipfile.ZipFile(path, "a") as zf:
        warnings.simplefilter("ignore")  # the duplicate name is the point: np.load reads it
        zf.writestr("fps.npy", member)
    with pytest.raises(InputFileError, match=r"tok.npz: cannot read as a dance .npz"):
        load_dance(path)


def test_policy_json_of_an_older_version_with_obs_layout_still_loads(tmp_path) -> None:
    """Files written before `obs.terms` list the same terms as `obs.layout`, without sources."""
    import json

    from quaddance.play.policy_spec import PolicySpec

    _, meta = _shipped_json()
    obs = meta["obs"]
    obs["layout"] = [{"name": t["name"], "size": t["size"]} for t in obs.pop("terms")]
    path = tmp_path / "policy.json"
    path.write_text(json.dumps(meta))
    spec = PolicySpec.load(path)
    assert (
        spec.obs_dim == sum(t.size for t in spec.obs_layout) and spec.obs_layout[0].source is None
    )
    both = dict(obs, terms=obs["layout"])
    path.write_text(json.dumps(dict(meta, obs=both)))
    with pytest.raises(InputFileError, match="exactly one of terms, layout"):
        PolicySpec.load(path)
