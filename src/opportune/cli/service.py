"""The service's commands: ``opportune serve``, ``opportune token create|list|revoke`` and ``opportune opcua
cert``, added to the main command line by :func:`register`.

Only typer is imported here at import time: FastAPI, uvicorn and SQLAlchemy
(the ``service`` extra) load inside the commands, so the rest of the command
line works without them.
"""

from __future__ import annotations

import json
from typing import Optional

import typer

from opportune.limits import DEFAULT_MAX_BODY, MAX_BODY, MIN_BODY, check_option

DB_HELP = "Database: a SQLAlchemy URL (sqlite:///path, postgresql+psycopg://...) or a SQLite file path " \
          "[default: $OPPORTUNE_DB or ./opportune.db]"


def echo(text: str, err: bool = False) -> None:
    """Print a line as every command does: control characters written as escapes (a name or a label
    stored by an older version, a database URL or a token id from the command line never reach the
    terminal raw); :func:`opportune.cli_count.printable_line` is the one escaping of the command line."""
    from opportune.cli_count import printable_line

    typer.echo(printable_line(text), err=err)


def _fail(message: str) -> None:
    echo(f"error: {message}", err=True)
    raise typer.Exit(1)


SERVICE_EXTRA = "pip install 'opportune[service]'"


def _require(*modules: str) -> None:
    """Exit with one line naming the extra to install if a module of the ``service`` extra is missing."""
    import importlib

    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError as exc:
            missing = exc.name or name
            _fail(f"this command needs the 'service' extra ({missing} is not installed): {SERVICE_EXTRA}")


def _store(db: Optional[str]):
    _require("sqlalchemy")
    from opportune.service.config import database_url
    from opportune.service.storage import Store

    url = database_url(db)
    try:
        return Store(url)
    except Exception as exc:  # bad URL, missing driver, unreachable server, unwritable file
        from opportune.service.server import safe_url

        _fail(f"cannot open the database {safe_url(url)}: {type(exc).__name__}: {str(exc).splitlines()[0]}")


def serve(
    db: Optional[str] = typer.Option(None, "--db", help=DB_HELP, show_default=False),
    host: str = typer.Option("127.0.0.1", "--host", help="Address to listen on"),
    port: int = typer.Option(8700, "--port", min=0, max=65535, help="TCP port"),
    max_body: int = typer.Option(DEFAULT_MAX_BODY, "--max-body",
                                 help=f"Largest request body accepted, in bytes ({MIN_BODY}–{MAX_BODY}: at most the "
                                      "largest plan file the readers read)"),
    access_log: bool = typer.Option(True, "--access-log/--no-access-log", help="Log every request (credentials redacted)"),
    workers: int = typer.Option(1, "--workers", min=1, max=64,
                                help="Server processes sharing the port and the database (more than 1: PostgreSQL only)"),
    memory_cap: Optional[int] = typer.Option(None, "--memory-cap", min=16, max=1 << 22,
                                             help="Megabytes the server may hold beyond its footprint at start "
                                                  "(the plans' memos, caches, programmes: shrunk, then least "
                                                  "recently used plans evicted, between requests); default a "
                                                  "quarter of the machine's memory",
                                             show_default=False),
    warm_up_seconds: float = typer.Option(30.0, "--warm-up-seconds", min=0.0, max=3600.0,
                                          help="Most seconds a plan's warm-up (counting its first state, once per "
                                               "plan, in the background) may take"),
    optimum_seconds: float = typer.Option(600.0, "--optimum-seconds", min=0.0, max=86400.0,
                                          help="With a decision budget, most seconds the preparation of the "
                                               "look-ahead's exact optimum may take, in the background, once per "
                                               "plan and setting (its runs decide by it once it is ready)"),
    poll_seconds: float = typer.Option(2.0, "--poll-seconds", min=0.05, max=86400.0,
                                       help="How often an event stream looks for changes made by other processes "
                                            "(PostgreSQL also pushes them at once)"),
    request_seconds: float = typer.Option(10.0, "--request-seconds", min=0.5, max=3600.0,
                                          help="Most seconds a request may take to arrive whole (its line, headers "
                                               "and body, from its first byte or the connection's opening); a slower "
                                               "one's connection is closed"),
    opcua: bool = typer.Option(False, "--opcua", help="Serve OPC UA too (at --opcua-endpoint), on the same runs"),
    opcua_endpoint: str = typer.Option("opc.tcp://127.0.0.1:4840", "--opcua-endpoint", metavar="URL",
                                       help="Where OPC UA listens (with --opcua)"),
    http: bool = typer.Option(True, "--http/--no-http", help="Serve HTTP (--no-http: OPC UA alone)"),
    opcua_pki: str = typer.Option("opcua-pki", "--opcua-pki",
                                  help="The OPC UA certificates' folder: own/ the server's (made on first start), "
                                       "trusted/ the clients' certificates"),
    opcua_anonymous: Optional[str] = typer.Option(None, "--opcua-anonymous", metavar="CELL",
                                                  help="Development only, on a loopback endpoint: accept anonymous "
                                                       "OPC UA sessions without security, acting as cell CELL",
                                                  show_default=False),
    opcua_max_connections: Optional[int] = typer.Option(
        None, "--opcua-max-connections", metavar="N", show_default=False,
        help="Lower the OPC UA server's cap on connections at once (default and most: 100; those without a "
             "session at most 16 of them)"),
    opcua_login_seconds: Optional[float] = typer.Option(
        None, "--opcua-login-seconds", metavar="S", show_default=False,
        help="Lower the seconds an OPC UA connection has to activate a session, else closed (default and most: "
             "30; HEL within 10 of them)"),
):
    """Serve the sequencer over HTTP for robot cells, with the live dashboard at /; with --opcua, over OPC UA too."""
    try:
        check_option("--max-body", max_body, MAX_BODY, MIN_BODY)
    except ValueError as exc:
        _fail(str(exc))
    if not opcua and (not http or opcua_anonymous is not None or opcua_max_connections is not None
                      or opcua_login_seconds is not None):
        _fail("--no-http and the --opcua-... options are for OPC UA: add --opcua")
    _require("sqlalchemy", *(("fastapi", "uvicorn") if http else ()), *(("asyncua",) if opcua else ()))
    options = _opcua_options(opcua_endpoint, opcua_pki, opcua_anonymous, opcua_max_connections, opcua_login_seconds,
                             workers) if opcua else None
    if workers > 1:
        _check_workers(db, workers)
    store = _store(db)  # fail early, with a clear message, on a bad database (and create the schema once)
    store.dispose()
    from opportune.service.server import safe_url, serve as run

    procs = f"; {workers} processes" if workers > 1 else ""
    if http:
        echo(f"opportune service on http://{host}:{port}/  (API docs /docs; database {safe_url(store.url)}{procs})",
                   err=True)
    if options is not None:
        echo(f"opportune OPC UA server on {options.endpoint}  (certificates in {options.pki}; namespace "
                   "urn:opportune:sequencer)", err=True)
    try:
        run(db_url=store.url, host=host, port=port, max_body=max_body, access_log=access_log, workers=workers,
            settings={"memory_cap": None if memory_cap is None else memory_cap << 20,
                      "warm_up_seconds": warm_up_seconds, "optimum_seconds": optimum_seconds,
                      "sse_poll_seconds": poll_seconds,
                      "request_seconds": request_seconds}, opcua=options, http=http)
    except Exception as exc:
        from opportune.service.opcua import OpcUaError

        if isinstance(exc, OpcUaError):
            _fail(str(exc))
        raise


def _opcua_options(endpoint: str, pki: str, anonymous: Optional[str], max_connections: Optional[int],
                   login_seconds: Optional[float], workers: int):
    """``serve --opcua``'s options, checked (one process; bounds only lowered; the anonymous cell's name);
    exits with one line saying what to change."""
    if workers > 1:
        _fail("--opcua serves from one process: use --workers 1 (several OPC UA servers cannot share a port)")
    from pathlib import Path

    from opportune.service.opcua import OpcUaError, OpcUaOptions
    from opportune.service.opcua_transport import TransportBounds

    lowered = {}
    for name, value in (("max_connections", max_connections), ("login_seconds", login_seconds)):
        if value is not None:
            try:      # lower only: past a bound is refused, saying it
                lowered[name] = getattr(TransportBounds(**{name: value}), name)
            except ValueError as exc:
                _fail(f"--opcua-{name.replace('_', '-')}: {exc}")
    transport = TransportBounds(**lowered)
    transport = transport.lowered(hello_seconds=transport.login_seconds,
                                  max_unauthenticated=transport.max_connections)
    options = OpcUaOptions(endpoint=endpoint, pki=Path(pki), anonymous_cell=anonymous, transport=transport)
    try:
        options.checked()
    except OpcUaError as exc:
        _fail(str(exc))
    if anonymous is not None:
        from opportune.service.auth import TokenError, check_cell_name

        try:
            check_cell_name(anonymous)
        except TokenError as exc:
            _fail(f"--opcua-anonymous: {exc}")
    return options


def _check_workers(db: Optional[str], workers: int) -> None:
    """Several server processes share one database: PostgreSQL only (exits saying so otherwise)."""
    from opportune.service.config import database_url

    url = database_url(db)
    if not url.startswith("postgresql"):
        _fail(f"--workers {workers} needs PostgreSQL (--db postgresql+psycopg://user@host/db): several "
              "processes share one database, and a SQLite file takes one writer at a time (they would only "
              "queue behind each other). Serve SQLite with one process (--workers 1).")


def token_create(
    cell: Optional[str] = typer.Argument(None, help="The cell this token drives (created if new)", show_default=False),
    operator: Optional[str] = typer.Option(None, "--operator", help="Create an operator token (reads every run) with this name"),
    db: Optional[str] = typer.Option(None, "--db", help=DB_HELP, show_default=False),
    as_json: bool = typer.Option(False, "--json", help="Print {id, token, role, cell} as JSON"),
):
    """Create a bearer token and print it once (only its SHA-256 is stored)."""
    if (cell is None) == (operator is None):
        _fail("give a CELL, or --operator NAME (not both)")
    _require("sqlalchemy")
    from opportune.service.auth import TokenError, create_token

    store = _store(db)
    try:
        token_id, token = create_token(store, cell=cell, operator=operator)
    except TokenError as exc:
        _fail(str(exc))
    finally:
        store.dispose()
    role = "operator" if operator else "cell"
    if as_json:
        echo(json.dumps({"id": token_id, "token": token, "role": role, "cell": cell, "label": operator or ""}))
        return
    echo(token)
    who = f"operator {operator!r}" if operator else f"cell {cell!r}"
    where = ""
    if db is not None:      # the same database (a password in a URL is not repeated: `***`)
        import shlex

        from opportune.service.server import safe_url

        where = f" --db {shlex.quote(safe_url(db) if '://' in db else db)}"
    echo(f"token {token_id} for {who}: shown once, keep it secret "
               f"(revoke with `opportune token revoke {token_id}{where}`)", err=True)


def token_list(db: Optional[str] = typer.Option(None, "--db", help=DB_HELP, show_default=False),
               as_json: bool = typer.Option(False, "--json", help="Machine-readable output")):
    """List tokens (ids, roles, cells; never the tokens themselves)."""
    _require("sqlalchemy")
    from opportune.service.auth import list_tokens
    from opportune.service.views import iso

    store = _store(db)
    try:
        rows = list_tokens(store)
    finally:
        store.dispose()
    for r in rows:
        r["created_at"], r["revoked_at"] = iso(r["created_at"]), iso(r["revoked_at"])
    if as_json:
        echo(json.dumps(rows, indent=2))
        return
    if not rows:
        echo("no tokens: create one with `opportune token create CELL`")
    for r in rows:
        who = f"cell {r['cell']}" if r["role"] == "cell" else f"operator {r['label']}"
        state = f"revoked {r['revoked_at']}" if r["revoked_at"] else "active"
        echo(f"{r['id']}  {who:<30} created {r['created_at']}  {state}")


def token_revoke(token_id: str = typer.Argument(..., help="The token's id, from `opportune token list`"),
                 db: Optional[str] = typer.Option(None, "--db", help=DB_HELP, show_default=False),
                 as_json: bool = typer.Option(False, "--json", help="Print {id, revoked} as JSON")):
    """Revoke a token: a running server refuses it within 1 s (REVOCATION_SECONDS), on HTTP and OPC UA."""
    _require("sqlalchemy")
    from opportune.service.auth import TokenError, revoke_token

    store = _store(db)
    try:
        revoke_token(store, token_id)
    except TokenError as exc:
        _fail(str(exc))
    finally:
        store.dispose()
    if as_json:
        echo(json.dumps({"id": token_id, "revoked": True}))
        return
    echo(f"token {token_id} revoked", err=True)


def opcua_cert(folder: str = typer.Argument(..., help="The folder to write the certificate and key into"),
               app_uri: str = typer.Option("urn:opportune:client", "--app-uri",
                                           help="The client's application URI (the client must connect with it)"),
               trust_in: Optional[str] = typer.Option(None, "--trust-in",
                                                      help="A server's PKI folder (--opcua-pki): copy the "
                                                           "certificate into its trusted/ too"),
               as_json: bool = typer.Option(False, "--json", help="Print {certificate, key, made, app_uri, "
                                                                  "trusted} as JSON")):
    """Make an OPC UA client's certificate and key (for UaExpert, a PLC, ...) and say how the server trusts it."""
    _require("asyncua")
    from pathlib import Path

    from opportune.service.opcua_security import client_certificate, client_files, shown

    if not app_uri or len(app_uri) > 200 or not app_uri.isprintable() or ":" not in app_uri:
        _fail(f"--app-uri {shown(app_uri)} is not a URI: give e.g. urn:my-company:cell-1")
    cert, key = client_files(folder)
    existed = cert.exists() and key.exists()
    try:
        cert, key = client_certificate(folder, app_uri, trust_in=trust_in)
    except OSError as exc:
        _fail(f"cannot write into {shown(folder)}: {exc.strerror or exc}: choose a folder you can write")
    if as_json:
        echo(json.dumps({"certificate": str(cert), "key": str(key), "made": not existed, "app_uri": app_uri,
                         "trusted": None if trust_in is None else str(Path(trust_in) / "trusted")}))
        return
    made = "kept (already made for this URI)" if existed else "wrote"
    echo(f"{made} {shown(cert)}: the client's certificate (DER)")
    echo(f"{made} {shown(key)}: its private key (PEM, readable by you only: keep it secret)")
    echo(f"the client connects with application URI {shown(app_uri)}, Basic256Sha256, Sign & Encrypt, "
         "user name and password (the cell's token)")
    if trust_in is not None:
        echo(f"trusted: copied into {shown(Path(trust_in) / 'trusted')} (no restart needed)")
    else:
        echo(f"to trust it, copy {shown(cert)} into the server's trust list, the folder trusted/ in its "
             "--opcua-pki folder (default opcua-pki/trusted/); no restart needed")


def register(app: typer.Typer) -> None:
    """Add ``serve``, ``token create|list|revoke`` and ``opcua cert`` to the main command line."""
    app.command("serve")(serve)
    tokens = typer.Typer(help="Bearer tokens for cells and operators.", no_args_is_help=True)
    tokens.command("create")(token_create)
    tokens.command("list")(token_list)
    tokens.command("revoke")(token_revoke)
    app.add_typer(tokens, name="token")
    opcua = typer.Typer(help="OPC UA clients' certificates.", no_args_is_help=True)
    opcua.command("cert")(opcua_cert)
    app.add_typer(opcua, name="opcua")
