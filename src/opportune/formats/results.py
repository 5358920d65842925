"""Reading a study's ``results.json`` to run it again (``opportune simulate --from``), bounded like plans.

A results file records the study's settings and its plan (``provenance.study``, ``provenance.plan``);
the rest (the summary of every strategy) is not read again.  Every size is bounded before it can
cost time or memory, as in :mod:`opportune.formats.loader`: at most :data:`MAX_RESULTS_BYTES`
bytes (read at most one byte more, whatever the file is: ``/dev/zero`` too); at most
:data:`MAX_RESULTS_VALUES` values (counted by :func:`~opportune.formats.loader.json_values_past`
before anything is parsed: C speed, one copy of the text), nested at most
:data:`~opportune.formats.loader.MAX_DEPTH` deep; at most :data:`MAX_RECORDED_STRATEGIES` strategies
in the study.  The plan is then checked as any plan (its own limits, :mod:`opportune.planning.plan`).  A file
at these bounds is read in well under a second of CPU time and under 300 MB.

>>> try:
...     read_recorded_study("no-such-results.json")
... except ResultsError as exc:
...     print(exc)
cannot read no-such-results.json: No such file or directory
"""

from __future__ import annotations

import json
from pathlib import Path

from opportune.formats.documents import MAX_DEPTH, MAX_FILE_BYTES, MAX_VALUES, json_values_past

__all__ = ["MAX_RECORDED_STRATEGIES", "MAX_RESULTS_BYTES", "MAX_RESULTS_VALUES", "ResultsError",
           "read_recorded_study"]

MAX_RESULTS_BYTES = 2 * MAX_FILE_BYTES   # 64 MiB: a plan file's bound and room for the summary
# The largest plan the loaders accept, written out by Plan.to_dict (a graph file's 10,000 parts with
# their data and 120,000 edges come to about 210,000 values; a plan file's 150,000 values stay
# 150,000), with room for the summary and the settings.
MAX_RESULTS_VALUES = 4 * MAX_VALUES
MAX_RECORDED_STRATEGIES = 64             # strategies of a study (there are fewer than 20 policies)
_HINT = "give the results.json that `opportune simulate --out` wrote, or rerun from the plan file"


class ResultsError(ValueError):
    """A results file that cannot be read or runs no study: the message says where and what to do."""


def _deeper_than(value, limit: int) -> bool:
    """Whether parsed JSON nests deeper than ``limit``.  Iterative, O(values)."""
    stack = [(value, 1)]
    while stack:
        value, depth = stack.pop()
        if depth > limit:
            return True
        if isinstance(value, dict):
            stack.extend((v, depth + 1) for v in value.values())
        elif isinstance(value, list):
            stack.extend((v, depth + 1) for v in value)
    return False


def read_recorded_study(path: str | Path) -> dict:
    """The provenance a ``results.json`` records, with the study settings and the plan document it
    needs to run again (``study``, ``plan``; ``plan_sha256`` if recorded), or :class:`ResultsError`.

    O(size of the file) and bounded (see the module): the size before reading, the values before
    parsing, the depth and the study's strategies after.  The plan is not checked here: build it
    with :func:`~opportune.formats.loader.plan_from_dict`, which applies the plan limits.
    """
    path = Path(path)
    try:
        with path.open("rb") as f:  # at most one byte past the bound, whatever the file is
            raw = f.read(MAX_RESULTS_BYTES + 1)
    except IsADirectoryError:
        raise ResultsError(f"{path} is a directory, not a results.json; {_HINT}") from None
    except OSError as exc:
        raise ResultsError(f"cannot read {path}: {exc.strerror or exc}") from None
    if len(raw) > MAX_RESULTS_BYTES:
        raise ResultsError(f"{path}: larger than {MAX_RESULTS_BYTES:,} bytes ({MAX_RESULTS_BYTES >> 20} MiB), "
                           f"the most a results.json holds: not a results.json; {_HINT}")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise ResultsError(f"{path}:{line}: not UTF-8 text (byte 0x{raw[exc.start]:02x}): not a results.json; "
                           f"{_HINT}") from None
    del raw
    line = json_values_past(text, MAX_RESULTS_VALUES)
    if line is not None:
        raise ResultsError(f"{path}:{line}: more than {MAX_RESULTS_VALUES:,} values (list items, keys and values), "
                           f"the most a results.json holds (its plan at the loaders' bounds and the summary); "
                           f"{_HINT}")
    try:
        doc = json.loads(text)
    except RecursionError:
        raise ResultsError(f"{path}: values nested more than {MAX_DEPTH} levels deep: not a results.json; "
                           f"{_HINT}") from None
    except ValueError as exc:  # JSONDecodeError, and integers of more than 4,300 digits
        where = f":{exc.lineno}" if isinstance(exc, json.JSONDecodeError) else ""
        raise ResultsError(f"{path}{where}: not JSON ({str(exc)[:200]}); {_HINT}") from None
    if _deeper_than(doc, MAX_DEPTH):
        raise ResultsError(f"{path}: values nested more than {MAX_DEPTH} levels deep: not a results.json; {_HINT}")
    prov = doc.get("provenance") if isinstance(doc, dict) else None
    if not isinstance(prov, dict) or not isinstance(prov.get("study"), dict) or "plan" not in prov:
        raise ResultsError(f"{path}: records no study to run again (no provenance.study and provenance.plan; "
                           "a results.json written by an earlier opportune does not): rerun from the plan file")
    strategies = prov["study"].get("strategies")
    if isinstance(strategies, list) and len(strategies) > MAX_RECORDED_STRATEGIES:
        raise ResultsError(f"{path}: provenance.study.strategies lists {len(strategies):,} strategies; a study "
                           f"runs at most {MAX_RECORDED_STRATEGIES}: {_HINT}")
    return prov
