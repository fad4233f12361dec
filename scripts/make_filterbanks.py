"""Regenerate src/quaddance/data/filterbanks.npz (librosa's filter banks that the analysers use,
shipped so that `dance` need not import librosa): run after a librosa upgrade, when
tests/test_spectral.py says the shipped ones differ."""

from quaddance.music.spectral import write_filterbanks

if __name__ == "__main__":
    print(write_filterbanks())
