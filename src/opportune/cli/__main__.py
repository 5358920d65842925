"""``python -m opportune.cli``: the command line, as ``python -m opportune`` runs it (without the quick path
of ``count``)."""

from opportune.cli import main

if __name__ == "__main__":    # run as a script only: importing the module (a doctest walk) runs nothing
    main()
