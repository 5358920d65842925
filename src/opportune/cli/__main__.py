"""``python -m opportune.cli``: the command line, as ``python -m opportune`` runs it (without the quick path
of ``count``)."""

from opportune.cli import main

main()
