"""Beat clarity (`quaddance.music.analysis.beat_clarity`) of songs with a beat and of audio
without one: where `AnalysisConfig.min_beat_clarity` lies between them.

Songs: every song of the real-music sets (tuning and held-out parts reported apart) and of each
set given with ``--also`` (e.g. ``benchmarks/real_music_fit``). Audio without a beat: speech
read by Debian's espeak-ng in three languages (skipped, with a line, where it is not installed:
``apt-get install espeak-ng``), and three noises drawn from a fixed seed (white, brown, and a
crackle of random clicks).

    python -m benchmarks.beat_clarity [--also ROOT ...] [--out FILE]
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.real_music import (
    REAL_SET_ROOTS,
    load_audio_at,
    load_songs,
    run_as_script,
    set_script_parser,
)
from quaddance.fileio import write_json
from quaddance.music import analysis
from quaddance.music.audio import load_audio

RESULTS = "benchmarks/results/beat_clarity.json"
SR_HZ = 22050
NOISE_S = 30.0
SPEECH = {
    "en": "A four legged robot can dance to any piece of music, but only when the music has a "
    "beat that it can hear. Speech has syllables and pauses, and its rhythm is not a steady "
    "pulse. Some sentences are short. Others run on for much longer than the ones before "
    "them, so that the pauses fall at irregular times. One, two, three, seventeen, forty two.",
    "de": "Ein vierbeiniger Roboter kann zu jeder Musik tanzen, wenn sie einen hörbaren Takt "
    "hat. Sprache hat Silben und Pausen, aber keinen gleichmäßigen Puls. Manche Sätze sind "
    "kurz. Andere sind viel länger als die vorigen, so dass die Pausen unregelmäßig fallen.",
    "fr": "Un robot à quatre pattes peut danser sur n'importe quelle musique, pourvu qu'elle "
    "ait un battement qu'il entende. La parole a des syllabes et des pauses, mais pas de "
    "pulsation régulière. Certaines phrases sont courtes; d'autres bien plus longues.",
}


def noises(seed: int = 0) -> dict[str, np.ndarray]:
    """Three noises of `NOISE_S` at `SR_HZ`, float32."""
    rng = np.random.default_rng(seed)
    n = int(NOISE_S * SR_HZ)
    brown = np.cumsum(rng.standard_normal(n))
    brown -= np.convolve(brown, np.ones(2000) / 2000, mode="same")  # no drift below 11 Hz
    crackle = np.zeros(n)
    t = np.arange(int(0.05 * SR_HZ)) / SR_HZ
    for at_s in np.cumsum(rng.exponential(0.4, size=int(NOISE_S / 0.4 * 2))):
        i = int(at_s * SR_HZ)
        if i + t.size <= n:
            crackle[i : i + t.size] += (
                rng.uniform(0.2, 1.0) * rng.standard_normal(t.size) * np.exp(-t / 0.01)
            )
    out = {"white noise": rng.standard_normal(n), "brown noise": brown, "crackle": crackle}
    return {k: (0.3 * v / np.abs(v).max()).astype(np.float32) for k, v in out.items()}


def speech() -> dict[str, np.ndarray]:
    """espeak-ng reading `SPEECH`, or nothing where it is not installed."""
    exe = shutil.which("espeak-ng")
    if exe is None:
        print("espeak-ng not found (apt-get install espeak-ng): no speech")
        return {}
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for lang, text in SPEECH.items():
            wav = Path(tmp) / f"{lang}.wav"
            subprocess.run([exe, "-v", lang, "-w", str(wav), text], check=True, timeout=120)
            out[f"speech ({lang}, espeak-ng)"] = load_audio(wav, sr=SR_HZ)[0]
    return out


def clarity(y: np.ndarray) -> float:
    return round(float(analysis.analyze(np.asarray(y, np.float32), SR_HZ).beat_clarity), 4)


def summary(values: list[float]) -> dict[str, float]:
    v = np.asarray(values)
    return {
        "n": int(v.size),
        "min": round(float(v.min()), 3),
        "p5": round(float(np.percentile(v, 5)), 3),
        "median": round(float(np.median(v)), 3),
        "max": round(float(v.max()), 3),
    }


def run(roots: dict[str, Path]) -> dict[str, Any]:
    sets = {name: load_songs(root) for name, root in roots.items()}  # all checked before work
    songs: dict[str, float] = {}
    for set_name, set_songs in sets.items():
        for song in set_songs:
            key = f"{song.split}/{set_name}/{song.name}"
            songs[key] = clarity(load_audio_at(song, SR_HZ))
            print(f"{key}: {songs[key]:.3f}")
    beatless = {name: clarity(y) for name, y in {**speech(), **noises()}.items()}
    for name, value in beatless.items():
        print(f"{name}: {value:.3f}")
    groups = {
        "songs outside the held-out parts": [v for k, v in songs.items() if k.startswith("tuning")],
        "held-out songs": [v for k, v in songs.items() if k.startswith("heldout")],
        "audio without a beat": list(beatless.values()),
    }
    return {
        "benchmark": "beat_clarity",
        "threshold": analysis.AnalysisConfig().min_beat_clarity,
        "summary": {k: summary(v) for k, v in groups.items() if v},
        "songs": songs,
        "beatless": beatless,
    }


def main(argv: list[str] | None = None) -> None:
    args = set_script_parser("benchmarks.beat_clarity", __doc__, RESULTS).parse_args(argv)
    roots = {**REAL_SET_ROOTS, **{root.name: root for root in args.also}}
    result = run(roots)
    for group, stats in result["summary"].items():
        print(f"{group}: {stats}")
    write_json(args.out, result)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    run_as_script(main)
