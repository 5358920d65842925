"""Hostile text: control characters in plans, files, requests and on terminals; XML encodings; text
after an .alb file's end; requests that never finish arriving.

Every refusal is a 4xx (service) or exit 1 with a message (command line), no traceback, nothing
changed, and no control character reaches a terminal raw.  Both stores the service supports.
"""

from __future__ import annotations

import json
import socket
import subprocess
import threading
import time
import uuid

import pytest

from conftest import GEARBOX, run_cli as run_in_process
from opportune import make_plan
from opportune.planning.plan import PlanError

pytest.importorskip("fastapi")

from opportune.service.testing import Client, ServiceProcess, free_port

ESC_ID = "a\x1b]0;pwned\x07\x1b[2J"
CONTROLS = ["\x00", "\x1b", "\x07", "\x7f", "\x9b", "\x85"]


def run_cli(*args) -> subprocess.CompletedProcess:
    """``opportune ARGS`` in this process (typer's runner: what ``python -m opportune.cli`` runs for a command
    line without ``--json``, without a new interpreter each time), as a finished process: the exit code, and
    standard output and error apart.  The runner's own check holds too: no traceback, no exception but the exit."""
    result = run_in_process(*args)
    return subprocess.CompletedProcess(args, result.exit_code, result.stdout, result.stderr)


def raw_controls(text: str) -> list[str]:
    """Control characters in output (tab and line feed are layout)."""
    return [c for c in text if (ord(c) < 32 and c not in "\t\n") or 0x7f <= ord(c) <= 0x9f]


# ---------------------------------------------------------------- plans

@pytest.mark.parametrize("char", CONTROLS)
def test_a_plan_with_a_control_character_is_refused_and_says_which(char):
    with pytest.raises(PlanError) as info:
        make_plan([f"a{char}b", "c"], {"c": [f"a{char}b"]})
    message = str(info.value)
    assert f"U+{ord(char):04X}" in message and not raw_controls(message)
    with pytest.raises(PlanError):
        make_plan(["a", "b"], {}, name=f"plan{char}")


def test_tabs_and_line_breaks_stay_allowed_in_a_description(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text('name: p\ndescription: "two\\tcolumns\\nand lines\\r\\n"\nparts: [a, b]\n'
                    "strategies: [{name: s, requires: {b: [a]}}]\n")
    out = run_cli("check", path)
    assert out.returncode == 0, out.stderr


@pytest.mark.parametrize("where", ["id", "name", "plan name", "file name"])
def test_no_escape_sequence_from_a_plan_reaches_the_terminal(tmp_path, where):
    part = ESC_ID if where == "id" else "a"
    name = ESC_ID if where == "plan name" else "p"
    fname = ("x" + ESC_ID + ".json") if where == "file name" else "p.json"
    doc = {"name": name, "parts": [{"id": part, "name": ESC_ID if where == "name" else "A"}, "b"],
           "strategies": [{"name": "s", "requires": {"b": [part]}}]}
    path = tmp_path / fname
    path.write_text(json.dumps(doc))
    for command in (["check", path], ["count", path], ["graph", path, "--format", "dot"]):
        out = run_cli(*command)
        assert "Traceback" not in out.stderr, out.stderr
        assert not raw_controls(out.stdout + out.stderr), (command, out.stdout + out.stderr)
        if where != "file name":
            assert out.returncode == 1 and "U+001B" in out.stdout + out.stderr, (command, out.stdout, out.stderr)


EVIL = "op\x1b]0;T\x07\x9b2J\x1b[31m"   # ESC (an OSC title), BEL, CSI (C1) and ESC [ (a colour)


def _cli(*args):
    from typer.testing import CliRunner

    from opportune.cli import app

    return CliRunner().invoke(app, [str(a) for a in args])


def _escaped(out) -> str:
    text = out.stdout + out.stderr
    assert "Traceback" not in text and out.exception is None or isinstance(out.exception, SystemExit), text
    assert not raw_controls(text), text
    return text


@pytest.mark.parametrize("command", [
    ["check", "{evil}.yaml"], ["check", "{evil}.yaml", "--json"], ["count", "{evil}.yaml"],
    ["graph", "{evil}.yaml"], ["graph", "{evil}.yaml", "--json"], ["replay", "example:gearbox", "{evil}.looks"],
    ["replay", "{evil}.yaml", "x.looks"], ["convert", "{evil}.yaml", "out.json"],
    ["convert", "example:gearbox", "{evil}/out.json"], ["graph", "example:gearbox", "-o", "{evil}/g.dot"],
    ["simulate", "{evil}.yaml"], ["evaluate", "{evil}.yaml"], ["relax", "{evil}.yaml"], ["learn", "{evil}.seq"],
    ["token", "create", "{evil}", "--db", "{db}"], ["token", "create", "--operator", "{evil}", "--db", "{db}"],
    ["token", "revoke", "{evil}", "--db", "{db}"], ["token", "list", "--db", "{evil}://x"],
    ["serve", "--db", "{evil}://x"],
])
def test_no_control_character_of_user_text_reaches_the_terminal_from_any_command(tmp_path, command):
    """ESC, BEL and CSI in a file name, a cell or operator name, a token id or a database URL: every command
    that prints it writes them as escapes (one escaping, :func:`opportune.cli_count.printable`)."""
    pytest.importorskip("sqlalchemy")
    args = [a.format(evil=str(tmp_path / EVIL) if a.startswith("{evil}.") or "/" in a else EVIL,
                     db=tmp_path / "t.db") for a in command]
    out = _cli(*args)
    assert out.exit_code in (1, 2), (args, out.output)
    text = _escaped(out)
    assert "\\x1b" in text or "\\u001b" in text, text          # said, escaped


def test_names_stored_with_control_characters_are_listed_escaped(tmp_path):
    """An operator name is checked like a cell's (letters, digits, '.', '_', '-'); one stored before that (or
    by hand) is listed with its control characters escaped, and so is its cell."""
    pytest.importorskip("sqlalchemy")
    import sqlite3

    db = tmp_path / "t.db"
    refused = _cli("token", "create", "--operator", EVIL, "--db", db)
    assert refused.exit_code == 1 and "invalid operator name" in refused.output
    for name in ("ops\n", "a b", "x" * 101, ""):
        assert _cli("token", "create", "--operator", name, "--db", db).exit_code == 1, name
        assert _cli("token", "create", name, "--db", db).exit_code == 1, name
    assert _cli("token", "create", "--operator", "alice.b-1", "--db", db).exit_code == 0
    with sqlite3.connect(db) as con:   # as an older version stored it
        con.execute("UPDATE tokens SET label = ?", (EVIL,))
    listed = _cli("token", "list", "--db", db)
    assert listed.exit_code == 0
    assert "operator op\\x1b]0;T\\x07\\x9b2J" in _escaped(listed)
    as_json = _cli("token", "list", "--db", db, "--json")
    assert json.loads(as_json.stdout)[0]["label"] == EVIL and not raw_controls(as_json.stdout)


def test_printable_writes_controls_as_escapes_and_keeps_layout():
    from opportune.cli import printable

    assert printable("a\x1b[2Jb\tc\nd\x00\x9b") == "a\\x1b[2Jb\tc\nd\\x00\\x9b"


# ---------------------------------------------------------------- files

GRAPHML = ('<?xml version="1.0" encoding="{enc}"?>\n<graphml xmlns="http://graphml.graphdrawing.org/xmlns">'
           '<graph edgedefault="directed"><node id="a"/><node id="b"/><edge source="a" target="b"/></graph></graphml>\n')


@pytest.mark.parametrize("enc", ["x-nope", "utf-32", "utf-7", "rot13", "base64", "hex", "zlib", "idna", "punycode",
                                 "uu_codec", "bz2"])
def test_a_graphml_file_declaring_a_strange_encoding_is_refused_with_a_message(tmp_path, enc):
    path = tmp_path / "g.graphml"
    path.write_text(GRAPHML.format(enc=enc))
    out = run_cli("check", path)
    assert out.returncode == 1 and "Traceback" not in out.stderr, out.stderr
    assert "encoding" in out.stdout + out.stderr and "UTF-8" in out.stdout + out.stderr


@pytest.mark.parametrize("enc", ["UTF-8", "utf8", "us-ascii", "ISO-8859-1"])
def test_a_graphml_file_in_a_plain_encoding_reads(tmp_path, enc):
    path = tmp_path / "g.graphml"
    path.write_text(GRAPHML.format(enc=enc))
    out = run_cli("check", path)
    assert out.returncode == 0, out.stdout + out.stderr


def alb(after: str) -> str:
    return "<number of tasks>\n2\n<task times>\n1 1\n2 1\n<precedence relations>\n1,2\n<end>\n" + after


def test_text_after_an_alb_files_end_is_a_warning_and_a_second_graph_an_error(tmp_path):
    from opportune.formats.alb import check_alb_bytes

    clean = check_alb_bytes(alb("").encode(), file="a.alb")
    assert clean.plan is not None and not clean.problems
    noted = check_alb_bytes(alb("\nnotes: measured 2024\nmore\n").encode(), file="a.alb")
    assert noted.plan is not None
    (warning,) = noted.problems
    assert warning.severity == "warning" and warning.line == 10 and "2 lines after `<end>`" in warning.message
    second = check_alb_bytes(alb("<number of tasks>\n1\n<task times>\n1 1\n<end>\n").encode(), file="a.alb")
    assert second.plan is None
    assert any("second graph" in p.message and p.line == 9 for p in second.problems)


# ---------------------------------------------------------------- the service, on both stores

@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def svc(request, tmp_path_factory):
    where = tmp_path_factory.mktemp("text")
    db = where / "t.db" if request.param == "sqlite" else request.getfixturevalue("postgres").database("text")
    with ServiceProcess(db, log=where / "t.log") as s:
        yield s


@pytest.fixture(scope="module")
def cell(svc):
    c = Client(svc.url, svc.token(cell="cell-t"))
    yield c
    c.close()


def error_of(r, *statuses) -> dict:
    assert r.status_code in statuses, (r.status_code, r.text)
    body = r.json()
    assert set(body) == {"error"} and body["error"]["message"]
    return body["error"]


def post_raw(cell, path: str, raw: bytes):
    return cell.post(path, content=raw, headers={"Content-Type": "application/json",
                                                  "Idempotency-Key": uuid.uuid4().hex}, key=False)


def test_u0000_and_other_controls_in_any_request_text_are_a_4xx_and_change_nothing(svc, cell):
    r = cell.post("/plans", content=GEARBOX.read_text(), headers={"Content-Type": "application/yaml"}, key=False)
    assert r.status_code in (200, 201), r.text
    plan = r.json()["id"]
    run = cell.post("/runs", {"plan": plan}).json()["id"]
    runs = len(cell.get("/runs").json()["runs"])
    plans = len(cell.get("/plans").json()["plans"])
    for char in ("\\u0000", "\\u001b", "\\u009b"):
        error_of(post_raw(cell, "/runs", f'{{"plan": "{plan}", "label": "x{char}y"}}'.encode()), 422)
        error_of(post_raw(cell, f"/runs/{run}/looks", f'{{"visible": ["ca{char}"]}}'.encode()), 422)
        doc = {"name": "p", "parts": ["a", "b"], "strategies": [{"name": "s", "requires": {"b": ["a"]}}]}
        text = json.dumps(doc).replace('"a"', f'"a{char}b"')
        error_of(post_raw(cell, "/plans", text.encode()), 422)
        yaml_text = f'name: p\nparts: ["a{char}b", c]\nstrategies: [{{name: s, requires: {{c: ["a{char}b"]}}}}]\n'
        err = error_of(cell.post("/plans", content=yaml_text, headers={"Content-Type": "application/yaml"},
                                 key=False), 422)
        assert "control character" in err["message"] or any("control character" in p["message"]
                                                            for p in err.get("problems", [])), err
    for path in ("/runs/1%00", "/plans/ab%00cd", "/plans/ab%1bcd", "/runs?label=a%00b", "/runs?cursor=%1b"):
        error_of(cell.get(path), 400, 404, 422)
    # an escaped backslash before u0000 is text, not a control character
    ok = post_raw(cell, "/runs", f'{{"plan": "{plan}", "label": "C:\\\\u0000"}}'.encode())
    assert ok.status_code == 201, ok.text
    assert len(cell.get("/runs").json()["runs"]) == runs + 1
    assert len(cell.get("/plans").json()["plans"]) == plans
    assert cell.get(f"/runs/{run}").json()["seq"] == 0
    assert cell.get("/healthz").status_code == 200


# ---------------------------------------------------------------- requests that never arrive

class SlowGuard:
    """The service's protocol in a thread, with a short arrival deadline."""

    def __init__(self, tmp_path, seconds: float):
        import uvicorn

        from opportune.service.app import create_app
        from opportune.service.config import Settings
        from opportune.service.protocol import Guarded
        from opportune.service.storage import Store

        self.store = Store(f"sqlite:///{tmp_path / 's.db'}")
        app = create_app(Settings(db_url=self.store.url), store=self.store)
        self.port = free_port()
        protocol = type("Quick", (Guarded,), {"seconds": seconds})
        config = uvicorn.Config(app, host="127.0.0.1", port=self.port, log_config=None, access_log=False,
                                http=protocol, timeout_keep_alive=30)
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def __enter__(self):
        self.thread.start()
        for _ in range(1000):
            if self.server.started:
                return self
            time.sleep(0.02)
        raise AssertionError("the server did not start")

    def __exit__(self, *exc):
        self.server.should_exit = True
        self.thread.join(10)


def response(s: socket.socket) -> bytes:
    """One whole HTTP response (headers and a Content-Length body) read from ``s``."""
    data = b""
    while b"\r\n\r\n" not in data:
        data += s.recv(4096)
    head, _, body = data.partition(b"\r\n\r\n")
    length = next(int(line.split(b":")[1]) for line in head.split(b"\r\n") if line.lower().startswith(b"content-length"))
    while len(body) < length:
        body += s.recv(4096)
    return head + b"\r\n\r\n" + body


def closed_while_trickling(port: int, data: bytes, gap: float) -> tuple[bool, int]:
    """Send ``data`` a byte every ``gap`` seconds; ``(closed by the server before the end, bytes sent)``."""
    with socket.create_connection(("127.0.0.1", port)) as s:
        s.settimeout(gap)
        for i, byte in enumerate(data):
            try:
                s.sendall(bytes([byte]))
                if s.recv(1024) == b"":
                    return True, i + 1
            except socket.timeout:
                continue
            except OSError:             # reset: closed
                return True, i + 1
        return False, len(data)


def test_a_trickled_request_or_a_silent_connection_is_closed_and_whole_requests_are_served(tmp_path):
    """A deadline of 0.5 s against a request trickled over 15 s: closed long before its end (the same
    request sent at once is answered); a connection that sends nothing is closed too."""
    with SlowGuard(tmp_path, 0.5) as srv:
        request = b"GET /healthz HTTP/1.1\r\nHost: x\r\nX-Slow: " + b"a" * 40 + b"\r\n\r\n"
        closed, sent = closed_while_trickling(srv.port, request, 0.2)
        assert closed and sent < len(request) // 2, (closed, sent)
        with socket.create_connection(("127.0.0.1", srv.port)) as s:
            s.sendall(request)
            s.settimeout(30)
            assert response(s).startswith(b"HTTP/1.1 200")
            # kept alive, then the next request arrives whole: answered as well
            time.sleep(1.0)
            s.sendall(request)
            assert response(s).startswith(b"HTTP/1.1 200")
        with socket.create_connection(("127.0.0.1", srv.port)) as s:
            s.settimeout(30)
            assert s.recv(1024) == b""          # nothing sent: closed by the server (not by this timeout)
        body = b'{"plan": "x"}'
        head = (b"POST /runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: "
                + str(len(body) + 30).encode() + b"\r\n\r\n")
        closed, sent = closed_while_trickling(srv.port, head + body + b" " * 30, 0.2)
        assert closed and sent < len(head) + len(body) + 30


def test_a_shipped_plans_problems_name_it_by_its_short_name():
    """`opportune check example:gearbox-overconstrained` says `example:gearbox-overconstrained:17`, not the
    path where the package is installed."""
    out = run_cli("check", "example:gearbox-overconstrained")
    assert out.returncode == 1
    lines = [line for line in (out.stdout + out.stderr).splitlines() if "error" in line]
    assert lines and all(line.startswith("example:gearbox-overconstrained:") for line in lines), lines
    assert "site-packages" not in out.stdout + out.stderr and "/datasets/" not in out.stdout + out.stderr
