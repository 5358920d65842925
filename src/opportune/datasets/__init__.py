"""Data sets shipped with the package: the public SALBP precedence graphs and the examples.

Scholl's benchmark data for simple assembly line balancing: real precedence
graphs of assembled products, 7 to 111 tasks (see ``salbp/README.md``).
Each is loadable by name wherever a plan file is accepted, as ``salbp:NAME``
(``opportune count salbp:KILBRID``), or from Python:

>>> from opportune import datasets
>>> datasets.salbp_names()[:3]
('MERTENS', 'BOWMAN8', 'JAESCHKE')
>>> len(datasets.salbp("KILBRID").parts)
45

The examples (the paper's gearbox and the looks of its Table 1) ship too, as ``example:NAME``
(``opportune replay example:gearbox example:gearbox-table1``; ``opportune examples`` lists them):

>>> names = [name for name, _, _ in datasets.examples()]
>>> "gearbox" in names and "gearbox-table1" in names
True

The assemblies ``opportune derive`` reads ship as folders of meshes, ``geometry:NAME``
(``opportune derive geometry:gearbox``): the gearbox, the pump and an interlocked puzzle.

The names and paths are :mod:`opportune.formats.shipped`'s (the readers resolve ``salbp:`` and
``example:`` through it); this package adds loading a graph as a plan.
"""

from __future__ import annotations

from opportune.formats.shipped import (EXAMPLE_PREFIX, GEOMETRY, GEOMETRY_PREFIX, PREFIX, SALBP,  # noqa: F401
                                       example_path, examples, geometry_path, resolve, resolve_assembly,
                                       salbp_names, salbp_path)


def salbp(name: str):
    """A shipped SALBP graph as a single-strategy :class:`~opportune.planning.plan.Plan` (tasks named by number).

    Parameters
    ----------
    name : str
        The graph's name (:func:`salbp_names`), case-insensitive.

    Returns
    -------
    Plan
        The graph's precedence constraints as a plan.

    Raises
    ------
    KeyError
        If no graph has that name.

    Examples
    --------
    >>> plan = salbp("MERTENS")
    >>> len(plan.parts), plan.part_ids[:3]
    (7, ('1', '2', '3'))
    """
    from opportune.formats.loader import load_plan

    return load_plan(salbp_path(name))
