"""The ``quaddance`` command: one module per command group, each command a few lines that
check its options, build a job and run it.

Command bodies import lazily so that ``--help`` stays fast. `main` runs the app with the
error and signal handling of `quaddance.cli._exit`.
"""

from __future__ import annotations

import typer

from quaddance.cli import choreograph, dance, deploy, evaluate, live, music, study, train
from quaddance.cli._exit import EXIT_SIGINT, EXIT_SIGTERM, one_line_error
from quaddance.cli._exit import run_command as _run_command
from quaddance.cli.bench import add_bench

__all__ = ["EXIT_SIGINT", "EXIT_SIGTERM", "app", "main", "one_line_error"]

app = typer.Typer(
    no_args_is_help=True,
    add_completion=False,
    help="Make a Unitree Go1 or Go2 quadruped dance to any piece of music.",
)
app.command("analyze")(music.analyze_cmd)
app.command("demo-song")(music.demo_song_cmd)
app.command("choreograph")(choreograph.choreograph_cmd)
app.command("train")(train.train_cmd)
app.command("dance")(dance.dance_cmd)
app.command("deploy")(deploy.deploy_cmd)
app.command("live")(live.live_cmd)
app.command("eval")(evaluate.eval_cmd)
app.command("study")(study.study_cmd)
add_bench(app)


def main() -> None:
    """Console entry point: user errors become one line on stderr and exit status 2; Ctrl-C
    and SIGTERM one line and exit status 130 / 143 (outputs complete or absent)."""
    _run_command(app)  # the module's `app` at call time: tests run a stand-in in its place
