"""``opportune token create|list|revoke`` and ``opportune serve``'s refusals, and what ``register`` imports."""

from __future__ import annotations

import hashlib
import sqlite3
import subprocess
import sys

from typer.testing import CliRunner

from opportune.cli import app

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, list(args))


def test_register_imports_only_typer():
    code = ("import sys, typer; import opportune.cli.service as c; app = typer.Typer(); c.register(app); "
            "heavy = [m for m in ('fastapi', 'uvicorn', 'sqlalchemy', 'starlette', 'httpx') if m in sys.modules]; "
            "print(','.join(heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_serve_and_token_are_commands():
    r = invoke("--help")
    assert r.exit_code == 0 and "serve" in r.output and "token" in r.output
    r = invoke("serve", "--help")
    assert r.exit_code == 0 and "--db" in r.output and "--max-body" in r.output and "8700" in r.output


def test_tokens_are_printed_once_and_stored_hashed(tmp_path):
    db = tmp_path / "t.db"
    r = invoke("token", "create", "cell-1", "--db", str(db))
    assert r.exit_code == 0, r.output
    token = r.stdout.strip().splitlines()[0]
    assert token.startswith("opp_") and len(token) > 40
    r = invoke("token", "create", "--operator", "alice", "--db", f"sqlite:///{db}", "--json")
    assert r.exit_code == 0, r.output
    import json

    op = json.loads(r.stdout)
    assert op["role"] == "operator" and op["token"].startswith("opp_") and op["cell"] is None
    with sqlite3.connect(db) as con:
        rows = con.execute("SELECT id, hash, role, cell FROM tokens ORDER BY created_at").fetchall()
        dump = "\n".join(con.iterdump())
    assert [(role, cell) for _, _, role, cell in rows] == [("cell", "cell-1"), ("operator", None)]
    assert rows[0][1] == hashlib.sha256(token.encode()).hexdigest()
    assert token not in dump and op["token"] not in dump  # only hashes are stored
    r = invoke("token", "list", "--db", str(db))
    assert r.exit_code == 0 and "cell cell-1" in r.stdout and "operator alice" in r.stdout and "opp_" not in r.stdout
    r = invoke("token", "revoke", rows[0][0], "--db", str(db))
    assert r.exit_code == 0
    assert "revoked" in invoke("token", "list", "--db", str(db)).stdout
    r = invoke("token", "revoke", rows[0][0], "--db", str(db))
    assert r.exit_code == 1 and "no active token" in r.output


def test_token_and_serve_mistakes_are_clear(tmp_path):
    db = str(tmp_path / "t.db")
    for args, words in [
        (("token", "create", "--db", db), "give a CELL"),
        (("token", "create", "c1", "--operator", "x", "--db", db), "not both"),
        (("token", "create", "bad cell!", "--db", db), "invalid cell name"),
        (("token", "create", "c1", "--db", str(tmp_path / "no" / "such" / "dir" / "t.db")), "cannot open the database"),
        (("serve", "--db", "nosuchdriver://x"), "cannot open the database"),
    ]:
        r = invoke(*args)
        assert r.exit_code == 1, (args, r.output)
        assert words in r.output and "Traceback" not in r.output, r.output


def test_the_revoke_hint_names_the_same_database(tmp_path):
    """The hint printed after a token is created revokes it in the database it was created in (without
    `--db` it made a stray ./opportune.db); a URL's password is not repeated."""
    db = tmp_path / "my tokens.db"
    r = invoke("token", "create", "cell-1", "--db", str(db))
    assert r.exit_code == 0, r.output
    hint = r.stderr.strip().splitlines()[-1]
    token_id = hint.split()[1]
    assert f"opportune token revoke {token_id} --db '{db}'" in hint
    r = invoke("token", "revoke", token_id, "--db", str(db))
    assert r.exit_code == 0, r.output
    assert not (tmp_path / "opportune.db").exists()
