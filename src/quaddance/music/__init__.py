"""Music in: decoding (`audio`), analysis (`analysis`) and songs made by code (`synth`).

The audio stack (librosa, soundfile) is imported inside functions, so importing this package
stays cheap.
"""
