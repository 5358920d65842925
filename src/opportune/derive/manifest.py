"""An assembly's manifest: what the geometry does not say.

A YAML file, ``assembly.yaml`` in the assembly's folder or given as ``derive --manifest FILE``; every key
optional::

    names: {ca: casing, sh: main shaft}      # display names, by part id
    quantities: {bolt: [bolt_1, bolt_2]}     # identical parts: the instances (files, nodes, bodies) of one part
    base: ca                                 # installed first: every other part after it
    fixture: jig                             # in place before the assembly starts; not installed
    directions: [+x, -x, +z, [0, 1, -1]]     # the insertion directions (axis names or vectors), or "axes"
    requires: {co: [sh, ba]}                 # process constraints, added to every strategy

It is checked as a plan file is (:mod:`opportune.formats.validate`): its size before it is read, its YAML
bounded (:func:`opportune.formats.loader.parse_yaml`), unknown keys, values of the wrong kind, text with
control characters, counts over :mod:`opportune.limits`, process constraints in a cycle; then, once the
geometry's part ids are known, unknown parts.  Every problem says where (file, line, key) and what to
do; all are reported at once, as :class:`ManifestError`.

Quantities are exact (:func:`unit_pairs`, :func:`merge_units`): the instances of a part are derived as
distinct parts with the order ``first < second < …`` added (they are interchangeable, so a sequence of
part ids is feasible iff it is with the instances in that order), then each strategy is written with the
part's quantity, which applies every constraint on the part to each unit.  Instances that the geometry
does not treat alike, or a strategy that would put another part between two of them, are refused.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

from opportune.derive.blocking import AXES, Blocking
from opportune.derive.plan import DeriveError, DerivedStrategy, reduction
from opportune.derive.scene import shown
from opportune.engine.poset import Poset, bits
from opportune.formats.problems import CONTROL_CHARS, Problem, did_you_mean, unknown_part_hint
from opportune.limits import (MAX_DIRECTIONS, MAX_ID, MAX_MANIFEST_BYTES, MAX_MESH_PARTS, MAX_PROCESS, MAX_TEXT)

#: Problems a message lists at most (a manifest may hold one on each of thousands of lines).
SHOWN = 20
#: The manifest's file name in an assembly's folder.
MANIFEST = "assembly.yaml"
#: The manifest's keys, and what each holds (for the message on an unknown key).
KEYS = {"names": "part id: display name", "quantities": "part id: [instance, ...]", "base": "a part id",
        "fixture": "a part id", "directions": "axes, or a list of +x, -x, ... or [x, y, z]",
        "requires": "part id: [parts before it, ...]"}
#: Characters no text of a manifest may hold: as a plan's (control characters, lone surrogates).
_BAD_CHAR = re.compile(f"[\ud800-\udfff{CONTROL_CHARS}]")


class ManifestError(ValueError):
    """A manifest that cannot be used: every problem, each saying where and what to do.

    Parameters
    ----------
    problems : sequence of Problem
        Every problem found (kept as ``.problems``); the message lists the first :data:`SHOWN`, each
        with its file, line and key where known and what to give instead.

    Examples
    --------
    >>> manifest_from({"base": 3, "colours": {}})
    Traceback (most recent call last):
    ...
    opportune.derive.manifest.ManifestError: unknown key 'colours' — the keys are names, quantities, base, ...
    base: 3 is not a part id — give one part id of 1 to 200 printable characters
    """

    def __init__(self, problems: Sequence[Problem]):
        self.problems = list(problems)
        lines = [f"{p.where + ': ' if p.where else ''}{p.message}" + (f" — {p.hint}" if p.hint else "")
                 for p in self.problems[:SHOWN]]
        if len(self.problems) > SHOWN:
            lines.append(f"… {len(self.problems) - SHOWN:,} more problems")
        super().__init__("\n".join(lines))


@dataclass(frozen=True)
class Manifest:
    """What a manifest (or :func:`opportune.derive.derive`'s keywords) says, checked for form.

    ``requires`` is a tuple of ``(before, after)`` part-id pairs; ``directions`` maps a direction's name
    to its unit vector (None: the ``directions`` argument of the derivation decides).
    """

    names: dict[str, str] = field(default_factory=dict)
    quantities: dict[str, tuple[str, ...]] = field(default_factory=dict)
    base: str | None = None
    fixture: str | None = None
    directions: dict[str, tuple[float, float, float]] | None = None
    requires: tuple[tuple[str, str], ...] = ()
    file: str | None = None
    lines: dict = field(default_factory=dict, repr=False)

    def where(self, *path) -> dict:
        """A problem's place: the file and the line of ``path`` (its nearest ancestor's)."""
        while path and path not in self.lines:
            path = path[:-1]
        return {"file": self.file, "line": self.lines.get(path)}


def read_manifest(path: str | Path) -> dict:
    """A manifest file's document, with the line of each value: size and YAML bounded, nothing checked yet.

    Parameters
    ----------
    path : str or Path
        The YAML file.

    Returns
    -------
    dict
        ``{"data": ..., "lines": ..., "file": ...}``, for :func:`manifest_from`.

    Raises
    ------
    ManifestError
        A file missing, over :data:`~opportune.limits.MAX_MANIFEST_BYTES`, not UTF-8 or not YAML within
        the plan files' bounds.

    Examples
    --------
    >>> read_manifest("no-such.yaml")
    Traceback (most recent call last):
    ...
    opportune.derive.manifest.ManifestError: no-such.yaml: no such file — give the assembly's manifest (YAML)
    """
    from opportune.formats.loader import parse_yaml

    path = Path(path)
    name = shown(str(path))
    if not path.is_file():
        raise ManifestError([Problem("no such file", "give the assembly's manifest (YAML)", file=name)])
    size = path.stat().st_size
    if size > MAX_MANIFEST_BYTES:
        raise ManifestError([Problem(f"{size:,} bytes; a manifest has at most {MAX_MANIFEST_BYTES:,}",
                                     "a manifest names parts: keep it short", file=name, code="limit")])
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ManifestError([Problem(f"not UTF-8 text (byte {exc.start + 1})", "save the file as UTF-8",
                                     file=name)]) from None
    doc = parse_yaml(text, name)
    if doc.problems:
        raise ManifestError(doc.problems)
    data = {} if doc.data is None else doc.data
    return {"data": data, "lines": doc.lines, "file": name}


def manifest_from(data, *, file: str | None = None, lines: dict | None = None) -> Manifest:
    """Check a manifest's document for form (keys, kinds, text, counts, cycles) and read it.

    Parameters
    ----------
    data : dict
        The document (a manifest file's, or the derivation's keywords).
    file : str, optional
        Where it comes from, for the messages.
    lines : dict, optional
        The line of each value (paths of keys and indices).

    Returns
    -------
    Manifest
        The manifest, part ids not yet checked against the geometry (:func:`check_parts`).

    Raises
    ------
    ManifestError
        Every problem found, each with its place and what to do.

    Examples
    --------
    >>> manifest_from({"requires": {"b": ["a"]}}).requires
    (('a', 'b'),)
    >>> manifest_from({"name": "x"}, file="assembly.yaml")
    Traceback (most recent call last):
    ...
    opportune.derive.manifest.ManifestError: assembly.yaml: unknown key 'name' — did you mean 'names'? the keys are names, quantities, base, fixture, directions, requires
    """
    found: list[Problem] = []
    man = Manifest(file=file, lines=lines or {})

    def bad(path: tuple, message: str, hint: str, code: str = "invalid") -> None:
        found.append(Problem(f"{_path(path)}: {message}" if path else message, hint, code=code, **man.where(*path)))

    if not isinstance(data, dict):
        bad((), "the manifest is not a mapping of keys", "write key: value lines (names, quantities, ...)")
        raise ManifestError(found)
    for key in data:
        if key not in KEYS:
            found.append(Problem(f"unknown key {str(key)!r}", did_you_mean(str(key), KEYS) + "the keys are "
                                 + ", ".join(KEYS), **man.where(key)))
    names = _mapping(data, "names", bad, lambda v: _text(v, MAX_TEXT), "a display name (text)")
    quantities = _mapping(data, "quantities", bad, _instances, f"a list of 2 to {MAX_MESH_PARTS} instance ids")
    requires = _mapping(data, "requires", bad, _id_list, "a list of part ids")
    single = {k: data[k] for k in ("base", "fixture") if k in data and data[k] is not None}
    for k, v in single.items():
        if not _text(v, MAX_ID):
            bad((k,), f"{_describe(v)} is not a part id{_why(v, MAX_ID)}", f"give one part id of 1 to {MAX_ID} "
                "printable characters")
    directions = _directions(data.get("directions"), bad) if data.get("directions") is not None else None
    pairs = tuple((b, a) for a, bs in requires.items() for b in bs)
    if len(pairs) > MAX_PROCESS:
        bad(("requires",), f"{len(pairs):,} process constraints; a manifest has at most {MAX_PROCESS:,}",
            "keep the constraints the process needs", "limit")
    if not found:
        _cycle(pairs, bad)
    if found:
        raise ManifestError(found)
    return Manifest({str(k): v for k, v in names.items()}, {str(k): tuple(v) for k, v in quantities.items()},
                    single.get("base"), single.get("fixture"), directions, pairs, file, lines or {})


def _mapping(data: dict, key: str, bad, ok, what: str) -> dict:
    """``data[key]``'s entries whose key is a part id and whose value is ``ok``; problems for the rest."""
    value = data.get(key)
    if value is None:
        return {}
    if not isinstance(value, dict):
        bad((key,), f"{_describe(value)} is not a mapping", f"write {key}: {{part id: {what}}}")
        return {}
    if len(value) > MAX_MESH_PARTS:
        bad((key,), f"{len(value):,} entries; an assembly has at most {MAX_MESH_PARTS:,} parts",
            "derive subassemblies separately", "limit")
        return {}
    good = {}
    for k, v in value.items():
        if not _text(k, MAX_ID):
            bad((key, k), f"{_describe(k)} is not a part id{_why(k, MAX_ID)}", f"give part ids of 1 to {MAX_ID} "
                "printable characters")
        elif not ok(v):
            bad((key, k), f"{_describe(v)} is not {what}{_why(v, MAX_TEXT)}", f"give {what}")
        else:
            good[k] = v
    return good


def _why(value, most: int) -> str:
    """Why a string is not text a manifest takes (``""`` for other values: the kind says it)."""
    if not isinstance(value, str):
        return ""
    if _BAD_CHAR.search(value):
        return ": it holds a control character (a terminal would act on it)"
    if len(value) > most:
        return f": {len(value):,} characters, over {most:,}"
    return ": it is empty" if not value else ""


def _text(value, most: int) -> bool:
    """Text of 1 to ``most`` characters without control characters."""
    return isinstance(value, str) and 0 < len(value) <= most and not _BAD_CHAR.search(value)


def _id_list(value) -> bool:
    return isinstance(value, list) and all(_text(v, MAX_ID) for v in value)


def _instances(value) -> bool:
    return (isinstance(value, list) and 2 <= len(value) <= MAX_MESH_PARTS and all(_text(v, MAX_ID) for v in value)
            and len(set(value)) == len(value))


def _directions(value, bad) -> dict[str, tuple[float, float, float]]:
    """The directions' names and unit vectors: ``axes``, or a list of axis names and ``[x, y, z]`` vectors."""
    if value == "axes":
        return dict(AXES)
    hint = "give axes, or a list of +x, -x, +y, -y, +z, -z and [x, y, z] vectors"
    if not isinstance(value, list) or not value:
        bad(("directions",), f"{_describe(value)} is not a list of directions", hint)
        return {}
    if len(value) > MAX_DIRECTIONS:
        bad(("directions",), f"{len(value):,} directions; a manifest lists at most {MAX_DIRECTIONS}",
            "fewer directions: every part's choices multiply", "limit")
        return {}
    out: dict[str, tuple[float, float, float]] = {}
    for i, d in enumerate(value):
        if isinstance(d, str) and d in AXES:
            name, vector = d, AXES[d]
        elif (isinstance(d, list) and len(d) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                           and math.isfinite(x) for x in d)
              and math.hypot(*d) > 0):
            norm = math.hypot(*d)
            name, vector = "[" + " ".join(f"{x:g}" for x in d) + "]", tuple(x / norm for x in d)
        else:
            bad(("directions", i), f"{_describe(d)} is not a direction", hint)
            continue
        if any(max(abs(a - b) for a, b in zip(vector, v)) < 1e-9 for v in out.values()):
            bad(("directions", i), f"direction {name} is listed twice", "list each direction once")
        out[name] = vector
    return out


def _cycle(pairs, bad) -> None:
    """A problem for process constraints in a cycle (no sequence could keep them)."""
    from opportune.formats.validate import find_cycles

    ids = sorted({p for pair in pairs for p in pair})
    req: dict[str, list[str]] = {}
    for b, a in pairs:
        req.setdefault(a, []).append(b)
    for b, a in pairs:
        if a == b:
            bad(("requires", a), f"process constraints in a cycle: {shown(a)} before {shown(a)}",
                "drop it: a part cannot go in before itself")
    for cycle in find_cycles(ids, req):
        bad(("requires", cycle[1]), "process constraints in a cycle: " + " before ".join(map(shown, cycle)),
            "drop one of them: no sequence can keep a cycle")


def check_parts(man: Manifest, instances: Sequence[str]) -> None:
    """Check the manifest's part ids against the geometry's (its files', nodes' or bodies' ids).

    Parameters
    ----------
    man : Manifest
        The manifest.
    instances : sequence of str
        The assembly's ids, as read.

    Raises
    ------
    ManifestError
        An instance or part unknown, an instance of two parts, a part id that is also another instance's, a
        fixture that is also base, listed among quantities or constrained.

    Examples
    --------
    >>> check_parts(manifest_from({"base": "ca"}), ["ca", "co"])
    >>> check_parts(manifest_from({"base": "cx"}), ["ca", "co"])
    Traceback (most recent call last):
    ...
    opportune.derive.manifest.ManifestError: base: unknown part 'cx' — the assembly's parts are ca, co
    """
    found: list[Problem] = []
    known = set(instances)
    grouped: dict[str, str] = {}
    for part, group in man.quantities.items():
        for inst in group:
            if inst not in known:
                found.append(_unknown(man, ("quantities", part), inst, instances, "instance"))
            elif inst in grouped:
                found.append(Problem(f"quantities: {inst!r} is an instance of {grouped[inst]!r} and "
                                     f"of {part!r}", "list each instance under one part",
                                     **man.where("quantities", part)))
            grouped.setdefault(inst, part)
    parts = [i for i in instances if i not in grouped] + list(man.quantities)
    for part in man.quantities:
        if part in known and grouped.get(part) != part:
            found.append(Problem(f"quantities: part id {part!r} is also another part's id",
                                 "give the identical parts an id of their own", **man.where("quantities", part)))
    named = [(("names", k), k) for k in man.names] + [(("base",), man.base)] * (man.base is not None)
    named += [(("requires", a), p) for b, a in man.requires for p in (b, a)]
    for path, pid in named:
        if pid not in parts:
            found.append(_unknown(man, path, pid, parts, "part"))
    if man.fixture is not None:
        if man.fixture not in known or man.fixture in grouped:
            found.append(_unknown(man, ("fixture",), man.fixture, [i for i in instances if i not in grouped], "part"))
        elif man.fixture == man.base or man.fixture in {p for pair in man.requires for p in pair}:
            found.append(Problem("fixture: the fixture is in place from the start: it is not installed",
                                 "do not name it as base or in requires", **man.where("fixture")))
    if found:
        raise ManifestError(found)


def _unknown(man: Manifest, path: tuple, pid: str, known, what: str) -> Problem:
    return Problem(f"{_path(path)}: unknown {what} {pid!r}",
                   unknown_part_hint(shown(pid), sorted(known), "the assembly's parts"), **man.where(*path))


def _path(path: tuple) -> str:
    return ".".join(shown(str(p)) for p in path)


def _describe(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


# ---------------------------------------------------------------- the units of identical parts


def unit_pairs(man: Manifest, instances: Sequence[str]) -> list[tuple[str, str]]:
    """The orders the manifest adds to every strategy, between instances: each part's instances in
    sequence, the base before every other part, and the process constraints (a part of several
    instances: before its first, after its last).

    Parameters
    ----------
    man : Manifest
        The manifest, checked against the instances.
    instances : sequence of str
        The instances derived (the fixture left out).

    Returns
    -------
    list of (str, str)
        ``(before, after)`` pairs of instances.

    Examples
    --------
    >>> man = manifest_from({"quantities": {"b": ["b1", "b2"]}, "requires": {"c": ["b"]}})
    >>> unit_pairs(man, ["a", "b1", "b2", "c"])
    [('b1', 'b2'), ('b2', 'c')]
    """
    group = {p: list(g) for p, g in man.quantities.items()}
    first = {p: g[0] for p, g in group.items()}
    last = {p: g[-1] for p, g in group.items()}
    pairs = [(g[i], g[i + 1]) for g in group.values() for i in range(len(g) - 1)]
    if man.base is not None:
        pairs += [(last.get(man.base, man.base), first.get(p, p)) for p in part_ids(man, instances) if p != man.base]
    pairs += [(last.get(b, b), first.get(a, a)) for b, a in man.requires]
    return pairs


def check_interchangeable(man: Manifest, options: Mapping[str, list[tuple[str, frozenset[str]]]]) -> None:
    """Refuse instances of one part that the geometry does not treat alike: swapping two neighbours of a
    part's list must map every part's minimal blocker sets onto the swapped part's.  (Feasibility depends
    on those sets only, and neighbour swaps generate every permutation: so all instances are
    interchangeable, and deriving them in one order loses no sequence of part ids.)

    Parameters
    ----------
    man : Manifest
        The manifest.
    options : dict
        Each instance's minimal blocker sets, by direction (:func:`opportune.derive.plan.options`), or with
        supports its ways in as ``(name, (after, before))`` (:func:`opportune.derive.plan.alternatives`).

    Raises
    ------
    ManifestError
        Two instances not interchangeable, named, with the part whose blockers tell them apart.

    Examples
    --------
    >>> opts = {"b1": [("+z", frozenset())], "b2": [("+z", frozenset({"c"}))], "c": [("+z", frozenset())]}
    >>> check_interchangeable(manifest_from({"quantities": {"b": ["b1", "b2"]}}), opts)
    Traceback (most recent call last):
    ...
    opportune.derive.manifest.ManifestError: quantities.b: instances 'b1' and 'b2' are not interchangeable in the assembly (part 'b1' goes in with other parts in its way than 'b2' would) — list them as separate parts
    """
    sets = {p: {q for _, q in opts} for p, opts in options.items()}
    for part, group in man.quantities.items():
        for a, b in zip(group, group[1:]):
            swap = {a: b, b: a}
            for p, family in sets.items():
                image = {_swapped(q, swap) for q in family}
                if image != sets.get(swap.get(p, p)):
                    raise ManifestError([Problem(
                        f"quantities.{shown(part)}: instances {a!r} and {b!r} are not interchangeable "
                        f"in the assembly (part {p!r} goes in with other parts in its way than "
                        f"{swap.get(p, p)!r} would)", "list them as separate parts",
                        **man.where("quantities", part))])


def _swapped(q, swap: dict):
    """A set of parts (or a tuple of such sets: a way's parts after and before) with two instances swapped."""
    if isinstance(q, tuple):
        return tuple(_swapped(x, swap) for x in q)
    return frozenset(swap.get(x, x) for x in q)


def merge_units(man: Manifest, ids: Sequence[str], strategies: Sequence[DerivedStrategy]
                ) -> list[tuple[DerivedStrategy, tuple[tuple[str, str], ...]]]:
    """Each strategy over instances (the instances of a part in sequence) as a strategy over part ids.

    A part of quantity *n* stands for its instances ``u1 < … < un``, and a constraint on it applies to
    each unit: so a strategy is written over part ids exactly when every other part before ``un`` is
    before ``u1``, and every part after ``u1`` after ``un`` (no part between two of them).

    Parameters
    ----------
    man : Manifest
        The manifest (its quantities).
    ids : sequence of str
        The instances, in the derivation's order.
    strategies : sequence of DerivedStrategy
        The strategies over instances.

    Returns
    -------
    list
        Each strategy with its ``(before, after)`` pairs over part ids (a transitive reduction).

    Raises
    ------
    ManifestError
        A strategy that puts a part between two instances of one part, named.
    """
    index = {p: i for i, p in enumerate(ids)}
    group_of = {inst: part for part, g in man.quantities.items() for inst in g}
    parts = part_ids(man, ids)
    first = {p: index[man.quantities[p][0]] if p in man.quantities else index[p] for p in parts}
    last = {p: index[man.quantities[p][-1]] if p in man.quantities else index[p] for p in parts}
    position = {first[p]: k for k, p in enumerate(parts)}    # a part's first instance: the part
    out = []
    for s in strategies:
        order = Poset.from_pairs(len(ids), [(index[a], index[b]) for a, b in s.pairs])
        for part, g in man.quantities.items():
            mine = sum(1 << index[i] for i in g)
            u1, un = index[g[0]], index[g[-1]]
            between = (order.below[un] & ~order.below[u1] & ~mine) | (order.above[u1] & ~order.above[un] & ~mine)
            if between:
                x = ids[next(bits(between))]
                raise ManifestError([Problem(
                    f"quantities.{shown(part)}: in some feasible sequences part {group_of.get(x, x)!r} goes "
                    f"in between two instances of {part!r}: a quantity cannot say that",
                    "list the instances as separate parts", **man.where("quantities", part))])
        # a before b iff a's last unit is before b's first (a closed order: last(a) < first(b) <= last(b) < ...)
        closure = tuple(sum(1 << position[i] for i in bits(order.above[last[p]]) if i in position) for p in parts)
        out.append((s, reduction(tuple(parts), closure)))
    return out


def part_ids(man: Manifest, instances: Sequence[str]) -> list[str]:
    """The part ids in the instances' order: an instance of its own, or a part of several at its first.

    Parameters
    ----------
    man : Manifest
        The manifest (its quantities).
    instances : sequence of str
        The instances.

    Returns
    -------
    list of str
        The plan's part ids.

    Examples
    --------
    >>> part_ids(manifest_from({"quantities": {"bolt": ["b1", "b2"]}}), ["a", "b1", "c", "b2"])
    ['a', 'bolt', 'c']
    """
    firsts = {g[0]: p for p, g in man.quantities.items()}
    grouped = {i for g in man.quantities.values() for i in g}
    return [firsts.get(i, i) for i in instances if i not in grouped or i in firsts]


def without_fixture(block: Blocking, fixture: str) -> Blocking:
    """The blocking relation with the fixture in place from the start: it is no part to install, and a
    direction along which it is in a part's way is no direction for that part.

    Parameters
    ----------
    block : Blocking
        The blocking relation over every part, the fixture's included.
    fixture : str
        The fixture's id.

    Returns
    -------
    Blocking
        The relation over the other parts.

    Raises
    ------
    DeriveError
        A part the fixture blocks along every direction, named.

    Examples
    --------
    >>> b = Blocking(("f", "a"), {"+z": (0, 0, 1), "-z": (0, 0, -1)},
    ...              {"f": {"+z": frozenset(), "-z": frozenset()}, "a": {"+z": frozenset("f"), "-z": frozenset()}}, 0, 0)
    >>> without_fixture(b, "f").blockers
    {'a': {'-z': frozenset()}}
    """
    blockers = {p: {d: q for d, q in dirs.items() if fixture not in q}
                for p, dirs in block.blockers.items() if p != fixture}
    stuck = [p for p, dirs in blockers.items() if not dirs]
    if stuck:
        raise DeriveError(f"part{'s' if len(stuck) > 1 else ''} {', '.join(map(shown, stuck[:20]))} cannot go in with "
                          f"the fixture {fixture!r} in place: it is in the way along every direction; give "
                          "more directions, or make the fixture a part (base) installed first")
    return Blocking(tuple(p for p in block.parts if p != fixture), block.directions, blockers, block.tolerance,
                    block.checks)
