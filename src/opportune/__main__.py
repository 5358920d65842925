"""``python -m opportune``: the command line, as the ``opportune`` script runs it."""

from opportune.launch import main

main()
