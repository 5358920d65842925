"""Hostile and careless plan files, looks files and command lines (issue 12): every one refused with a
message that says where and what to do, within stated limits, quickly, and never with a traceback."""

from __future__ import annotations

import json
import sys
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from conftest import GEARBOX
from opportune.cli import app
from opportune.formats import check_text, read_plan
from opportune.formats import loader
from opportune.formats.looks import LooksError, parse_looks
from opportune.formats.validate import plan_schema
from opportune.planning.plan import MAX_QUANTITY, MAX_UNITS

runner = CliRunner()


def cli(*args):
    """Run the command line in-process; fail on any traceback."""
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert "Traceback" not in result.output, result.output
    return result


def errors(result, code=None):
    return [p for p in result.errors if code is None or p.code == code]


def billion_laughs(levels: int = 9) -> str:
    """The classic: 352 bytes that expand to 9**9 (387 million) values."""
    lines = ['a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    names = "abcdefghijklmnop"
    for prev, cur in zip(names[: levels - 1], names[1:levels]):
        lines.append(f"{cur}: &{cur} [" + ",".join([f"*{prev}"] * 9) + "]")
    lines.append(f"parts: *{names[levels - 1]}")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- YAML aliases and nesting


def test_an_alias_bomb_is_refused_at_once_with_its_limit():
    text = billion_laughs()
    assert len(text) == 352
    start = time.process_time()
    result = check_text(text, fmt="yaml", file="bomb.yaml")
    assert time.process_time() - start < 1.0
    (p,) = errors(result)
    assert p.code == "limit" and p.file == "bomb.yaml" and p.line is not None
    assert "alias" in p.message and f"{loader.MAX_VALUES:,}" in p.message


def test_a_smaller_alias_bomb_is_refused_by_the_values_aliases_may_add():
    start = time.process_time()
    (p,) = errors(check_text(billion_laughs(5), fmt="yaml", file="b.yaml"))  # 9**5 values
    assert time.process_time() - start < 1.0
    assert p.code == "limit" and f"at most {loader.MAX_ALIAS_VALUES:,}" in p.message


def test_too_many_aliases_are_refused(monkeypatch):
    monkeypatch.setattr(loader, "MAX_ALIASES", 3)
    text = "x: &x a\nparts: [*x, *x, *x, *x]\n"
    (p,) = errors(check_text(text, fmt="yaml"))
    assert p.code == "limit" and "more than 3 YAML aliases" in p.message and p.line == 2


def test_a_self_referencing_alias_is_a_clean_error():
    for text in ("parts: &a [a, *a]\n", "name: x\nparts: [a]\nrequires: &r {a: [b, *r]}\n"):
        (p,) = errors(check_text(text, fmt="yaml", file="self.yaml"))
        assert p.code == "limit" and "inside the value it names" in p.message and p.line is not None


def test_aliases_used_sensibly_still_work():
    text = """
parts: [a, b, c, d]
strategies:
  - {name: one, requires: &common {c: [a, b], d: [c]}}
  - {name: two, requires: {d: &ab [a, b]}}
  - {name: three, requires: {c: *ab, d: *ab}}
"""
    result = check_text(text, fmt="yaml")
    assert result.ok, [str(p) for p in result.problems]
    assert dict(result.plan.strategies[2].requires) == {"c": ("a", "b"), "d": ("a", "b")}


@pytest.mark.parametrize("depth", [65, 1_000, 100_000])
def test_nesting_too_deep_is_refused_with_its_line(depth):
    yaml_text = "name: deep\nparts: " + "[" * depth + "]" * depth + "\n"
    json_text = '{"name": "deep",\n "parts": ' + "[" * depth + "]" * depth + "}"
    for fmt, text in (("yaml", yaml_text), ("json", json_text)):
        start = time.process_time()
        (p,) = errors(check_text(text, fmt=fmt, file=f"deep.{fmt}"))
        assert time.process_time() - start < 2.0
        assert p.code == "limit" and f"{loader.MAX_DEPTH} levels" in p.message and p.line == 2, (fmt, str(p))


def test_cli_check_of_hostile_files_exits_1_without_traceback(tmp_path):
    files = {
        "bomb.yaml": billion_laughs(),
        "self.yaml": "parts: &a [a, *a]\n",
        "deep.yaml": "parts: " + "[" * 1000 + "]" * 1000 + "\n",
        "deep.json": '{"parts": ' + "[" * 1000 + "]" * 1000 + "}",
        "big.json": '{"parts": [{"id": "a", "quantity": ' + "9" * 5000 + "}]}",
        "big.yaml": "parts: [{id: a, quantity: " + "9" * 5000 + "}]\n",
        "huge.json": json.dumps({"parts": [{"id": "a", "quantity": 10**30}, "b"]}),
    }
    for name, text in files.items():
        path = tmp_path / name
        path.write_text(text)
        for command in ("check", "count"):
            result = cli(command, path)
            assert result.exit_code == 1, (name, command, result.output)
            assert f"{path}:" in result.output and "error" in result.output, (name, result.output)


# ---------------------------------------------------------------- sizes of plans


def test_quantity_is_bounded_in_the_schema_and_the_message():
    assert plan_schema()["$defs"]["part"]["properties"]["quantity"]["maximum"] == MAX_QUANTITY
    assert plan_schema()["properties"]["parts"]["maxItems"] == MAX_UNITS
    result = check_text(json.dumps({"parts": [{"id": "a", "quantity": 10**30}, "b"]}), fmt="json", file="q.json")
    (p,) = errors(result)
    assert p.code == "limit" and f"at most {MAX_QUANTITY:,}" in p.message and p.line == 1
    assert check_text(json.dumps({"parts": [{"id": "a", "quantity": MAX_QUANTITY}]}), fmt="json").ok


def test_total_units_are_bounded():
    half = MAX_UNITS // 2 + 1
    result = check_text(json.dumps({"parts": [{"id": "a", "quantity": half}, {"id": "b", "quantity": half}]}),
                        fmt="json", file="u.json")
    (p,) = errors(result)
    assert p.code == "limit" and f"{2 * half:,} units" in p.message and f"at most {MAX_UNITS:,}" in p.message


def test_numbers_too_long_to_read_are_errors():
    for fmt, text in (("json", '{"parts": [{"id": "a", "quantity": ' + "1" * 5000 + "}]}"),
                      ("yaml", "parts:\n  - {id: a, quantity: " + "1" * 5000 + "}\n")):
        (p,) = errors(check_text(text, fmt=fmt, file=f"n.{fmt}"))
        assert "digits" in p.message, str(p)


def test_costs_must_be_finite():
    result = check_text("parts:\n  - {id: a, acquire: .nan}\n  - {id: b, install: .inf}\n", fmt="yaml", file="c.yaml")
    assert sorted((p.line, p.code) for p in result.errors) == [(2, "type"), (3, "type")]
    assert all("not a finite number" in p.message for p in result.errors)
    assert not check_text('{"parts": [{"id": "a", "visibility": NaN}]}', fmt="json").ok


def test_lone_surrogates_in_a_plan_are_errors_with_their_line():
    for fmt, text in (("yaml", 'name: x\nparts: [a, "b\\ud800"]\n'), ("json", '{"name": "x",\n"parts": ["a", "b\\ud800"]}')):
        (p,) = errors(check_text(text, fmt=fmt, file=f"s.{fmt}"))
        assert p.line == 2 and "\ud800" not in str(p), str(p)  # described, never the raw half-character
        str(p).encode("utf-8")  # printable anywhere
        if fmt == "json" or p.code != "syntax":  # libyaml refuses the escape itself: a syntax error
            assert p.code == "text" and "surrogate" in p.message and "\\ud800" in p.message
    both_halves = check_text('{"parts": ["a", "b\\ud83d\\ude00"]}', fmt="json")
    assert both_halves.ok and both_halves.plan.part_ids == ("a", "b\U0001f600")


# ---------------------------------------------------------------- every problem, linear time


def test_an_unknown_part_does_not_hide_a_cycle_in_the_same_entry():
    result = check_text("parts: [a, b, c]\nrequires:\n  a: [b, zz]\n  b: [a]\n", fmt="yaml", file="p.yaml")
    codes = sorted(p.code for p in result.errors)
    assert codes == ["cycle", "unknown-part"], [str(p) for p in result.errors]
    self_and_cycle = check_text("parts: [a, b]\nrequires:\n  a: [a, b]\n  b: [a]\n", fmt="yaml")
    assert sorted(p.code for p in self_and_cycle.errors) == ["cycle", "self-requirement"]


def test_many_problems_are_capped_with_a_count_of_the_rest():
    requires = {"a": [f"x{i}" for i in range(500)]}
    result = check_text(json.dumps({"parts": ["a"], "requires": requires}), fmt="json", file="m.json")
    unknown = [p for p in result.errors if p.code == "unknown-part"]
    assert len(unknown) == 101 and "and 400 more problems" in unknown[-1].message


def test_a_requirement_repeated_30000_times_is_checked_in_linear_time():
    text = json.dumps({"parts": ["a", "b"], "requires": {"b": ["a"] * 30_000}})
    start = time.process_time()
    result = check_text(text, fmt="json")
    assert time.process_time() - start < 3.0
    assert result.ok and [p.code for p in result.warnings] == ["repeated"]


def test_a_long_list_with_one_bad_item_costs_the_schema_little_and_is_placed_exactly():
    text = json.dumps({"parts": ["a", "b", "c d", "e"], "requires": {"b": ["a"] * 50_000 + [{}, "a", "x y"]}}, indent=0)
    start = time.process_time()
    result = check_text(text, fmt="json", file="long.json")
    assert time.process_time() - start < 3.0
    lines = text.splitlines()
    found = {(p.line, p.message.split(":")[0]) for p in result.errors}
    assert found == {(lines.index('"c d",') + 1, "parts[2]"), (lines.index("{},") + 1, "requires.b[50000]"),
                     (lines.index('"x y"') + 1, "requires.b[50002]")}, found


def test_in2_repeating_one_pair_100000_times_is_read_in_linear_time(tmp_path):
    path = tmp_path / "dup.IN2"
    path.write_text("\n".join(["3", "1", "1", "1"] + ["1,2"] * 100_000 + ["2,3", "-1,-1"]) + "\n")
    start = time.process_time()
    result = read_plan(path)
    assert time.process_time() - start < 2.0
    assert result.ok and result.plan.strategies[0].pairs() == [("1", "2"), ("2", "3")]
    (w,) = result.warnings
    assert w.code == "repeated" and w.line == 6 and "99,999 times (first at line 5)" in w.message


def test_in2_cut_before_its_end_marker_is_refused_with_file_and_line(salbp, tmp_path):
    lines = (salbp / "KILBRID.IN2").read_bytes().split(b"\n")
    path = tmp_path / "KILBRID80.IN2"
    path.write_bytes(b"\n".join(lines[:80]) + b"\n")
    (p,) = read_plan(path).errors
    assert p.code == "truncated" and p.file == str(path) and p.line == 80 and "-1,-1" in p.message
    result = cli("count", path)
    assert result.exit_code == 1 and "admissible sequences" not in result.output
    assert cli("count", salbp / "KILBRID.IN2").exit_code == 0


def test_undecodable_bytes_are_described_not_printed(tmp_path):
    in2 = tmp_path / "bytes.IN2"
    in2.write_bytes(b"3\n1\n1\n1\n1,2\n\xff\xfe,3\n-1,-1\n")
    (p,) = read_plan(in2).errors
    assert p.line == 6 and "'\\xff\\xfe,3'" in p.message and "ÿ" not in p.message
    yml = tmp_path / "bytes.yaml"
    yml.write_bytes(b"parts:\n  - a\n  - b\xff\n")
    (p,) = read_plan(yml).errors
    assert p.line == 3 and "0xff" in p.message and "column 6" in p.message
    result = cli("check", in2)
    assert "\\xff\\xfe" in result.output and "ÿ" not in result.output


def test_a_plan_file_over_the_size_limit_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(loader, "MAX_FILE_BYTES", 100)
    path = tmp_path / "big.yaml"
    path.write_text("parts: [" + ", ".join(f"p{i}" for i in range(100)) + "]\n")
    (p,) = read_plan(path).errors
    assert p.code == "limit" and "larger than 100 bytes" in p.message


# ---------------------------------------------------------------- looks files


@pytest.mark.parametrize("text, words", [
    ("[" * 100_000 + "]" * 100_000, "nested too deep"),
    ("[[" + "1" * 5000 + "]]", "digits"),
    ('[["\\ud800"]]', "surrogate"),
], ids=["deep", "long-number", "surrogate"])
def test_hostile_looks_files_are_looks_errors(text, words):
    with pytest.raises(LooksError) as info:
        parse_looks(text, file="x.looks")
    assert words in info.value.problem.message
    str(info.value.problem).encode("utf-8")


# ---------------------------------------------------------------- the command line's messages


def test_one_error_prefix_for_a_bad_looks_file(tmp_path):
    looks = tmp_path / "bad.json"
    looks.write_text("[[")
    result = cli("replay", GEARBOX, looks)
    assert result.exit_code == 1
    assert result.output.startswith(f"{looks}:1: error: JSON syntax error"), result.output
    assert "error: error" not in result.output and result.output.count(": error: ") == 1


def test_messages_are_text_not_markup(tmp_path):
    result = cli("count", GEARBOX, "--after", "[bold]x[/bold]")
    assert result.exit_code == 1 and "[bold]x[/bold]" in result.output


def test_dask_missing_names_the_scale_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    result = cli("simulate", GEARBOX, "--dask", "127.0.0.1:1", "--trials", "2", "--strategies", "pallet")
    assert result.exit_code == 1 and "pip install 'opportune[scale]'" in result.output


@pytest.mark.parametrize("args", [["token", "create", "cell-1"], ["token", "create", "--operator", "ops"],
                                  ["token", "list"], ["token", "revoke", "abc"], ["serve"]])
def test_service_commands_without_the_service_extra_name_it(args, monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "sqlalchemy", None)
    result = cli(*args, "--db", tmp_path / "x.db")
    assert result.exit_code == 1
    assert "pip install 'opportune[service]'" in result.output and result.output.count("error:") == 1
    assert not (tmp_path / "x.db").exists()


def test_counts_of_more_than_4300_digits_are_printed_exactly(tmp_path):
    plan = tmp_path / "free.json"
    plan.write_text(json.dumps({"parts": [f"p{i}" for i in range(2000)]}))
    looks = tmp_path / "one.looks"
    looks.write_text("p1 p2\n")
    counted = json.loads(cli("count", plan, "--json").stdout)
    assert counted["exact"] and len(counted["sequences"]) == 5736  # 2000!
    explained = cli("replay", plan, looks, "--explain")
    assert explained.exit_code == 0 and "keeps " + "1658137546" in explained.output
    doc = json.loads(cli("replay", plan, looks, "--json", "--explain").stdout)
    (cand, *_rest) = doc[0]["reasons"]["candidates"]
    assert len(cand["options"]) == 5733 and cand["total"] == counted["sequences"]


# ---------------------------------------------------------------- fuzz


def _mutations():
    base = GEARBOX.read_bytes()
    return st.lists(st.tuples(st.integers(0, len(base)), st.binary(min_size=0, max_size=8), st.integers(0, 8)),
                    min_size=1, max_size=4).map(lambda edits: _apply(base, edits))


def _apply(base: bytes, edits) -> bytes:
    out = bytearray(base)
    for at, insert, cut in edits:
        at = min(at, len(out))
        out[at: at + cut] = insert
    return bytes(out)


_json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=6),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(
        st.sampled_from(["parts", "requires", "strategies", "id", "quantity", "name", "a", "b"]), children, max_size=4),
    max_leaves=20)


@settings(max_examples=150, deadline=None)
@given(_mutations())
def test_fuzzed_plan_files_give_problems_never_exceptions(raw):
    for suffix in (".yaml", ".json", ".IN2"):
        path = _fuzz_dir() / f"fuzz{suffix}"
        path.write_bytes(raw)
        result = read_plan(path)
        for p in result.problems:
            str(p).encode("utf-8")
        assert result.ok or result.errors


@settings(max_examples=150, deadline=None)
@given(_json_values)
def test_fuzzed_documents_give_problems_never_exceptions(data):
    try:
        text = json.dumps(data, allow_nan=True)
    except (ValueError, RecursionError):
        return
    for fmt in ("json", "yaml"):
        result = check_text(text, fmt=fmt, file="f")
        for p in result.problems:
            str(p).encode("utf-8")


_FUZZ_DIR = []


def _fuzz_dir():
    if not _FUZZ_DIR:
        import tempfile
        from pathlib import Path

        _FUZZ_DIR.append(Path(tempfile.mkdtemp(prefix="opportune-fuzz-")))
    return _FUZZ_DIR[0]
