"""Convert BeatNet's published CRNN weights into the ONNX file the beat benchmarks run.

BeatNet 1.1.3 (https://github.com/mjhydri/BeatNet, weights and code CC BY 4.0) is taken from
PyPI as a wheel and checked against its SHA-256. Its three ``models/model_N_weights.pt`` (torch
state dicts, read with ``weights_only=True``) are loaded, unchanged, into one torch module
that runs the three networks side by side and averages their beat and downbeat
probabilities, exported as ``src/quaddance/data/beatnet/beatnet_ensemble.onnx`` (the sequence
length free, the LSTM state an input and an output so that a stream can be fed in pieces),
with the licence beside it. BeatNet itself is never installed (it needs madmom and pyaudio).

Usage: .venv/bin/python scripts/fetch_beatnet.py
"""

from __future__ import annotations

import argparse
import hashlib
import io
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

VERSION = "1.1.3"
WHEEL = f"BeatNet-{VERSION}-py3-none-any.whl"
WHEEL_SHA256 = "1ecfa17bdcbe899975a88bdb6efebd6970d846a4f3b6cfd5c6f320647c641c7e"
OUT = Path(__file__).resolve().parent.parent / "src" / "quaddance" / "data" / "beatnet"
MODELS = (1, 2, 3)
ATTRIBUTION = f"""\
beatnet_ensemble.onnx holds the weights of BeatNet's three pre-trained CRNN models
(models/model_1_weights.pt, model_2_weights.pt and model_3_weights.pt of the PyPI package
BeatNet=={VERSION}), unchanged, in BeatNet's network run three times side by side with the
mean of the three outputs taken, exported to ONNX by scripts/fetch_beatnet.py.

BeatNet: Mojtaba Heydari, Frank Cwitkowitz and Zhiyao Duan, "BeatNet: CRNN and Particle
Filtering for Online Joint Beat Downbeat and Meter Tracking", ISMIR 2021.
https://github.com/mjhydri/BeatNet

Licensed under the Creative Commons Attribution 4.0 International licence (CC BY 4.0),
https://creativecommons.org/licenses/by/4.0/ ; the licence text is in LICENSE.txt.
"""


def _wheel(dest: Path) -> Path:
    subprocess.run(
        [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check",
         "--no-deps", "--only-binary", ":all:", "--dest", str(dest), f"BeatNet=={VERSION}"],
        check=True,
    )  # fmt: skip
    path = dest / WHEEL
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    if digest != WHEEL_SHA256:
        raise SystemExit(f"{path}: SHA-256 {digest}, expected {WHEEL_SHA256}")
    return path


def _states(whl: zipfile.ZipFile) -> list[dict]:
    """BeatNet's state dicts of `MODELS` from its wheel, read with ``weights_only=True``."""
    import torch

    return [
        torch.load(
            io.BytesIO(whl.read(f"BeatNet/models/model_{n}_weights.pt")),
            map_location="cpu",
            weights_only=True,
        )
        for n in MODELS
    ]


def _ensemble(states: list[dict]):
    """A torch module with BeatNet's ``BDA`` forward pass for each state dict: conv (2 x 10
    over the 272 features), ReLU, max-pool 2, linear to 150, a 2-layer LSTM of 150 cells,
    linear to 3 classes, softmax; the mean of the first two classes (beat, downbeat)."""
    import torch
    from torch.nn import functional

    class Bda(torch.nn.Module):
        def __init__(self, state: dict) -> None:
            super().__init__()
            self.conv1 = torch.nn.Conv1d(1, 2, 10)
            self.linear0 = torch.nn.Linear(262, 150)
            self.lstm = torch.nn.LSTM(150, 150, num_layers=2)
            self.linear = torch.nn.Linear(150, 3)
            self.load_state_dict(state)

        def forward(self, feats, h0, c0):
            x = functional.max_pool1d(functional.relu(self.conv1(feats[:, None, :])), 2)
            x = self.linear0(x.reshape(x.shape[0], -1))
            y, (h, c) = self.lstm(x[:, None, :], (h0, c0))
            return torch.softmax(self.linear(y[:, 0]), dim=1)[:, :2], h, c

    class Ensemble(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.nets = torch.nn.ModuleList(Bda(s) for s in states)

        def forward(self, feats, h0, c0):
            outs = [net(feats, h0[i], c0[i]) for i, net in enumerate(self.nets)]
            probs = torch.stack([o[0] for o in outs]).mean(dim=0)
            return probs, torch.stack([o[1] for o in outs]), torch.stack([o[2] for o in outs])

    return Ensemble().eval()


def main(argv: list[str] | None = None) -> None:
    import torch

    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp, zipfile.ZipFile(_wheel(Path(tmp))) as whl:
        licence = whl.read(f"BeatNet-{VERSION}.dist-info/LICENSE").decode()
        (OUT / "LICENSE.txt").write_text(licence)
        (OUT / "ATTRIBUTION.txt").write_text(ATTRIBUTION)
        model = _ensemble(_states(whl))
    state_shape = (len(MODELS), 2, 1, 150)
    args = (torch.zeros(50, 272), torch.zeros(state_shape), torch.zeros(state_shape))
    out = OUT / "beatnet_ensemble.onnx"
    tmp_out = out.with_suffix(".tmp.onnx")
    torch.onnx.export(
        model, args, str(tmp_out), input_names=["features", "h0", "c0"],
        output_names=["probs", "h", "c"], dynamic_axes={"features": {0: "frames"},
        "probs": {0: "frames"}}, opset_version=17, dynamo=False,
    )  # fmt: skip
    tmp_out.replace(out)
    print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB)")


if __name__ == "__main__":
    main()
