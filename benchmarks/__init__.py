"""Benchmarks and experiments of quaddance: the ``quaddance bench`` commands (`benchmarks.cli`).

Not part of the installed package: ``quaddance bench`` loads this folder from a source
checkout (``benchmarks/`` beside ``src/``). Each benchmark writes a JSON file under
``benchmarks/results/``; renders of MIDI songs are cached under ``benchmarks/cache/``.
"""
