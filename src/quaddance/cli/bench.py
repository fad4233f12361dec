"""The ``bench`` command group, loaded from a source checkout.

The benchmarks are not part of the installed package: they live in the repository's top-level
``benchmarks/`` package, beside ``src/`` (an editable install's ``src/quaddance`` ->
``../../benchmarks``). Without it (a wheel install) ``quaddance bench`` is one line saying so
and exit status 2.
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from quaddance.errors import QuaddanceError

MISSING = "quaddance bench needs a source checkout: benchmarks/ not found next to src/"


def checkout_root() -> Path:
    """The folder that would hold ``src/quaddance`` and ``benchmarks/`` in a checkout."""
    return Path(__file__).resolve().parents[3]  # src/quaddance/cli/bench.py


def add_bench(app: typer.Typer, root: Path | None = None) -> None:
    """Add the ``bench`` group to ``app``: the app of ``ROOT/benchmarks/cli.py`` (``root``
    defaults to `checkout_root`), or, where there is none, a ``bench`` command that raises
    `QuaddanceError` (`MISSING`) whatever its arguments."""
    root = checkout_root() if root is None else root
    if (root / "benchmarks" / "cli.py").is_file():
        if str(root) not in sys.path:
            sys.path.insert(0, str(root))
        from benchmarks.cli import app as bench_app

        app.add_typer(bench_app, name="bench")
        return

    @app.command(
        "bench",
        add_help_option=False,
        context_settings={"allow_extra_args": True, "ignore_unknown_options": True},
        help="Benchmarks (needs a source checkout of quaddance).",
    )
    def bench_missing() -> None:
        raise QuaddanceError(MISSING)
