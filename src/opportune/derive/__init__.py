"""Plans from the product's geometry: every feasible assembly sequence, derived from the parts' shapes.

:func:`derive` reads an assembly in its assembled pose (a folder of meshes, one file a part:
:mod:`opportune.derive.geometry`; a glTF/GLB scene or a STEP file: :mod:`opportune.derive.scene`; an MJCF
model: :mod:`opportune.derive.mjcf`) and
its manifest (:mod:`opportune.derive.manifest`), finds which parts block each part's straight insertion along each
direction (:mod:`opportune.derive.blocking`) and writes the plan that admits exactly the feasible
sequences (:mod:`opportune.derive.plan`).  Needs the ``geometry`` extra (``pip install
'opportune[geometry]'``: trimesh reads the meshes).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from typing import Mapping, Sequence

from opportune.derive.blocking import AXES, Blocking, find_blocking
from opportune.derive.contacts import Contact, find_contacts
from opportune.derive.directions import default_directions, parse_directions, support_conditions
from opportune.derive.geometry import SCENE_SUFFIXES, Assembly, GeometryError, read_assembly
from opportune.derive.manifest import (MANIFEST, Manifest, ManifestError, check_interchangeable, check_parts,
                                       manifest_from, merge_units, part_ids, read_manifest, unit_pairs,
                                       without_fixture)
from opportune.derive.plan import (Conditions, DeriveError, DerivedStrategy, TooManyStrategies, alternatives,
                                   exact_strategies, options)
from opportune.derive.mjcf import read_mjcf_assembly
from opportune.derive.scene import read_scene_assembly
from opportune.planning.plan import Plan, PlanError, Way

__all__ = ["derive", "Derivation", "DeriveError", "GeometryError", "ManifestError", "DIRECTION_SETS", "plan_of"]

#: The direction sets ``--directions`` names.
DIRECTION_SETS = {"axes": AXES}


@dataclass(frozen=True)
class Derivation:
    """A derived plan with what it was derived from: the blocking relation, the contacts, the supports
    each part needed, the strategies with each part's way in, and the CPU seconds taken.

    :func:`derive` makes it; it is data (frozen), read by ``derive --json`` (:meth:`to_dict`), by
    :func:`~opportune.derive.explain.explain` and by :func:`~opportune.derive.figure.exploded`.

    Parameters
    ----------
    plan : Plan
        The derived plan (:class:`~opportune.planning.plan.Plan`): exactly the feasible sequences.
    blocking : Blocking
        The blocking relation: for each part and direction, the parts in the way of its straight
        insertion (:class:`~opportune.derive.blocking.Blocking`).
    strategies : tuple of DerivedStrategy
        The plan's strategies with each part's way in (a direction, and the parts it rests on or
        touches) and their constraints as ``(before, after)`` pairs.
    seconds : float
        CPU seconds the derivation took.
    contacts : tuple of Contact
        The contacts between parts (found only where the directions or the supports need them).
    conditions : Conditions
        The supports each part needed (``gravity``, ``connected``) and the base.
    assembly : Assembly, optional
        The parts' geometry (the figure and the explanation's added directions read it).
    notes : tuple of str
        What the plan does not carry of the shapes (said on standard error by the command).
    manifest : Manifest, optional
        The manifest the plan was derived under (names, quantities, base, fixture, process constraints):
        :meth:`replanned` derives again under it.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from opportune.derive.examples import box, cut, obj_text
    >>> tmp = tempfile.TemporaryDirectory()
    >>> _ = (Path(tmp.name) / "cup.obj").write_text(obj_text(cut((0, 0, 0), (3, 3, 2), [((1, 1, 1), (2, 2, 3))])))
    >>> _ = (Path(tmp.name) / "peg.obj").write_text(obj_text([box((1, 1, 1), (2, 2, 2))]))
    >>> d = derive(tmp.name, directions="axes", gravity="-z")     # the peg rests in the cup
    >>> d.strategies[0]
    DerivedStrategy(directions={'cup': '+z', 'peg': '-z on cup'}, pairs=(('cup', 'peg'),))
    >>> sorted(d.blocking.blockers["peg"]["+x"]), d.plan.parts[1].id
    (['cup'], 'peg')
    >>> tmp.cleanup()
    """

    plan: Plan
    blocking: Blocking
    strategies: tuple[DerivedStrategy, ...]
    seconds: float
    contacts: tuple[Contact, ...] = ()
    conditions: Conditions = Conditions({})
    assembly: Assembly | None = None
    notes: tuple[str, ...] = ()
    manifest: Manifest | None = None

    def replanned(self, block: Blocking) -> Plan:
        """The plan of another blocking relation over the same parts, derived under this derivation's
        conditions: the manifest's quantities, base, fixture and process constraints, and the supports
        (``gravity``, ``connected``) each part needed.  What ``derive --explain`` recounts.

        Parameters
        ----------
        block : Blocking
            The changed relation (a part out of everyone's way, a direction added).

        Returns
        -------
        Plan
            Its exact plan, named as this one.

        Raises
        ------
        DeriveError
            No feasible sequence, or a plan larger than a plan holds.
        ManifestError
            Instances of one part the changed relation tells apart.

        Examples
        --------
        >>> d = derive("geometry:gearbox")
        >>> d.replanned(d.blocking).strategies == d.plan.strategies
        True
        """
        man = self.manifest if self.manifest is not None else manifest_from({})
        return _plan_under(block, man, self.conditions, self.plan.name, "changed")[0]

    def blocking_along(self, directions: dict) -> Blocking:
        """The blocking relation of this derivation's parts along other directions, found in its assembly,
        the fixture (if any) in place: a direction along which the fixture is in a part's way is none for it.

        Parameters
        ----------
        directions : dict
            Name → vector.

        Returns
        -------
        Blocking
            Over the derivation's parts and those directions only.

        Raises
        ------
        ValueError
            A derivation without its assembly.

        Examples
        --------
        >>> d = derive("geometry:gearbox")
        >>> d.blocking_along({"up": (0, 0, 1)}).blockers["cover"]["up"] == d.blocking.blockers["cover"]["+z"]
        True
        """
        if self.assembly is None:
            raise ValueError("this derivation carries no assembly: derive from the geometry")
        more = find_blocking(self.assembly, directions)
        fixture = self.manifest.fixture if self.manifest is not None else None
        blockers = {p: {d: q for d, q in more.blockers[p].items() if fixture is None or fixture not in q}
                    for p in self.blocking.parts}
        return Blocking(self.blocking.parts, dict(more.directions), blockers, more.tolerance, more.checks)

    def to_dict(self) -> dict:
        """The numbers of the derivation, as ``derive --json`` prints them (the plan aside).

        Returns
        -------
        dict
            Parts, directions, tolerance (metres), blocking checks, contacts, strategies, constraints,
            CPU seconds, the base, each part's supports and blockers, and each strategy's directions: plain
            data (lists, not sets), ready for JSON.

        Examples
        --------
        >>> d = derive("geometry:gearbox")
        >>> row = d.to_dict()
        >>> row["parts"], row["strategies"], row["blockers"]["cover"]["+x"]
        (14, 10, ['screw_1', 'screw_2', 'screw_3', 'screw_4'])
        """
        b = self.blocking
        return {"parts": len(b.parts), "directions": list(b.directions), "tolerance_m": b.tolerance,
                "blocking_checks": b.checks, "contacts": len(self.contacts), "strategies": len(self.strategies),
                "constraints": sum(len(s.pairs) for s in self.strategies), "cpu_seconds": round(self.seconds, 4),
                "base": self.conditions.base,
                "supports": {p: {kind: sorted(n) for kind, n in needs} for p, needs in self.conditions.needs.items()},
                "blockers": {p: {d: sorted(q) for d, q in dirs.items()} for p, dirs in b.blockers.items()},
                "directions_by_strategy": [s.directions for s in self.strategies]}


def derive(source: str | Path | Assembly, *, directions: str | Sequence | dict | None = None,
           tolerance: float | None = None, units: str = "m", name: str | None = None, gravity: str | None = None,
           connected: bool = False, base: str | None = None, manifest: str | Path | None = None,
           names: Mapping[str, str] | None = None, quantities: Mapping[str, Sequence[str]] | None = None,
           fixture: str | None = None, requires: Mapping[str, Sequence[str]] | None = None,
           form: str = "auto") -> Derivation:
    """Derive the plan of an assembly: exactly the sequences feasible under the motion model.

    Parameters
    ----------
    source : str, Path or Assembly
        The assembly in its assembled pose: a folder of meshes, one file a part (``.obj``, ``.stl``,
        ``.ply``; the id is the file's stem), a glTF/GLB scene (each named node with a mesh a part), a
        MuJoCo MJCF model (each named body with geoms a part), ``geometry:NAME`` (a shipped assembly:
        ``gearbox``, ``pump``, ``puzzle``), or an assembly already read.
    directions : str, list or dict, optional
        The insertion directions: ``"axes"`` (the six axis directions), a text list such as
        ``"+z,-x,0 0.7 0.7"``, a list of axis names and ``[x, y, z]`` vectors, or names and vectors.
        Default: the manifest's, else the axes and the normals of the contacts between parts.
    tolerance : float, optional
        Penetration tolerance in the files' units (default: a millionth of the assembly's size).
    units : str
        ``"m"`` or ``"mm"``: the files' unit of length.
    name : str, optional
        The plan's name (default: the folder's or file's name).
    gravity : str, optional
        The direction of gravity (``"-z"``): each part rests on a part below it that it touches, or on the
        fixture (its lowest point at the assembly's lowest level; the first part must, unless it is the base).
    connected : bool
        Each part after the first touches a part already in.
    manifest : str or Path, optional
        The assembly's manifest (:mod:`opportune.derive.manifest`); default ``assembly.yaml`` in the folder,
        if there is one.
    names, quantities, base, fixture, requires : optional
        As the manifest's keys, replacing them: display names; identical parts (a part id: its instances);
        the part installed first (it needs no support); the part in place from the start (not installed); process constraints
        (a part id: the parts before it), added to every strategy.
    form : str
        ``"auto"`` (strategies where the exact union of partial orders fits a plan, else each part's ways
        in: :mod:`opportune.derive.ways`), ``"strategies"`` (refused where they do not fit) or ``"ways"``.

    Returns
    -------
    Derivation
        ``.plan`` (a :class:`~opportune.planning.plan.Plan`, checked as a plan file is), the blocking
        relation and the strategies' directions.

    Raises
    ------
    GeometryError
        A folder, scene or mesh that cannot be used (the message names the file and the part).
    ManifestError
        A manifest (or keyword) that cannot be used: every problem, with its file, line and key.
    DeriveError
        No feasible sequence (the parts that lock each other named), an exact plan larger than a plan holds
        (``form="strategies"``), or an unknown ``form``.

    Examples
    --------
    A cup and a peg that stands in it, written as two OBJ files (a shipped assembly, ``geometry:gearbox``,
    is used the same way).  Along the six axes each can go in by itself (the cup from below, the peg from
    above), so the plan admits both orders; under gravity the peg rests on the cup, which goes first:

    >>> import tempfile
    >>> from pathlib import Path
    >>> from opportune.derive.examples import box, cut, obj_text
    >>> from opportune.engine import Schedule
    >>> tmp = tempfile.TemporaryDirectory()
    >>> _ = (Path(tmp.name) / "cup.obj").write_text(obj_text(cut((0, 0, 0), (3, 3, 2), [((1, 1, 1), (2, 2, 3))])))
    >>> _ = (Path(tmp.name) / "peg.obj").write_text(obj_text([box((1, 1, 1), (2, 2, 2))]))
    >>> Schedule(derive(tmp.name, directions="axes").plan).count()
    2
    >>> derived = derive(tmp.name, directions="axes", gravity="-z", names={"peg": "locating peg"})
    >>> [s.pairs for s in derived.strategies], Schedule(derived.plan).count(), derived.plan.parts[1].name
    ([(('cup', 'peg'),)], 1, 'locating peg')

    A process constraint against the geometry is refused, and so is a folder that is not there:

    >>> derive(tmp.name, directions="axes", gravity="-z", requires={"cup": ["peg"]})
    Traceback (most recent call last):
    ...
    opportune.derive.plan.DeriveError: no feasible sequence keeps the process constraints (1 order, ...
    >>> tmp.cleanup()
    >>> derive("no-such-folder")
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: no-such-folder: not a folder; give a folder of meshes, one file a part (.obj, .stl, .ply)
    """
    start = time.process_time()
    source = _resolve(source)
    man = _manifest(source, manifest, {"names": names, "quantities": quantities, "base": base, "fixture": fixture,
                                       "requires": requires, "directions": directions})
    label, given = _direction_set(directions, man)
    assembly, title = _read(source, units, tolerance)
    check_parts(man, [p.id for p in assembly.parts])
    # contacts only where something asks for them: the supports, or the default directions
    contacts = find_contacts(assembly) if given is None or gravity is not None or connected else []
    ids = {p.id for p in assembly.parts}
    conditions = support_conditions(assembly, contacts, gravity=gravity, connected=connected,
                                    base=man.base if man.base in ids else None)
    block = find_blocking(assembly, default_directions(contacts) if given is None else given)
    if man.fixture is not None:
        block = without_fixture(block, man.fixture)
        conditions = _held_by_fixture(conditions, man.fixture)
    from opportune.derive.shapes import shapes

    carried, notes = shapes(assembly)
    plan, strategies, why = _plan_under(block, man, conditions, name or title or "assembly", label, carried, form)
    if why:
        notes = [why] + list(notes)
    return Derivation(plan, block, tuple(strategies), time.process_time() - start, tuple(contacts), conditions,
                      assembly, tuple(notes), man)


def _plan_under(block: Blocking, man: Manifest, conditions: Conditions, name: str, label: str,
                carried: dict | None = None, form: str = "auto") -> tuple[Plan, list[DerivedStrategy], str]:
    """The exact plan of a blocking relation under the manifest and the supports, its strategies over
    instances (none where it is written as ways) and why it is written as ways (or ""): the one place a
    derivation's conditions meet its relation (:func:`derive`, and :meth:`Derivation.replanned` for the
    explanation's recounts)."""
    check_interchangeable(man, _ways(block, conditions))
    strategies, ways, why = _exact(block, conditions, man, form)
    written = []
    if ways is None:
        try:
            written = merge_units(man, block.parts, strategies)
        except ManifestError as exc:    # a part between two identical instances: the ways form says it
            if form != "auto":
                raise
            strategies, ways = [], _units_ways(block, conditions, man)
            why = (f"{exc.problems[0].message} in a plan of strategies: the plan is written as each part's ways in "
                   "instead, as exact (docs/derive.md)")
    plan = plan_of(block, written, name, label, carried, manifest=man, conditions=conditions, ways=ways)
    return plan, strategies, why


FORMS = ("auto", "strategies", "ways")


def _exact(block: Blocking, conditions: Conditions, man: Manifest, form: str) -> tuple[list, dict | None, str]:
    """The exact plan: strategies (and None), or no strategies and each part's ways with why."""
    if form not in FORMS:
        raise DeriveError(f"form {form!r}: give one of {', '.join(FORMS)}")
    pairs = unit_pairs(man, block.parts)
    if form != "ways":
        try:
            return exact_strategies(block, conditions, pairs), None, ""
        except TooManyStrategies as exc:
            if form == "strategies":
                raise
            said = str(exc).split(": give fewer")[0].replace(", and the engine counts and runs unions of partial "
                                                             "orders only", "")
            why = f"{said}: the plan is written as each part's ways in instead, as exact (docs/derive.md)"
    else:
        why = "written as each part's ways in (exact), as asked"
    return [], _units_ways(block, conditions, man), why


def _units_ways(block: Blocking, conditions: Conditions, man: Manifest) -> dict:
    """Each part's ways in, identical instances as the units of their part (:mod:`opportune.derive.ways`)."""
    from opportune.derive.ways import as_units, exact_ways

    return as_units(exact_ways(block, conditions, unit_pairs(man, block.parts)), man.quantities)


def _resolve(source):
    """A shipped assembly's folder for ``geometry:NAME``; any other source as it is."""
    if isinstance(source, Assembly):
        return source
    from opportune.formats.shipped import resolve_assembly

    try:
        return resolve_assembly(source)
    except KeyError as exc:
        raise GeometryError(exc.args[0]) from None


def _read(source, units: str, tolerance: float | None) -> tuple[Assembly, str]:
    """The assembly and its title (the folder's or file's name)."""
    if isinstance(source, Assembly):
        return source, "assembly"
    whole = Path(source).resolve()
    return _reader(source)(source, units=units, tolerance=tolerance), whole.name if whole.is_dir() else whole.stem


def _held_by_fixture(conditions: Conditions, fixture: str) -> Conditions:
    """The supports with the fixture in place from the start: a requirement it meets is met."""
    needs = {p: tuple((kind, n) for kind, n in needs if fixture not in n)
             for p, needs in conditions.needs.items() if p != fixture}
    return Conditions({p: n for p, n in needs.items() if n}, conditions.base, conditions.waived_first)


def _ways(block: Blocking, conditions: Conditions) -> dict:
    """Each part's ways in, as the check of identical instances compares them: the blocker sets, or with
    supports or a base the (after, before) sets of each way."""
    if not conditions.needs and conditions.base is None:
        return options(block)
    return {p: [(w.name, (w.after, w.before)) for w in ws] for p, ws in alternatives(block, conditions).items()}


def _reader(path):
    """The reader of an assembly: a folder of meshes, a glTF/GLB or STEP scene, or an MJCF model."""
    suffix = Path(path).suffix.lower()
    if Path(path).is_dir() or suffix not in SCENE_SUFFIXES:
        return read_assembly
    return read_mjcf_assembly if suffix in (".xml", ".mjcf") else read_scene_assembly


def _manifest(path, file, keywords: dict) -> Manifest:
    """The manifest: the file's (given, or ``assembly.yaml`` in the folder), its keys replaced by the keywords given."""
    if file is None and not isinstance(path, Assembly) and Path(path).is_dir() and (Path(path) / MANIFEST).is_file():
        file = Path(path) / MANIFEST
    doc = read_manifest(file) if file is not None else {"data": {}, "lines": {}, "file": None}
    if not isinstance(doc["data"], dict):
        return manifest_from(doc["data"], file=doc["file"])     # refused, saying what a manifest is
    data = doc["data"]
    given = {k: v for k, v in keywords.items()
             if v is not None and not (k == "directions" and isinstance(v, (str, dict)))}
    lines = {k: v for k, v in doc["lines"].items() if not (k and k[0] in given)}
    return manifest_from({**data, **given}, file=doc["file"], lines=lines)


def _direction_set(directions, man: Manifest) -> tuple[str, dict | None]:
    """The directions' label (for the plan's description) and vectors (None: the axes and the contacts'
    normals): a named set, a text list, names and vectors, or the manifest's list."""
    if isinstance(directions, str):
        if directions in DIRECTION_SETS:
            return directions, DIRECTION_SETS[directions]
        return "listed", parse_directions(directions)
    if isinstance(directions, dict):
        return "listed", directions
    if man.directions:
        return "listed", man.directions
    return "the axes and the contacts' normals", None


def plan_of(block: Blocking, written: list, name: str, directions: str, shapes: dict[str, dict] | None = None, *,
            manifest: Manifest | None = None, conditions: Conditions | None = None,
            ways: Mapping | None = None) -> Plan:
    """The strategies as a plan, through the plan checker (what ``opportune check`` reads back).

    Parameters
    ----------
    block : Blocking
        The blocking relation (its directions and tolerance are stated in the plan's description).
    written : list
        What :func:`~opportune.derive.plan.exact_strategies` found, or
        :func:`~opportune.derive.manifest.merge_units`' ``(strategy, pairs)`` with identical parts merged.
    name : str
        The plan's name.
    directions : str
        The name of the direction set, as the description states it.
    shapes : dict, optional
        Part id → its ``geometry`` (:func:`opportune.derive.shapes.shapes`), carried by the plan.
    manifest : Manifest, optional
        Names, quantities, base, fixture and process constraints, as the plan states them.
    conditions : Conditions, optional
        The supports asked (``gravity``, ``connected``), as the description states them.
    ways : mapping of str to tuple of Way, optional
        Each part's ways in (:func:`opportune.derive.ways.exact_ways`): the plan is written as ways, and
        ``written`` is empty.

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
    man = manifest if manifest is not None else manifest_from({})
    conditions = conditions if conditions is not None else Conditions({})
    written = [w if isinstance(w, tuple) else (w, w.pairs) for w in written]
    from opportune.formats.loader import plan_from_dict

    extra = "".join([f" {man.fixture} is in place from the start (the fixture)." if man.fixture else "",
                     f" {man.base} is installed first (the base)." if man.base else "",
                     f" {len(man.requires)} process constraints are in every strategy." if man.requires else ""])
    doc = {"name": name, "description": (
        f"Derived from the parts' geometry (opportune derive): each part goes in by one straight translation "
        f"from far away along one of the directions {directions} ({', '.join(block.directions)}), sliding along "
        f"faces it touches, never through another part (penetration tolerance {block.tolerance:.6g} m). "
        + _supports_text(conditions)
        + ("Each strategy is one choice of a way in per part; " if ways is None else
           "Each part lists its ways in (a direction, the parts it must go in before, the supports it needs); ")
        + "the plan admits exactly the feasible sequences." + extra), "parts": []}
    if ways is not None:
        doc["ways"] = {p: [w.to_dict() for w in ws] for p, ws in ways.items() if ws != (Way(),)}
    else:
        doc["strategies"] = []
    for pid in part_ids(man, block.parts):
        quantity = len(man.quantities.get(pid, (pid,)))
        entry = {"id": pid, **({"name": man.names[pid]} if pid in man.names else {}),
                 **({"quantity": quantity} if quantity > 1 else {}),
                 **({"geometry": shapes[shape]} if shapes and (shape := man.quantities.get(pid, (pid,))[0]) in shapes
                    else {})}
        doc["parts"].append(entry if len(entry) > 1 else pid)
    for k, (s, pairs) in enumerate(written, 1):
        requires: dict[str, list[str]] = {}
        for before, after in pairs:
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
