"""Music commands: ``analyze`` (a song -> analysis JSON) and ``demo-song``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from quaddance.cli.options import SongArg, print_notes


def analyze_cmd(
    song: SongArg,
    online: Annotated[
        bool,
        typer.Option(
            "--online",
            help="Run the online beat tracker of `live` over the song instead (as fast as the "
            "CPU allows): beats, downbeats and tempo as it reports them, and lock_s.",
        ),
    ] = False,
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Where to write the analysis JSON.")
    ] = Path("analysis.json"),
    click: Annotated[
        Path | None,
        typer.Option(
            "--click",
            help="Also write the song with a click on each beat, a higher one on each "
            "downbeat, to hear whether the beats are right (.wav, .flac or .ogg; mono, 22.05 kHz).",
        ),
    ] = None,
) -> None:
    """Find the tempo, beats, downbeats, sections and envelopes of a song; write them as JSON."""
    from rich.console import Console

    from quaddance.fileio import check_outputs
    from quaddance.music.analysis import analyze_file
    from quaddance.music.audio import check_audio_output, load_audio, write_audio
    from quaddance.music.click import with_clicks
    from quaddance.music.live import track_file

    # Outputs are checked before the work, not after it.
    if click is not None:
        check_audio_output(click)
    check_outputs({"--out": out, "--click": click} if click else {"--out": out}, {"SONG": song})
    with Console(stderr=True).status(f"Analysing {song.name}..."):
        result = track_file(song) if online else analyze_file(song)
    result.save_json(out)
    print(f"{song.name}: {result.summary()} -> {out}")
    if not online:
        print_notes(Console(stderr=True), result.notes(song.name))
    if click is not None:
        # The times as the JSON has them, so that the clicks are what `--beats OUT` dances to.
        written = result.to_json_dict()
        y, sr = load_audio(song)
        write_audio(click, with_clicks(y, sr, written["beats_s"], written["downbeats_s"]), sr)
        print(f"{song.name}: {len(written['beats_s'])} beats clicked -> {click}")


def demo_song_cmd(
    out: Annotated[Path, typer.Argument(help="Where to write the song (wav, flac or ogg).")] = Path(
        "demo_song.wav"
    ),
) -> None:
    """Write the built-in demo song: 30 s at 118 BPM, drums, bass and chords, made by code."""
    from quaddance.music.audio import check_audio_output
    from quaddance.music.synth import write_demo_song

    check_audio_output(out)
    truth = write_demo_song(out)
    print(
        f"demo song: {truth.duration_s:.0f} s, {truth.tempo_bpm:g} BPM, {truth.beats_s.size} beats,"
        f" section change at {truth.section_change_s[0]:.2f} s -> {out}"
    )
