"""Every command the README shows runs, as written, from an empty directory (nothing of the repository
at hand: the shipped plans are reached by name), and its Python example runs too."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
BIN = Path(sys.executable).parent

# Commands shown in the README that this test does not run, each with the reason.  Anything else the
# README shows as `opportune ...` is run.
NOT_RUN = {
    "opportune serve": "serves until stopped (any options): the service tests start and drive a real server",
}
# Inline mentions that are parts of commands, not commands (placeholders, alternatives, bare names).
FRAGMENT = re.compile(r"\.\.\.|\||\b[A-Z]{3,}\b(?!:)|^opportune [a-z]+$|^opportune count --time-limit")


def readme_commands() -> list[str]:
    commands = []
    fence = None   # the open code block's language ("" for a plain block), None outside blocks
    for line in README.splitlines():
        if line.startswith("```"):
            fence = line.strip()[3:] if fence is None else None
            continue
        if fence in ("sh", "", "console"):
            text = line.removeprefix("$ ").split("  #")[0].strip()
            if text.startswith("opportune "):
                commands.append(text)
    for inline in re.findall(r"`(opportune [^`]*)`", README):
        inline = " ".join(inline.split())
        if not FRAGMENT.search(inline.replace("salbp:ARC111", "salbp:arc")):
            commands.append(inline)
    return list(dict.fromkeys(commands))


def written_by(command: str) -> list[str]:
    """The files or folders a command writes (the values of its ``-o``/``--out``)."""
    args = shlex.split(command)
    return [args[i + 1] for i, a in enumerate(args[:-1]) if a in ("-o", "--out")]


def command_groups() -> list[list[str]]:
    """The README's commands to run, in groups, each group in the README's order: a command that names a file
    an earlier one writes (or writes the same file) joins that command's group.  Groups share nothing, so each
    runs in its own empty directory (and test workers can run them side by side)."""
    commands = [c for c in readme_commands() if c not in NOT_RUN and not c.startswith("opportune serve")]
    group = list(range(len(commands)))          # union-find over command indices

    def root(i):
        while group[i] != i:
            i = group[i]
        return i

    for j, later in enumerate(commands):
        args = shlex.split(later)
        for i in range(j):
            if any(a == out or a.startswith(out.rstrip("/") + "/") for out in written_by(commands[i]) for a in args):
                group[root(j)] = root(i)
    groups: dict[int, list[str]] = {}
    for i, command in enumerate(commands):
        groups.setdefault(root(i), []).append(command)
    return list(groups.values())


GROUPS = command_groups()


def test_the_readme_shows_the_commands_this_test_runs():
    commands = readme_commands()
    assert "opportune count example:gearbox" in commands and "opportune schema" in commands
    assert all(any(c.startswith(n) for c in commands) for n in NOT_RUN), "an excused command left the README"
    assert len(commands) >= 12
    # every command to run is in exactly one group, and a command that reads a file runs after its writer
    flat = [c for g in GROUPS for c in g]
    assert sorted(flat) == sorted(c for c in commands if c not in NOT_RUN and not c.startswith("opportune serve"))
    rerun = "opportune simulate --from demo-output/results.json --trials 1000"
    demo = next(g for g in GROUPS if rerun in g)
    assert demo.index("opportune simulate example:gearbox --out demo-output") < demo.index(rerun)
    assert any(len(g) == 1 for g in GROUPS) and len(GROUPS) >= 8


@pytest.mark.parametrize("group", GROUPS, ids=[g[0].removeprefix("opportune ") for g in GROUPS])
def test_every_readme_command_runs_from_an_empty_directory(group, tmp_path):
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}", "COLUMNS": "120"}
    failures = []
    for command in group:
        done = subprocess.run(shlex.split(command), cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=300)
        if done.returncode != 0 or "Traceback" in done.stderr:
            failures.append(f"{command}: exit {done.returncode}\n{done.stdout[-500:]}{done.stderr[-1500:]}")
    assert not failures, "\n\n".join(failures)
    for command in group:
        for out in written_by(command):
            assert (tmp_path / out).exists(), f"{command} wrote no {out}"
    if "opportune graph example:gearbox -o gearbox.svg" in group:
        assert (tmp_path / "gearbox.svg").read_text().startswith("<?xml")
    if "opportune simulate example:gearbox --out demo-output" in group:
        assert (tmp_path / "demo-output" / "results.json").exists()


def test_the_readme_python_example_runs_from_an_empty_directory(tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", README, flags=re.S)
    assert blocks
    for i, code in enumerate(blocks):
        done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, f"README python block {i + 1}:\n{done.stderr[-2000:]}"
        if "decision.explain()" in code:
            assert done.stdout.startswith("buffer rl"), done.stdout


def test_the_readme_is_for_users():
    """A newcomer's page: short, no development history, every link leading somewhere the site builds."""
    lines = README.splitlines()
    assert len(lines) < 400, f"README.md has {len(lines)} lines: move long sections into docs/ pages"
    for pattern, what in ((r"\bissues? #?\d+", "an issue number"), (r"\b20\d\d-\d\d-\d\d\b", "a date"),
                          (r"<!--", "a comment marker"), (r"(?i)before this (change|session)", "history")):
        found = [f"README.md:{i}: {line}" for i, line in enumerate(lines, 1) if re.search(pattern, line)]
        assert not found, f"{what} in the README:\n" + "\n".join(found)
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README)
    assert links
    for link in links:
        if "://" in link:
            continue
        assert (ROOT / link).exists(), f"README.md links to {link}, which does not exist"
        if link.startswith("docs/") and link.endswith(".md"):
            assert link.removeprefix("docs/") in nav, f"{link} is linked from the README but not in mkdocs.yml's nav"
    # the demo's measured time is stated, and `make demo` installs the package alone (no extra)
    assert re.search(r"\*\*\d+ min \d+ s\*\*|\*\*\d+ s\*\*", README), "the README states make demo's measured time"
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    demo = re.search(r"^demo: (.*)$", makefile, flags=re.M).group(1)
    assert "setup" not in demo.split(), "make demo must not install the extras (setup)"
    core = re.search(r"^\$\(CORE_STAMP\):.*\n((?:\t.*\n)+)", makefile, flags=re.M).group(1)
    assert "install --quiet -e .\n" in core and "[" not in core, core
    assert "CHANGELOG.md" in README and "docs/scale.md" in README
