"""Plans from the product's geometry: every feasible assembly sequence, derived from the parts' shapes.

:func:`derive` reads an assembly in its assembled pose (a folder of meshes, one file a part:
:mod:`opportune.derive.geometry`), finds which parts block each part's straight insertion along each
direction (:mod:`opportune.derive.blocking`) and writes the plan that admits exactly the feasible
sequences (:mod:`opportune.derive.plan`).  Needs the ``geometry`` extra (``pip install
'opportune[geometry]'``: trimesh reads the meshes).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from opportune.derive.blocking import AXES, Blocking, find_blocking
from opportune.derive.geometry import Assembly, GeometryError, read_assembly
from opportune.derive.plan import DeriveError, DerivedStrategy, exact_strategies
from opportune.planning.plan import Plan, PlanError

__all__ = ["derive", "Derivation", "DeriveError", "GeometryError", "DIRECTION_SETS", "plan_of"]

#: The direction sets ``--directions`` names.
DIRECTION_SETS = {"axes": AXES}


@dataclass(frozen=True)
class Derivation:
    """A derived plan with what it was derived from: the blocking relation, the strategies with each
    part's direction, and the CPU seconds taken."""

    plan: Plan
    blocking: Blocking
    strategies: tuple[DerivedStrategy, ...]
    seconds: float
    assembly: Assembly | None = None
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        """The numbers of the derivation, as ``derive --json`` prints them (the plan aside)."""
        b = self.blocking
        return {"parts": len(b.parts), "directions": list(b.directions), "tolerance_m": b.tolerance,
                "blocking_checks": b.checks, "strategies": len(self.strategies),
                "constraints": sum(len(s.pairs) for s in self.strategies), "cpu_seconds": round(self.seconds, 4),
                "blockers": {p: {d: sorted(q) for d, q in dirs.items()} for p, dirs in b.blockers.items()},
                "directions_by_strategy": [s.directions for s in self.strategies]}


def derive(path: str | Path, *, directions: str = "axes", tolerance: float | None = None, units: str = "m",
           name: str | None = None) -> Derivation:
    """Derive the plan of an assembly: exactly the sequences feasible under the motion model.

    Parameters
    ----------
    path : str or Path
        A folder of meshes in the assembled pose, one file a part (``.obj``, ``.stl``, ``.ply``; the id
        is the file's stem), or ``geometry:NAME``, a shipped assembly (``gearbox``, ``pump``, ``puzzle``).
    directions : str
        The insertion directions: ``"axes"`` (the six axis directions).
    tolerance : float, optional
        Penetration tolerance in the files' units (default: a millionth of the assembly's size).
    units : str
        ``"m"`` or ``"mm"``: the files' unit of length.
    name : str, optional
        The plan's name (default: the folder's name).

    Returns
    -------
    Derivation
        ``.plan`` (a :class:`~opportune.planning.plan.Plan`, checked as a plan file is), the blocking
        relation and the strategies' directions.

    Raises
    ------
    GeometryError
        A folder or mesh that cannot be used (the message names the part).
    DeriveError
        No feasible sequence (the parts that lock each other named), or an exact plan larger than a plan holds.

    Examples
    --------
    >>> derive("no-such-folder")
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: no-such-folder: not a folder; give a folder of meshes, one file a part (.obj, .stl, .ply)
    """
    if directions not in DIRECTION_SETS:
        raise GeometryError(f"directions {directions!r}: give one of {', '.join(DIRECTION_SETS)}")
    from opportune.formats.shipped import resolve_assembly

    try:
        path = resolve_assembly(path)
    except KeyError as exc:
        raise GeometryError(exc.args[0]) from None
    start = time.process_time()
    assembly = read_assembly(path, units=units, tolerance=tolerance)
    block = find_blocking(assembly, DIRECTION_SETS[directions])
    strategies = exact_strategies(block)
    from opportune.derive.shapes import shapes

    carried, notes = shapes(assembly)
    plan = plan_of(block, strategies, name or Path(path).resolve().name or "assembly", directions, carried)
    return Derivation(plan, block, tuple(strategies), time.process_time() - start, assembly, tuple(notes))


def plan_of(block: Blocking, strategies: list[DerivedStrategy], name: str, directions: str,
            shapes: dict[str, dict] | None = None) -> Plan:
    """The strategies as a plan, through the plan checker (what ``opportune check`` reads back).

    Parameters
    ----------
    block : Blocking
        The blocking relation (its directions and tolerance are stated in the plan's description).
    strategies : list of DerivedStrategy
        What :func:`~opportune.derive.plan.exact_strategies` found.
    name : str
        The plan's name.
    directions : str
        The name of the direction set, as the description states it.
    shapes : dict, optional
        Part id → its ``geometry`` (:func:`opportune.derive.shapes.shapes`), carried by the plan.

    Returns
    -------
    Plan
        The plan, checked.

    Raises
    ------
    DeriveError
        A plan the checker refuses (a part id it does not take).

    Examples
    --------
    >>> from opportune.derive.plan import exact_strategies
    >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0)}, {"a": {"+x": frozenset("b")}, "b": {"+x": frozenset()}}, 0, 0)
    >>> dict(plan_of(b, exact_strategies(b), "two", "axes").strategies[0].requires)
    {'b': ('a',)}
    """
    from opportune.formats.loader import plan_from_dict

    doc = {"name": name, "description": (
        f"Derived from the parts' geometry (opportune derive): each part goes in by one straight translation "
        f"from far away along one of the directions {directions} ({', '.join(block.directions)}), sliding along "
        f"faces it touches, never through another part (penetration tolerance {block.tolerance:.6g} m). "
        "Each strategy is one choice of a direction per part; the plan admits exactly the feasible sequences."),
        "parts": [{"id": p, "geometry": shapes[p]} if shapes and p in shapes else p for p in block.parts],
        "strategies": []}
    for k, s in enumerate(strategies, 1):
        requires: dict[str, list[str]] = {}
        for before, after in s.pairs:
            requires.setdefault(after, []).append(before)
        doc["strategies"].append({"name": f"s{k}: " + " ".join(f"{p} {d}" for p, d in s.directions.items())
                                  if len(s.directions) <= 12 else f"s{k}", "requires": requires})
    try:
        return plan_from_dict(doc)
    except PlanError as exc:   # the files' names are the part ids: one the plan refuses is the user's to rename
        raise DeriveError(f"the derived plan is not valid ({exc}); part ids are the files' stems: rename the "
                          "files") from None
