"""The documentation site (mkdocs.yml, docs/): its examples run, and it builds offline with no warning.

What the pages' code blocks mean, which this test relies on and enforces:

* ```python blocks of a page run in order, in one namespace, in a fresh temporary directory.
* A ```text block right after a ```python block (nothing but blank lines between) is what that
  block prints: the test checks it, line by line (trailing spaces aside), where ``...`` stands
  for any text (numbers that depend on the machine's speed or on chance).
* ```console blocks: each ``$ `` line is a command, run with bash in the page's directory with the
  installed ``opportune`` first on the PATH; the lines after it are its output, checked the same
  way. Every command must exit 0.
* ```sh blocks: the lines that start with ``opportune`` run the same way (a ``#`` comment after
  them is the shell's) and must exit 0. A block without such a line (``make``, ``pip``) is only
  shown; a block mixing the two is refused, so that nothing in a block is run by half.
* ``<!-- docs-test: skip (reason) -->`` on the line before a block: not run. The reason is required
  (``opportune serve`` runs until stopped; the page runs a server through ServiceProcess instead).
* Any other fence (``bash``, ``pycon``, ...) is refused, so that no example escapes the test;
  ``yaml``, ``json`` and ``text`` blocks are shown only.

Blocks of all kinds run in the order of the page, in the same directory.

The site itself: ``mkdocs build --strict`` succeeds with no WARNING line and no network (in a
network namespace of its own where the system allows one, and with every proxy leading nowhere),
and no page it builds loads anything from elsewhere (fonts, scripts, styles).
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shutil
import stat
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
SHOWN_ONLY = {"text", "yaml", "json"}
RUN = {"python", "console", "sh"}
SKIP = re.compile(r"<!--\s*docs-test:\s*skip\s*\((?P<why>[^)]*\S[^)]*)\)\s*-->")
TUTORIALS = ("gearbox.md", "http.md", "large-plans.md")


@dataclass
class Block:
    page: str
    line: int          # of the opening fence, 1-based
    lang: str
    code: str
    skip: str | None = None
    expected: str | None = None   # a python block's output, from the ```text block after it


def pages() -> list[Path]:
    return sorted(p for p in DOCS.rglob("*.md") if "_ext" not in p.parts)


def blocks(path: Path) -> list[Block]:
    """The fenced blocks of a page, with each python block's expected output attached."""
    page = str(path.relative_to(DOCS))
    lines = path.read_text(encoding="utf-8").splitlines()
    found: list[Block] = []
    last_end = None      # index of the closing fence of the previous block
    i = 0
    while i < len(lines):
        opening = re.match(r"^(\s*)```(\S*)(.*)$", lines[i])
        if not opening:
            i += 1
            continue
        indent, lang, extra = opening.group(1), opening.group(2), opening.group(3).strip()
        assert lang, f"{page}:{i + 1}: a fence without a language: say what the block is (text, python, ...)"
        assert lang in RUN | SHOWN_ONLY, (f"{page}:{i + 1}: a ```{lang} block would escape the tests: use python, "
                                          f"console or sh (run) or text, yaml, json (shown)")
        assert not extra or lang in SHOWN_ONLY, f"{page}:{i + 1}: no attributes on a block that runs ({extra!r})"
        start = i
        j = i + 1
        while j < len(lines) and lines[j].strip() != "```":
            j += 1
        assert j < len(lines), f"{page}:{start + 1}: the block is not closed"
        code = "\n".join(line.removeprefix(indent) for line in lines[start + 1:j])   # a block in a list item
        between = lines[last_end + 1:start] if last_end is not None else []
        follows_python = (found and found[-1].lang == "python" and last_end is not None
                          and all(not line.strip() for line in between))
        if lang == "text" and follows_python and found[-1].expected is None:
            found[-1].expected = code
        else:
            before = next((lines[k] for k in range(start - 1, -1, -1) if lines[k].strip()), "")
            skip = SKIP.search(before)
            assert "docs-test" not in before or skip, f"{page}:{start + 1}: a skip needs its reason: {before}"
            found.append(Block(page, start + 1, lang, code, skip.group("why").strip() if skip else None))
        last_end = j
        i = j + 1
    return found


def same_output(expected: str, actual: str) -> bool:
    """``actual`` is ``expected``, trailing spaces and blank edges aside, with ``...`` matching any text."""
    def clean(text: str) -> str:
        return "\n".join(line.rstrip() for line in text.strip("\n").splitlines())

    pattern = ".*?".join(re.escape(part) for part in clean(expected).split("..."))
    return re.fullmatch(pattern, clean(actual), flags=re.DOTALL) is not None


def shell_commands(block: Block) -> list[tuple[str, str | None]]:
    """The commands of a console or sh block that run, each with its expected output (None: unchecked)."""
    if block.lang == "console":
        commands: list[tuple[str, list[str]]] = []
        for line in block.code.splitlines():
            if line.startswith("$ "):
                commands.append((line[2:], []))
            else:
                assert commands, f"{block.page}:{block.line}: output before any `$ ` command"
                commands[-1][1].append(line)
        return [(cmd, "\n".join(out) if out else None) for cmd, out in commands]
    lines = [line for line in block.code.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    runnable = [line for line in lines if line.startswith("opportune ")]
    assert not runnable or len(runnable) == len(lines), \
        f"{block.page}:{block.line}: a sh block either runs opportune commands only, or is shown only"
    return [(line, None) for line in runnable]


def bin_dir(tmp: Path) -> Path:
    """A directory holding the installed ``opportune`` (the console script beside this Python)."""
    here = Path(sys.executable).parent
    if (here / "opportune").exists():
        return here
    shim = tmp / ".bin" / "opportune"      # no console script (an unusual install): the module, the same code
    shim.parent.mkdir()
    shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m opportune "$@"\n')
    shim.chmod(shim.stat().st_mode | stat.S_IEXEC)
    return shim.parent


def run_shell(command: str, cwd: Path, path: Path, where: str) -> str:
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    env.update(PATH=f"{path}{os.pathsep}{env.get('PATH', '')}", PYTHONIOENCODING="utf-8")
    done = subprocess.run(["bash", "-c", command], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"{where}: `{command}` exited {done.returncode}:\n{done.stdout}\n{done.stderr}"
    return done.stdout


RUNNABLE_PAGES = [p for p in pages() if any(b.lang in RUN for b in blocks(p))]


@pytest.mark.parametrize("path", RUNNABLE_PAGES, ids=[str(p.relative_to(DOCS)) for p in RUNNABLE_PAGES])
def test_the_examples_of_a_page_run(path, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path_dir = bin_dir(tmp_path)
    namespace: dict = {"__name__": "__docs__"}
    try:
        for block in blocks(path):
            where = f"docs/{block.page}:{block.line}"
            if block.lang not in RUN or block.skip:
                continue
            if block.lang == "python":
                code = compile("\n" * block.line + block.code, f"docs/{block.page}", "exec")
                printed = io.StringIO()
                with contextlib.redirect_stdout(printed):
                    exec(code, namespace)
                if block.expected is not None:
                    assert same_output(block.expected, printed.getvalue()), \
                        f"{where}: the block printed\n{printed.getvalue()}\nbut the page shows\n{block.expected}"
            else:
                for command, expected in shell_commands(block):
                    out = run_shell(command, tmp_path, path_dir, where)
                    if expected is not None:
                        assert same_output(expected, out), \
                            f"{where}: `{command}` printed\n{out}\nbut the page shows\n{expected}"
    finally:
        from opportune.service.testing import ServiceProcess

        for value in namespace.values():     # a page's server never outlives it, even when a block fails
            if isinstance(value, ServiceProcess):
                value.stop()


def test_the_tutorials_run_and_show_what_they_print():
    """Each tutorial has Python examples whose output the page shows (and the test above checks)."""
    for name in TUTORIALS:
        found = blocks(DOCS / name)
        assert [b for b in found if b.lang == "python" and b.expected is not None], name
    gearbox = "\n".join(b.expected or "" for b in blocks(DOCS / "gearbox.md"))
    assert "336 admissible sequences" in gearbox
    assert "install cl (from buffer)" in gearbox and "done" in gearbox
    skipped = [(b.page, b.line, b.skip) for p in pages() for b in blocks(p) if b.skip]
    assert all("opportune serve" in b.code for p in pages() for b in blocks(p) if b.skip), skipped


def test_the_output_check_is_strict():
    assert same_output("336\n", "336")
    assert same_output("about ...e+46 (log10 ...)", "about 9.1e+46 (log10 46.9)")
    assert not same_output("336", "337")
    assert not same_output("a\nb", "a")


def _network_off() -> list[str]:
    """A prefix that runs a command without a network (a new network namespace), where the system allows it."""
    if shutil.which("unshare") and subprocess.run(["unshare", "-n", "true"], capture_output=True).returncode == 0:
        return ["unshare", "-n"]
    return []


def test_the_site_builds_offline_with_no_warning(tmp_path):
    import importlib.util

    if importlib.util.find_spec("mkdocs") is None:
        pytest.fail("MkDocs is not installed: `make setup` installs the docs extra (pip install '.[docs]')")
    site = tmp_path / "site"
    dead = "http://127.0.0.1:9"     # and, where no network namespace can be made, every proxy leads nowhere
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "http_proxy": dead, "https_proxy": dead, "HTTP_PROXY": dead,
           "HTTPS_PROXY": dead, "ALL_PROXY": dead, "no_proxy": "", "NO_PROXY": ""}
    command = [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site),
               "--config-file", str(ROOT / "mkdocs.yml")]
    done = subprocess.run([*_network_off(), *command], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    log = done.stdout + done.stderr
    assert done.returncode == 0, log
    warnings = [line for line in log.splitlines() if re.search(r"\bWARNING\b|\bERROR\b", line)]
    assert not warnings, "\n".join(warnings)
    for page in ("index.html", "gearbox/index.html", "http/index.html", "large-plans/index.html", "cli/index.html",
                 "reference/engine/index.html", "img/gearbox-mean-time.png"):
        assert (site / page).is_file(), page
    cli = (site / "cli" / "index.html").read_text(encoding="utf-8")
    assert "opportune simulate" in cli and "--decision-budget" in cli and "cli-help" not in cli
    engine = (site / "reference" / "engine" / "index.html").read_text(encoding="utf-8")
    assert "count_result" in engine and ":class:`" not in engine and ":meth:`" not in engine
    # Read offline too: no page loads anything from elsewhere (fonts, scripts, styles).
    for html in site.rglob("*.html"):
        text = html.read_text(encoding="utf-8")
        outside = re.findall(r'<(?:script|link|img)\b[^>]*(?:src|href)="(?:https?:)?//[^"]*"', text)
        assert not outside, (html.relative_to(site), outside[:3])
