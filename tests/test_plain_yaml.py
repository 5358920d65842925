"""The loader's plain-YAML path (``formats.loader._plain_yaml``, which saves PyYAML's import on small
plans) reads exactly what PyYAML's path reads, data and lines, or declines: on generated plan-like
documents in every style it reads, and on the same documents mutated character by character."""

from __future__ import annotations

import random

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from opportune.formats import loader

WORDS = st.from_regex(r"[a-z][a-z0-9_]{0,6}", fullmatch=True)
SCALARS = st.one_of(WORDS, st.integers(-10**6, 10**6),
                    st.decimals(-1000, 1000, places=2, allow_nan=False, allow_infinity=False).map(float),
                    st.from_regex(r"[A-Z][a-z]{1,6}( [a-z]{1,6}){1,3}", fullmatch=True))


def full(text: str):
    """PyYAML's path: (data, lines), or None where it finds a problem."""
    saved, loader._plain_yaml = loader._plain_yaml, lambda text: None
    try:
        doc = loader.parse_yaml(text)
    finally:
        loader._plain_yaml = saved
    return None if doc.problems else (doc.data, doc.lines)


def render(value, indent: int, rng: random.Random, step: int) -> list[str]:
    """Block-style lines of a mapping ``value`` (keys to scalars, lists and mappings) at ``indent``."""
    pad = " " * indent
    out = []
    for key, v in value.items():
        if rng.random() < 0.15:
            out.append(pad + "# " + rng.choice(["note", "x: y", "- a"]))
        if rng.random() < 0.1:
            out.append("")
        comment = rng.choice(["", "", "", "   # why"])
        if isinstance(v, dict) and v:
            out.append(f"{pad}{key}:{comment}")
            out += render(v, indent + step, rng, step)
        elif isinstance(v, list) and v and rng.random() < 0.5 and all(isinstance(x, (str, int, float)) for x in v):
            out.append(f"{pad}{key}:{comment}")
            dash = pad if rng.random() < 0.5 else pad + " " * step
            out += [f"{dash}- {x}" for x in v]
        elif isinstance(v, list):
            out.append(f"{pad}{key}: [{', '.join(str(x) for x in v)}]{comment}")
        else:
            out.append(f"{pad}{key}: {v}{comment}")
    return out


DOCS = st.dictionaries(WORDS, st.one_of(SCALARS, st.lists(st.one_of(WORDS, st.integers(0, 99)), max_size=5),
                                        st.dictionaries(WORDS, st.lists(WORDS, max_size=3), max_size=4)),
                       min_size=1, max_size=6)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(DOCS, st.integers(0, 2**32 - 1), st.sampled_from([2, 4]))
def test_the_plain_path_reads_what_pyyaml_reads(doc, seed, step):
    text = "\n".join(render(doc, 0, random.Random(seed), step)) + "\n"
    plain = loader._plain_yaml(text)
    expected = full(text)
    assert plain is None or plain == expected, text
    if expected is not None and plain is None:
        # it declines only what it is not meant to read: words PyYAML reads as booleans or null (as
        # keys, values or a phrase's first word), and empty mappings (`{}`, a flow mapping)
        assert special(doc), text


def special(value) -> bool:
    if isinstance(value, dict):
        return not value or any(special(k) or special(v) for k, v in value.items())
    if isinstance(value, list):
        return any(special(v) for v in value)
    return isinstance(value, str) and value.split(" ")[0].lower() in loader._SPECIAL


@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(DOCS, st.integers(0, 2**32 - 1), st.lists(st.tuples(st.integers(0, 10**6), st.sampled_from(
    list(" -:#[],{}\"'&*!|>%@`?~\t\r\n.0yYnN") + ["  ", ": ", "- ", "---", "yes", "null"])), min_size=1, max_size=4))
def test_mutated_documents_are_read_as_pyyaml_reads_them_or_declined(doc, seed, edits):
    text = "\n".join(render(doc, 0, random.Random(seed), 2)) + "\n"
    for at, piece in edits:
        at %= len(text) + 1
        text = text[:at] + piece + text[at + (at % 2):]      # an insertion, or a replacement of one character
    plain = loader._plain_yaml(text)
    if plain is not None:
        assert plain == full(text), text


def test_the_shipped_plans_and_the_count_benchmarks_plan_are_read_alike():
    from opportune.datasets import example_path

    six = "name: six\nparts: [a, b, c, d, e, f]\nrequires:\n  c: [a]\n  d: [b]\n"
    assert loader._plain_yaml(six) == full(six) and loader._plain_yaml(six) is not None
    for name in ("gearbox", "pump", "gearbox-overconstrained"):
        text = example_path(name).read_text()
        plain = loader._plain_yaml(text)
        assert plain is None or plain == full(text)
    # what it must decline: flow mappings, quotes, anchors, booleans, nulls, repeated keys, tabs
    for text in ("parts: [a, {id: b}]\n", "name: 'x'\n", "a: &x [b]\nc: *x\n", "a: yes\n", "a: ~\n", "a:\n",
                 "a: 1\na: 2\n", "a:\n\t- b\n", "--- \na: b\n", "a: b: c\n", "a: 0x1F\n", "a: 2001-12-14\n",
                 "a: 1e3\n", "On: b\n", "a: [b, c\n", "a: b\n  c\n"):
        assert loader._plain_yaml(text) is None, text
