"""The files shipped with the package, by name: the public SALBP precedence graphs (``salbp:NAME``) and
the examples (``example:NAME``), as paths the readers open (:mod:`opportune.datasets` loads them).

>>> salbp_names()[:3]
('MERTENS', 'BOWMAN8', 'JAESCHKE')
>>> names = [name for name, _, _ in examples()]
>>> "gearbox" in names and "gearbox-table1" in names
True
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

# Smallest first: the order of the data's README.
SALBP = ("MERTENS", "BOWMAN8", "JAESCHKE", "JACKSON", "MANSOOR", "MITCHELL", "HESKIA", "KILBRID",
         "TONGE70", "ARC111")
PREFIX = "salbp:"
EXAMPLE_PREFIX = "example:"
GEOMETRY_PREFIX = "geometry:"
#: The shipped assemblies (folders of meshes under ``examples/geometry``), for ``opportune derive``.
GEOMETRY = ("gearbox", "pump", "puzzle")


def shipped_folder(kind: str):
    """The folder of the shipped ``salbp`` graphs or ``examples`` (a ``Traversable``: a directory of the
    installed package, wherever it is).  ``opportune`` itself is named, not ``opportune.datasets``, so
    that finding a file loads nothing more."""
    return resources.files("opportune").joinpath("datasets").joinpath(kind)


def salbp_names() -> tuple[str, ...]:
    """The names of the shipped SALBP graphs, smallest first.

    Returns
    -------
    tuple of str
        Names for :func:`salbp_path` and ``salbp:NAME``.

    Examples
    --------
    >>> salbp_names()[-2:]
    ('TONGE70', 'ARC111')
    """
    return SALBP


def salbp_path(name: str) -> Path:
    """The file of a shipped SALBP graph (``.IN2``), by name.

    Parameters
    ----------
    name : str
        The graph's name, case-insensitive; ``.IN2`` optional.

    Returns
    -------
    pathlib.Path
        The installed file.

    Raises
    ------
    KeyError
        If no graph has that name; the message names the graphs there are.

    Examples
    --------
    >>> salbp_path("kilbrid").name
    'KILBRID.IN2'
    """
    stem = name.upper().removesuffix(".IN2")
    if stem not in SALBP:
        raise KeyError(f"no SALBP graph named '{name}': the package ships {', '.join(SALBP)}")
    return Path(str(shipped_folder("salbp").joinpath(f"{stem}.IN2")))


def examples() -> list[tuple[str, str, str]]:
    """The shipped examples.

    Returns
    -------
    list of (str, str, str)
        ``(name, kind, description)``, by name: kind ``plan``, ``looks`` or ``sequences`` (observed
        assemblies, for ``opportune learn``); the description is the plan's ``description`` or the
        file's first comment line.

    Examples
    --------
    >>> examples()[0]
    ('gearbox', 'plan', 'Ten-part gearbox of Fox & Kempf (reconstructed Figure 2)')
    """
    folder = shipped_folder("examples")
    out = []
    for entry in sorted(folder.iterdir(), key=lambda e: e.name.rpartition(".")[0]):
        name, _, suffix = entry.name.rpartition(".")
        if suffix not in ("yaml", "looks", "seq"):
            continue
        text = entry.read_text(encoding="utf-8")
        if suffix == "yaml":
            import yaml

            doc = yaml.safe_load(text) or {}
            about = str(doc.get("description", "")) if isinstance(doc, dict) else ""
        else:
            about = next((line.lstrip("# ").strip() for line in text.splitlines() if line.startswith("#")), "")
        out.append((name, {"yaml": "plan", "looks": "looks", "seq": "sequences"}[suffix], about))
    return out


def example_path(name: str) -> Path:
    """The file of a shipped example, by name.

    Parameters
    ----------
    name : str
        ``gearbox``, ``gearbox-table1``, ... (:func:`examples`); a suffix is optional.

    Returns
    -------
    pathlib.Path
        The installed file.

    Raises
    ------
    KeyError
        If no example has that name; the message names the examples there are.

    Examples
    --------
    >>> example_path("gearbox-table1").name
    'gearbox-table1.looks'
    """
    stem = name.removesuffix(".yaml").removesuffix(".looks").removesuffix(".seq")
    folder = shipped_folder("examples")
    for suffix in ("yaml", "looks", "seq"):
        entry = folder.joinpath(f"{stem}.{suffix}")
        if entry.is_file():
            return Path(str(entry))
    names = ", ".join(n for n, _, _ in examples())
    raise KeyError(f"no example named '{name}': the package ships {names}")


def plan_names() -> tuple[str, ...]:
    """The shipped plans by the names the readers take: ``salbp:NAME`` for each graph, ``example:NAME`` for
    each example plan (not the looks and sequences).

    >>> plan_names()[0], "example:gearbox" in plan_names()
    ('salbp:MERTENS', True)
    """
    return tuple(PREFIX + n for n in SALBP) + tuple(EXAMPLE_PREFIX + n for n, kind, _ in examples() if kind == "plan")


def resolve(path: str | Path) -> Path:
    """``salbp:NAME`` and ``example:NAME`` as the shipped files they name; any other path as it is.

    Parameters
    ----------
    path : str or os.PathLike
        A file, ``salbp:NAME`` or ``example:NAME``.

    Returns
    -------
    pathlib.Path
        The file.

    Raises
    ------
    KeyError
        For an unknown shipped name (naming what there is).

    Examples
    --------
    >>> resolve("salbp:KILBRID").name, resolve("my-plan.yaml").name
    ('KILBRID.IN2', 'my-plan.yaml')
    """
    text = str(path)
    if text.lower().startswith(PREFIX):
        return salbp_path(text[len(PREFIX):])
    if text.lower().startswith(EXAMPLE_PREFIX):
        return example_path(text[len(EXAMPLE_PREFIX):])
    return Path(path)


def geometry_path(name: str) -> Path:
    """The folder of a shipped assembly's meshes (``gearbox``, ``pump``, ``puzzle``), for ``opportune derive``.

    Raises ``KeyError`` naming the assemblies there are.

    >>> sorted(p.name for p in geometry_path("puzzle").iterdir())
    ['link_a.obj', 'link_b.obj', 'stand.obj']
    """
    if name not in GEOMETRY:
        raise KeyError(f"no shipped assembly named '{name}': the package ships {', '.join(GEOMETRY)}")
    return Path(str(shipped_folder("examples").joinpath("geometry").joinpath(name)))


def resolve_assembly(path: str | Path) -> Path:
    """``geometry:NAME`` as the shipped assembly's folder; any other path as it is.

    Raises ``KeyError`` (naming what there is) for an unknown name.

    >>> resolve_assembly("geometry:gearbox").name, resolve_assembly("my-product").name
    ('gearbox', 'my-product')
    """
    text = str(path)
    if text.lower().startswith(GEOMETRY_PREFIX):
        return geometry_path(text[len(GEOMETRY_PREFIX):])
    return Path(path)
