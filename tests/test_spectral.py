"""The analysers' spectral pieces (quaddance.music.spectral) against librosa, which they stand
in for so that `dance` need not import it."""

from __future__ import annotations

import subprocess
import sys
import warnings

import librosa
import numpy as np
import pytest

from quaddance.music import spectral

SR = 22050


def _signal(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / SR
    return (np.sin(2 * np.pi * 220.0 * t) + 0.3 * rng.standard_normal(n)).astype(np.float32)


@pytest.mark.parametrize(
    ("n", "n_fft", "hop"), [(SR * 3, 2048, 512), (SR + 77, 1024, 256), (900, 2048, 512)]
)
def test_stft_magnitude_equals_librosa_s(n: int, n_fft: int, hop: int) -> None:
    y = _signal(n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # librosa's "n_fft too large" (short)
        want = np.abs(librosa.stft(y, n_fft=n_fft, hop_length=hop))
    got = spectral.stft_magnitude(y, n_fft, hop)
    assert got.shape == want.shape and got.dtype == want.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5 * float(want.max()))


def test_stft_magnitude_works_in_blocks_for_long_input() -> None:
    """More frames than one block: the blocks join without a seam."""
    y = _signal(512 * (spectral._BLOCK_FRAMES + 300))
    want = np.abs(librosa.stft(y, n_fft=2048, hop_length=512))
    got = spectral.stft_magnitude(y, 2048, 512)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5 * float(want.max()))


def test_db_peak_normalisation_and_rms_equal_librosa_s() -> None:
    y = _signal(SR * 2)
    stft = spectral.stft_magnitude(y, 2048, 512)
    power = stft**2
    power[:, 5] = 0.0  # a silent frame: left as it is by the normalisation
    np.testing.assert_allclose(
        spectral.power_to_db(power, top_db=80.0),
        librosa.power_to_db(power, ref=np.max, top_db=80.0),
        atol=1e-4,
    )
    np.testing.assert_array_equal(
        spectral.normalize_peak(power, axis=0), librosa.util.normalize(power, norm=np.inf, axis=0)
    )
    np.testing.assert_allclose(
        spectral.rms_from_stft(stft, 2048),
        librosa.feature.rms(S=stft, frame_length=2048)[0],
        rtol=1e-5,
    )
    banks = spectral.filterbanks(SR, 2048, 96)
    np.testing.assert_allclose(
        spectral.normalize_peak(banks.chroma @ power, axis=0),
        librosa.feature.chroma_stft(S=power, sr=SR, n_fft=2048, tuning=0.0),
        rtol=1e-5,
    )


@pytest.mark.parametrize("shape", [*spectral.SHIPPED, (16000, 512, 40)])
def test_filterbanks_are_librosa_s(shape: tuple[int, int, int]) -> None:
    """The shipped banks (and one computed on demand) are exactly librosa's; after a librosa
    upgrade that changes them, run scripts/make_filterbanks.py. The mel band centres (float64,
    from exp and log) may differ in the last bit on another CPU, whose vectorised exp/log
    numpy picks at run time (3 of 96 did, by 2e-16 relative, on a fresh machine)."""
    sr, n_fft, n_mels = shape
    banks = spectral.filterbanks(sr, n_fft, n_mels)
    np.testing.assert_array_equal(
        banks.mel, librosa.filters.mel(sr=sr, n_fft=n_fft, n_mels=n_mels, fmax=sr / 2)
    )
    np.testing.assert_allclose(
        banks.mel_hz, librosa.mel_frequencies(n_mels=n_mels + 2, fmax=sr / 2)[1:-1], rtol=1e-14
    )
    np.testing.assert_array_equal(
        banks.chroma, librosa.filters.chroma(sr=sr, n_fft=n_fft, tuning=0.0)
    )
    np.testing.assert_array_equal(banks.freqs_hz, librosa.fft_frequencies(sr=sr, n_fft=n_fft))
    assert not banks.mel.flags.writeable  # shared through the cache


def test_write_filterbanks_writes_what_is_shipped(tmp_path) -> None:
    path = spectral.write_filterbanks(tmp_path / "banks.npz")
    with np.load(path) as new, np.load(spectral._shipped_path()) as shipped:
        assert sorted(new.files) == sorted(shipped.files)
        for name in new.files:
            assert new[name].dtype == shipped[name].dtype
            if new[name].dtype == np.float64:  # band centres: the last bit is the CPU's
                np.testing.assert_allclose(new[name], shipped[name], rtol=1e-14)
            else:
                np.testing.assert_array_equal(new[name], shipped[name])


def test_analysing_a_song_does_not_import_librosa(tmp_path) -> None:
    """The point of this module: `dance`'s analysis and choreography run without librosa."""
    import soundfile as sf

    song = tmp_path / "song.wav"
    sf.write(song, _signal(SR * 4), SR)
    code = (
        "import sys\n"
        "from quaddance.music.analysis import analyze_file\n"
        "from quaddance.music.online_beats import OnlineBeatTracker\n"
        f"a = analyze_file({str(song)!r})\n"
        "OnlineBeatTracker()\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('librosa', 'numba')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("damage", ["missing", "not a zip", "other keys"])
def test_a_lost_or_damaged_banks_file_falls_back_to_librosa(tmp_path, monkeypatch, damage) -> None:
    path = tmp_path / "filterbanks.npz"
    if damage == "not a zip":
        path.write_bytes(b"PK\x03\x04 garbage")
    elif damage == "other keys":
        np.savez(path, something=np.zeros(3))
    monkeypatch.setattr(spectral, "_shipped_path", lambda: path)
    spectral.filterbanks.cache_clear()
    try:
        banks = spectral.filterbanks(*spectral.SHIPPED[0])
    finally:
        spectral.filterbanks.cache_clear()
    sr, n_fft, n_mels = spectral.SHIPPED[0]
    np.testing.assert_array_equal(
        banks.mel, librosa.filters.mel(sr=sr, n_fft=n_fft, n_mels=n_mels, fmax=sr / 2)
    )
