"""A learned beat activation: how likely each onset frame is a beat, from its band fluxes.

A logistic regression over the flux of 8 mel bands (dB and log1p-compressed, each divided by
its local level) at a frame and the 3 frames on either side. It learns which bands carry the
beat (a kick, a snare) and which carry the off-beats (open hats, skanks) from real music with
exact beats: the tuning songs of the real-music sets (``benchmarks/real_music*``, their
sources and licences in each set's ``sources.toml``). The analyser mixes it into its onset
envelopes (`analysis.AnalysisConfig.activation_weight`).

``python -m benchmarks.train_beat_activation`` fits it and writes ``data/beat_activation.json``;
this module only reads and applies it, in numpy. The weights are this project's own, fitted at
the analyser's default settings (22.05 kHz, 2048-point FFT, hop 512, 96 mel bands); the songs
they were fitted on and those songs' licences are listed in the sets' ``sources.toml``.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import InputFileError

FORMAT = "quaddance-beat-activation-1"
N_BANDS = 8
"""Mel bands of the activation's input: the analyser's mel bands in 8 equal groups."""
CONTEXT = (3, 3)
"""Frames before and after a frame that the activation sees (70 ms each at 43 frames/s)."""


def n_features(context: tuple[int, int]) -> int:
    """Inputs of a model that sees ``context`` (before, after) frames around each frame."""
    return 2 * N_BANDS * (context[0] + context[1] + 1)


def band_flux(flux_db: np.ndarray, flux_log: np.ndarray) -> np.ndarray:
    """(2 * N_BANDS, ...) mean dB flux, then mean log1p flux, of each group of mel bands.

    Args:
        flux_db: (n_mels, ...) half-wave rectified flux of the dB mel spectrogram.
        flux_log: (n_mels, ...) the same of the log1p-compressed mel spectrogram.
    """
    groups = np.array_split(np.arange(flux_db.shape[0]), N_BANDS)
    return np.stack([flux[g].mean(axis=0) for flux in (flux_db, flux_log) for g in groups])


def design_matrix(rows: np.ndarray, context: tuple[int, int]) -> np.ndarray:
    """(n, n_features(context)) each frame's rows (``(2 * N_BANDS, n)``, normalised) and those
    of its ``context`` (before, after) neighbours, earliest first; the edges repeat."""
    n = rows.shape[1]
    pad = np.pad(rows, ((0, 0), context), mode="edge")
    return np.concatenate([pad[:, k : k + n] for k in range(sum(context) + 1)]).T


def sigmoid(z: np.ndarray | float) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-np.clip(z, -60.0, 60.0)))


@dataclass(frozen=True)
class BeatActivationModel:
    """The fitted weights and where they came from."""

    weights: np.ndarray
    """(n_features(context),) logistic weights, in `design_matrix`'s column order."""
    bias: float
    context: tuple[int, int]
    """Frames (before, after) each frame that it sees."""
    trained_on: tuple[str, ...]
    """Names of the songs it was fitted on (tuning songs of the real-music sets)."""
    regularisation_c: float
    """Inverse L2 strength of the fit (scikit-learn's ``C``)."""

    def activation(self, rows: np.ndarray) -> np.ndarray:
        """(n,) beat probability of each frame from its normalised band rows."""
        return sigmoid(design_matrix(rows, self.context) @ self.weights + self.bias)

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "n_bands": N_BANDS,
            "context_frames": list(self.context),
            "weights": [round(float(w), 6) for w in self.weights],
            "bias": round(float(self.bias), 6),
            "trained_on": list(self.trained_on),
            "regularisation_c": self.regularisation_c,
        }

    def save(self, path: str | Path) -> None:
        """Write the model as JSON, atomically."""
        from quaddance.fileio import write_json

        write_json(path, self.to_json_dict())

    @classmethod
    def load(cls, path: str | Path) -> BeatActivationModel:
        """Read a model written by `save`; a bad file raises ``InputFileError``."""
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except FileNotFoundError as err:
            raise InputFileError(path, "no such file") from err
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise InputFileError(path, f"is not a JSON file ({err})") from err
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise InputFileError(path, f"is not a beat activation model (format {FORMAT})")
        if data.get("n_bands") != N_BANDS:
            raise InputFileError(path, f"needs {N_BANDS} bands")
        try:
            weights = np.asarray(data["weights"], dtype=float)
            bias = float(data["bias"])
            before, after = (int(k) for k in data["context_frames"])
            trained_on = tuple(str(name) for name in data["trained_on"])
            c = float(data["regularisation_c"])
        except (KeyError, TypeError, ValueError) as err:
            raise InputFileError(path, f"has a missing or malformed field ({err})") from err
        if not (0 <= before <= 50 and 0 <= after <= 50):
            raise InputFileError(path, "context_frames must be two counts of 0-50 frames")
        expected = n_features((before, after))
        if weights.shape != (expected,) or not np.all(np.isfinite(weights)):
            raise InputFileError(path, f"weights must be {expected} finite numbers")
        if not np.isfinite(bias):
            raise InputFileError(path, "bias must be a finite number")
        weights.setflags(write=False)
        return cls(weights, bias, (before, after), trained_on, c)


def shipped_path() -> Path:
    return Path(str(resources.files("quaddance") / "data" / "beat_activation.json"))


@functools.lru_cache(maxsize=4)
def load_model(path: Path | None = None) -> BeatActivationModel:
    """The model at ``path``, or the shipped one; read once per process."""
    return BeatActivationModel.load(path if path is not None else shipped_path())
