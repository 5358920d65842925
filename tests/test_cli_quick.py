"""``opportune count`` without typer: the quick path says exactly what the typer command says, loads
neither typer nor rich, and hands every command line it does not take to the typer command."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import GEARBOX, run_cli
from opportune import cli_count

SIX = "name: six\nparts: [a, b, c, d, e, f]\nrequires:\n  c: [a]\n  d: [b]\n"


def quick(*argv, env=None) -> subprocess.CompletedProcess:
    """``opportune ARGV...`` as the console script runs it (``opportune.launch``), in a fresh interpreter."""
    return subprocess.run([sys.executable, "-m", "opportune", *map(str, argv)], capture_output=True, text=True,
                          timeout=120, cwd=GEARBOX.parent.parent, env=env)


def modules_after(*argv) -> set[str]:
    code = ("import atexit, sys\n"
            "atexit.register(lambda: print('\\nMODULES', ' '.join(sorted(sys.modules))))\n"
            f"sys.argv = ['opportune', *{[str(a) for a in argv]!r}]\n"
            "from opportune.launch import main\nmain()\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=GEARBOX.parent.parent).stdout
    return set(out.rstrip().splitlines()[-1].split()[1:])


@pytest.fixture
def six(tmp_path):
    path = tmp_path / "six.yaml"
    path.write_text(SIX)
    return path


def test_count_and_its_help_load_neither_typer_nor_rich(six):
    help_mods = modules_after("count", "--help")
    assert not {"typer", "rich", "click", "yaml", "opportune.engine.schedule"} & help_mods
    assert "typing" not in help_mods        # (a tenth of the help's start-up)
    count_mods = modules_after("count", six)
    assert "opportune.engine.schedule" in count_mods        # it did count
    assert not {"typer", "rich", "click"} & count_mods
    # a count's start-up pays only for what counting needs (each of these costs 2-5 ms)
    assert not {"typing", "pathlib", "json", "random", "threading", "ast", "dis", "tokenize"} & count_mods
    assert "typer" in modules_after("check", six)           # the other commands are typer's


def test_a_deferred_module_loads_at_its_first_use_and_then_works_as_itself():
    code = ("import sys\n"
            "from opportune.launch import defer\n"
            "defer('inspect')\n"
            "import dataclasses\n"
            "print('ast' in sys.modules)\n"
            "@dataclasses.dataclass\n"
            "class Point:\n"
            "    x: int\n"
            "    y: int = 2\n"
            "import inspect\n"
            "print('ast' in sys.modules, Point.__doc__, inspect.signature(Point), inspect.isclass(Point))\n")
    lines = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                           check=True).stdout.splitlines()
    assert lines[0] == "False"          # dataclasses imported inspect without loading it
    # a class without a docstring made inspect load, and it answers as inspect itself does
    assert lines[1] == "True Point(x: int, y: int = 2) (x: int, y: int = 2) -> None True"


@pytest.mark.parametrize("extra", [(), ("--json",), ("--after", "a,b"), ("--after=b a", "--json"),
                                   ("--time-limit", "3", "--max-memo", "5000"), ("--max-memo=100",),
                                   ("--threads", "2"), ("--threads=0", "--json")])
def test_the_quick_path_answers_as_the_typer_command(six, extra):
    """Byte for byte, on standard output, for every option and both output forms (exact counts)."""
    fast = quick("count", six, *extra)
    slow = run_cli("count", six, *extra)
    assert fast.returncode == 0 == slow.exit_code, fast.stderr
    assert fast.stdout == slow.stdout


def test_the_quick_path_counts_the_shipped_plans_as_the_typer_command():
    for spec in ("salbp:KILBRID", "example:gearbox", str(GEARBOX)):
        fast, slow = quick("count", spec, "--json"), run_cli("count", spec, "--json")
        assert json.loads(fast.stdout) == json.loads(slow.stdout)
        assert json.loads(fast.stdout)["exact"] is True


def test_a_prefix_that_is_not_admissible_is_refused_as_the_typer_command_refuses_it(six):
    fast = quick("count", six, "--after", "c")
    slow = run_cli("count", six, "--after", "c")
    assert fast.returncode == 1 == slow.exit_code
    assert fast.stdout == ""
    assert fast.stderr.strip() == slow.stderr.strip() and fast.stderr.startswith("error: --after: part 'c'")
    fast = quick("count", six, "--after", "c", "--json")
    slow = run_cli("count", six, "--after", "c", "--json")
    assert json.loads(fast.stdout) == json.loads(slow.stdout)
    assert json.loads(fast.stdout)["error"]["exit_code"] == 1


@pytest.mark.parametrize("argv,code,words", [
    (("count",), 2, "Missing argument"),
    (("count", "{six}", "--time-limit", "0.01"), 2, "0.01 is not in the range x>=0.1"),
    (("count", "{six}", "--time-limit", "soon"), 2, "'soon' is not a valid float"),
    (("count", "{six}", "--bogus"), 2, "No such option: --bogus"),
    (("count", "{six}", "{six}"), 2, "unexpected extra argument"),
    (("count", "{six}", "--json=yes"), 2, "does not take a value"),
    (("count", "{six}", "--after"), 2, "requires an argument"),
    (("count", "{six}", "--threads", "-1"), 2, "-1 is not in the range 0<=x<=256"),
    (("count", "{six}", "--threads", "257"), 2, "257 is not in the range 0<=x<=256"),
    (("count", "no-such-plan.yaml"), 1, "no such file"),
])
def test_every_command_line_the_quick_path_does_not_take_gets_the_typer_commands_answer(six, argv, code, words):
    argv = [a.format(six=six) for a in argv]
    assert cli_count.parse(argv[1:]) is None or argv[1:] == ["no-such-plan.yaml"]
    r = quick(*argv)
    assert r.returncode == code, r.stdout + r.stderr
    assert words.lower() in (r.stdout + r.stderr).lower()
    assert "Traceback" not in r.stderr


def test_a_plan_read_from_standard_input_goes_to_the_typer_command(six):
    r = subprocess.run([sys.executable, "-m", "opportune", "count", "-"], input=SIX, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("six: 180 admissible sequences")


def test_text_from_the_plan_never_reaches_the_terminal_raw(tmp_path):
    """A plan's text is refused when it holds control characters; its name, taken from a file name that
    holds them, is written with escapes, as the typer command writes it."""
    path = tmp_path / "evil\x1b[2J\x07.yaml"
    path.write_text("parts: [a, b]\n")
    r = quick("count", path)
    assert r.returncode == 0, r.stderr
    assert "\x1b" not in r.stdout and "\x07" not in r.stdout
    assert "2 admissible sequences" in r.stdout
    assert r.stdout == run_cli("count", path).stdout


def _options(help_text: str) -> dict[str, str]:
    """Option -> its help text, whitespace folded, from a help page in click's plain layout."""
    body = help_text.split("Options:", 1)[1]
    out, flag = {}, None
    for line in body.splitlines():
        m = re.match(r"\s{2}(-h, --help|--[\w-]+)(?: <[^>]+>)?\s*(.*)", line)
        if m:
            flag = m.group(1)
            out[flag] = m.group(2)
        elif flag and line.strip():
            out[flag] += " " + line.strip()
    return {k: " ".join(v.split()) for k, v in out.items()}


def test_the_quick_help_says_what_the_typer_help_says():
    """The same usage line, description, argument and options (each with its help, default and range),
    whatever the width the lines are folded at."""
    env = {"COLUMNS": "100", "PATH": "/usr/bin:/bin"}
    fast = quick("count", "--help", env=env).stdout
    slow = subprocess.run([sys.executable, "-c", "import sys; sys.argv = ['opportune', 'count', '--help']\n"
                           "from opportune.cli import main; main()"], capture_output=True, text=True, env=env,
                          timeout=120).stdout
    assert fast.splitlines()[0] == slow.splitlines()[0]
    assert _options(fast) == _options(slow)
    assert set(_options(fast)) == {"--after", "--json", "--time-limit", "--max-memo", "--threads", "-h, --help"}
    fold = lambda text: " ".join(text.split("Options:")[0].split())  # noqa: E731
    assert fold(fast) == fold(slow)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.sampled_from(["--after", "--json", "--time-limit", "--max-memo", "-h", "--", "-", "x.yaml",
                                 "0.5", "7", "--time-limit=2", "--json=1", "--max-memo=x", "", "-x", "a,b",
                                 "--threads", "--threads=300", "-1"]),
                max_size=6))
def test_parsing_never_fails_and_takes_only_what_it_understands(argv):
    """Any command line: None (the typer command takes it) or arguments of the declared types, one plan,
    a time limit of at least 0.1 s."""
    args = cli_count.parse(argv)
    if args is None or args.get("help"):
        return
    assert isinstance(args["plan_file"], str) and args["plan_file"] in argv
    assert args["time_limit"] >= cli_count.MIN_TIME_LIMIT and isinstance(args["max_memo"], int)
    assert 0 <= args["threads"] <= cli_count.MAX_THREADS
    assert isinstance(args["as_json"], bool)


@pytest.mark.parametrize("columns", [None, "", "0", "-3", "abc", "1", "72", "200"])
def test_the_help_is_as_wide_as_shutil_says_the_terminal_is(monkeypatch, columns):
    import shutil

    if columns is None:
        monkeypatch.delenv("COLUMNS", raising=False)
    else:
        monkeypatch.setenv("COLUMNS", columns)
    assert cli_count.terminal_columns() == shutil.get_terminal_size().columns


def test_the_quick_path_bounds_threads_as_the_engine_does():
    from opportune.engine import relaxmc

    assert cli_count.MAX_THREADS == relaxmc.MAX_THREADS
