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
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

# Smallest first: the order of the data's README.
SALBP = ("MERTENS", "BOWMAN8", "JAESCHKE", "JACKSON", "MANSOOR", "MITCHELL", "HESKIA", "KILBRID",
         "TONGE70", "ARC111")
PREFIX = "salbp:"
EXAMPLE_PREFIX = "example:"


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


def examples() -> list[tuple[str, str, str]]:
    """The shipped examples as ``(name, kind, description)``: kind ``plan``, ``looks`` or ``sequences``
    (observed assemblies, for ``opportune learn``); the description is the plan's ``description`` or
    the file's first comment line."""
    folder = resources.files(__name__).joinpath("examples")
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
    """The file of a shipped example, by name (``gearbox``, ``gearbox-table1``; a suffix is optional).

    Raises ``KeyError`` naming the examples there are.
    """
    stem = name.removesuffix(".yaml").removesuffix(".looks").removesuffix(".seq")
    folder = resources.files(__name__).joinpath("examples")
    for suffix in ("yaml", "looks", "seq"):
        entry = folder.joinpath(f"{stem}.{suffix}")
        if entry.is_file():
            return Path(str(entry))
    names = ", ".join(n for n, _, _ in examples())
    raise KeyError(f"no example named '{name}': the package ships {names}")


def resolve(path: str | Path) -> Path:
    """``salbp:NAME`` and ``example:NAME`` as the shipped files they name; any other path as it is.

    Raises ``KeyError`` (naming what there is) for an unknown name.
    """
    text = str(path)
    if text.lower().startswith(PREFIX):
        return salbp_path(text[len(PREFIX):])
    if text.lower().startswith(EXAMPLE_PREFIX):
        return example_path(text[len(EXAMPLE_PREFIX):])
    return Path(path)
