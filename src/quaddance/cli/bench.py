"""The ``bench`` command group, loaded from a source checkout.

The benchmarks are not part of the installed package: they live in the repository's top-level
``benchmarks/`` package, beside ``src/`` (an editable install's ``src/quaddance`` ->
``../../benchmarks``), whose ``benchmarks.cli.app`` holds the commands. They are imported the
first time a ``bench`` command is listed or looked up, so no other command loads them and
``benchmarks.cli`` may import ``quaddance.cli``. Without them (a wheel install) every
``quaddance bench ...`` is one line saying so and exit status 2.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import typer
from typer.core import TyperGroup

from quaddance.errors import QuaddanceError

MISSING = "quaddance bench needs a source checkout: benchmarks/ not found next to src/"


def checkout_root() -> Path:
    """The folder that would hold ``src/quaddance`` and ``benchmarks/`` in a checkout."""
    return Path(__file__).resolve().parents[3]  # src/quaddance/cli/bench.py


def benchmark_commands() -> dict[str, Any]:
    """The commands of the checkout's ``benchmarks.cli.app`` (click commands by name).

    Raises:
        QuaddanceError: `MISSING`, where `checkout_root` has no ``benchmarks/cli.py``.
    """
    root = checkout_root()
    if not (root / "benchmarks" / "cli.py").is_file():
        raise QuaddanceError(MISSING)
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    from benchmarks.cli import app

    return dict(typer.main.get_group(app).commands)


class BenchGroup(TyperGroup):
    """The ``bench`` group: `benchmark_commands`, loaded when first listed or looked up."""

    def _loaded(self) -> dict[str, Any]:
        if not self.commands:
            self.commands.update(benchmark_commands())
        return dict(self.commands)

    def list_commands(self, ctx: Any) -> list[str]:
        return list(self._loaded())

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        return self._loaded().get(cmd_name)


def add_bench(app: typer.Typer) -> None:
    """Add the ``bench`` group to ``app``."""
    app.add_typer(
        typer.Typer(no_args_is_help=True),
        name="bench",
        cls=BenchGroup,
        help="Benchmarks; each writes a JSON file of results (needs a source checkout).",
    )
