"""``python -m quaddance.cli ...``: the same as the ``quaddance`` command."""

from quaddance.cli import main

main()
