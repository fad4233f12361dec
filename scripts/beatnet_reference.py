"""Write tests/data/beatnet_reference.npz: what madmom and BeatNet's own torch model compute on
a short song, the numbers `tests/test_beat_activation.py` holds quaddance's numpy version to.

Needs madmom (``bash scripts/install_madmom.sh``) and torch (the project's environment); the
BeatNet wheel is taken from PyPI as ``scripts/fetch_beatnet.py`` takes it.

Usage: .venv/bin/python scripts/beatnet_reference.py
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "tests" / "data" / "beatnet_reference.npz"
MADMOM_PYTHON = ROOT / ".madmom" / "venv" / "bin" / "python"
# BeatNet's LOG_SPECT, written with madmom's processors as BeatNet writes it.
MADMOM_FEATURES = """
import sys, numpy as np
from madmom.audio.signal import SignalProcessor, FramedSignalProcessor
from madmom.audio.stft import ShortTimeFourierTransformProcessor
from madmom.audio.spectrogram import (FilteredSpectrogramProcessor,
    LogarithmicSpectrogramProcessor, SpectrogramDifferenceProcessor)
from madmom.processors import ParallelProcessor, SequentialProcessor
y = np.load(sys.argv[1])
chain = SequentialProcessor((
    FramedSignalProcessor(frame_size=1411, hop_size=441),
    ShortTimeFourierTransformProcessor(),
    FilteredSpectrogramProcessor(num_bands=24, fmin=30, fmax=17000, norm_filters=True),
    LogarithmicSpectrogramProcessor(mul=1, add=1),
    SpectrogramDifferenceProcessor(diff_ratio=0.5, positive_diffs=True, stack_diffs=np.hstack)))
pipe = SequentialProcessor((SignalProcessor(num_channels=1, win_length=1411, sample_rate=22050),
                            ParallelProcessor([chain]), np.hstack))
np.save(sys.argv[2], np.asarray(pipe(y), dtype=np.float32))
"""


def main(argv: list[str] | None = None) -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    if not MADMOM_PYTHON.is_file():
        raise SystemExit(f"no madmom at {MADMOM_PYTHON}: run `bash scripts/install_madmom.sh`")
    import torch

    sys.path.insert(0, str(ROOT / "scripts"))
    from fetch_beatnet import MODELS, _ensemble, _states, _wheel

    from quaddance.music.synth import render_song

    y, truth = render_song(120.0, 5.0, sr=22050, seed=3)
    y = y.astype(np.float32)
    with tempfile.TemporaryDirectory() as tmp:
        np.save(Path(tmp) / "y.npy", y)
        subprocess.run(
            [str(MADMOM_PYTHON), "-c", MADMOM_FEATURES, f"{tmp}/y.npy", f"{tmp}/f.npy"],
            check=True,
        )
        feats = np.load(Path(tmp) / "f.npy")
        with zipfile.ZipFile(_wheel(Path(tmp))) as whl:
            states = _states(whl)
    # Each network alone, run by torch (the ONNX file runs them together).
    acts = {}
    zeros = torch.zeros(1, 2, 1, 150)
    with torch.no_grad():
        for n, state in zip(MODELS, states, strict=True):
            probs, _, _ = _ensemble([state])(torch.from_numpy(feats), zeros, zeros)
            acts[f"activation_{n}"] = probs.numpy()
    np.savez_compressed(OUT, audio=y, features=feats, beats_s=truth.beats_s, **acts)
    print(f"wrote {OUT} ({OUT.stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()
