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
    "opportune simulate salbp:ARC111": "10,000 trials per strategy on 111 parts take many minutes: "
                                       "benchmarks/bench_decisions.py measures it",
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


def test_the_readme_shows_the_commands_this_test_runs():
    commands = readme_commands()
    assert "opportune count example:gearbox" in commands and "opportune schema" in commands
    assert all(any(c.startswith(n) for c in commands) for n in NOT_RUN), "an excused command left the README"
    assert len(commands) >= 12


def test_every_readme_command_runs_from_an_empty_directory(tmp_path):
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}", "COLUMNS": "120"}
    failures = []
    for command in readme_commands():
        if command in NOT_RUN or command.startswith("opportune serve"):
            continue
        done = subprocess.run(shlex.split(command), cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=300)
        if done.returncode != 0 or "Traceback" in done.stderr:
            failures.append(f"{command}: exit {done.returncode}\n{done.stdout[-500:]}{done.stderr[-1500:]}")
    assert not failures, "\n\n".join(failures)
    assert (tmp_path / "gearbox.svg").read_text().startswith("<?xml")
    assert (tmp_path / "demo-output" / "results.json").exists()


def test_the_readme_python_example_runs_from_an_empty_directory(tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", README, flags=re.S)
    assert blocks
    for i, code in enumerate(blocks):
        done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, f"README python block {i + 1}:\n{done.stderr[-2000:]}"
        if "decision.explain()" in code:
            assert done.stdout.startswith("buffer rl"), done.stdout
