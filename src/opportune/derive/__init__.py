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
from opportune.derive.contacts import Contact, find_contacts
from opportune.derive.directions import default_directions, parse_directions, support_conditions
from opportune.derive.geometry import Assembly, GeometryError, read_assembly
from opportune.derive.plan import Conditions, DeriveError, DerivedStrategy, exact_strategies
from opportune.planning.plan import Plan, PlanError

__all__ = ["derive", "Derivation", "DeriveError", "GeometryError", "DIRECTION_SETS"]

#: The direction sets ``--directions`` names.
DIRECTION_SETS = {"axes": AXES}


@dataclass(frozen=True)
class Derivation:
    """A derived plan with what it was derived from: the blocking relation, the contacts, the supports
    each part needed, the strategies with each part's way in, and the CPU seconds taken."""

    plan: Plan
    blocking: Blocking
    strategies: tuple[DerivedStrategy, ...]
    seconds: float
    contacts: tuple[Contact, ...] = ()
    conditions: Conditions = Conditions({})

    def to_dict(self) -> dict:
        """The numbers of the derivation, as ``derive --json`` prints them (the plan aside)."""
        b = self.blocking
        return {"parts": len(b.parts), "directions": list(b.directions), "tolerance_m": b.tolerance,
                "blocking_checks": b.checks, "contacts": len(self.contacts), "strategies": len(self.strategies),
                "constraints": sum(len(s.pairs) for s in self.strategies), "cpu_seconds": round(self.seconds, 4),
                "base": self.conditions.base,
                "supports": {p: {kind: sorted(n) for kind, n in needs} for p, needs in self.conditions.needs.items()},
                "blockers": {p: {d: sorted(q) for d, q in dirs.items()} for p, dirs in b.blockers.items()},
                "directions_by_strategy": [s.directions for s in self.strategies]}


def derive(source: str | Path | Assembly, *, directions: str | dict | None = None, tolerance: float | None = None,
           units: str = "m", name: str | None = None, gravity: str | None = None, connected: bool = False,
           base: str | None = None) -> Derivation:
    """Derive the plan of an assembly: exactly the sequences feasible under the motion model.

    Parameters
    ----------
    source : str, Path or Assembly
        A folder of meshes in the assembled pose, one file a part (``.obj``, ``.stl``, ``.ply``; the id
        is the file's stem), or an assembly already read.
    directions : str or dict, optional
        The insertion directions: ``"axes"`` (the six axis directions), a list such as ``"+z,-x,0 0.7 0.7"``,
        or names and vectors; default the axes and the normals of the contacts between parts.
    tolerance : float, optional
        Penetration tolerance in the files' units (default: a millionth of the assembly's size).
    units : str
        ``"m"`` or ``"mm"``: the files' unit of length.
    name : str, optional
        The plan's name (default: the folder's name).
    gravity : str, optional
        The direction of gravity (``"-z"``): each part rests on a part below it that it touches, or on the
        fixture (its lowest point at the assembly's lowest level; the first part must, unless it is the base).
    connected : bool
        Each part after the first touches a part already in.
    base : str, optional
        The part that goes first.

    Returns
    -------
    Derivation
        ``.plan`` (a :class:`~opportune.planning.plan.Plan`, checked as a plan file is), the blocking
        relation, the contacts and the strategies' ways in.

    Raises
    ------
    GeometryError
        A folder or mesh that cannot be used (the message names the part), or an option that does not fit it.
    DeriveError
        No feasible sequence (the parts that lock each other named), or an exact plan larger than a plan holds.

    Examples
    --------
    >>> derive("no-such-folder")
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: no-such-folder: not a folder; give a folder of meshes, one file a part (.obj, .stl, .ply)
    """
    start = time.process_time()
    given = parse_directions(directions) if isinstance(directions, str) else directions
    if isinstance(source, Assembly):
        assembly, label = source, "assembly"
    else:
        assembly, label = read_assembly(source, units=units, tolerance=tolerance), Path(source).resolve().name
    # contacts only where something asks for them: the supports, or the default directions
    needed = given is None or gravity is not None or connected
    contacts = find_contacts(assembly) if needed else []
    conditions = support_conditions(assembly, contacts, gravity=gravity, connected=connected, base=base)
    block = find_blocking(assembly, default_directions(contacts) if given is None else given)
    strategies = exact_strategies(block, conditions)
    spec = directions if isinstance(directions, str) else "the axes and the contacts' normals"
    plan = _plan(block, strategies, name or label or "assembly", spec, conditions)
    return Derivation(plan, block, tuple(strategies), time.process_time() - start, tuple(contacts), conditions)


def _plan(block: Blocking, strategies: list[DerivedStrategy], name: str, directions: str,
          conditions: Conditions) -> Plan:
    """The strategies as a plan, through the plan checker (what ``opportune check`` reads back)."""
    from opportune.formats.loader import plan_from_dict

    doc = {"name": name, "description": (
        f"Derived from the parts' geometry (opportune derive): each part goes in by one straight translation "
        f"from far away along one of the directions {directions} ({', '.join(block.directions)}), sliding along "
        f"faces it touches, never through another part (penetration tolerance {block.tolerance:.6g} m). "
        + _supports_text(conditions)
        + "Each strategy is one choice of a way in per part; the plan admits exactly the feasible sequences."),
        "parts": list(block.parts), "strategies": []}
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


def _supports_text(conditions: Conditions) -> str:
    """The supports asked, as the plan's description states them."""
    text = f"The base {conditions.base} goes first. " if conditions.base else ""
    if conditions.needs:
        text += (f"{len(conditions.needs)} parts need a part in before them: under gravity one they rest on "
                 "(unless they rest on the fixture, as the first part must), with connected one they touch "
                 "(unless they go in first). ")
    return text
