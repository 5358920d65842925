"""Data sets shipped with the package: the public SALBP precedence graphs.

Scholl's benchmark data for simple assembly line balancing: real precedence
graphs of assembled products, 7 to 111 tasks (see ``salbp/README.md``).
Each is loadable by name wherever a plan file is accepted, as ``salbp:NAME``
(``opportune count salbp:KILBRID``), or from Python:

>>> from opportune import datasets
>>> datasets.salbp_names()[:3]
('MERTENS', 'BOWMAN8', 'JAESCHKE')
>>> len(datasets.salbp("KILBRID").parts)
45
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

# Smallest first: the order of the data's README.
SALBP = ("MERTENS", "BOWMAN8", "JAESCHKE", "JACKSON", "MANSOOR", "MITCHELL", "HESKIA", "KILBRID",
         "TONGE70", "ARC111")
PREFIX = "salbp:"


def salbp_names() -> tuple[str, ...]:
    """The names of the shipped SALBP graphs, smallest first."""
    return SALBP


def salbp_path(name: str) -> Path:
    """The file of a shipped SALBP graph (``.IN2``), by name (case-insensitive; ``.IN2`` optional).

    Raises ``KeyError`` naming the graphs there are.
    """
    stem = name.upper().removesuffix(".IN2")
    if stem not in SALBP:
        raise KeyError(f"no SALBP graph named '{name}': the package ships {', '.join(SALBP)}")
    return Path(str(resources.files(__name__).joinpath("salbp", f"{stem}.IN2")))


def salbp(name: str):
    """A shipped SALBP graph as a single-strategy :class:`~opportune.plan.Plan` (tasks named by number)."""
    from opportune.formats import load_plan

    return load_plan(salbp_path(name))
