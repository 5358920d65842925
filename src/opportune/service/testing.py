"""A real service on a loopback port, for integration tests (ours, and a cell controller's).

:class:`ServiceProcess` runs ``opportune serve`` in a subprocess on
127.0.0.1 and a free port, waits until it answers, and stops it — politely,
or with ``kill -9`` to test recovery.  It needs only the ``service`` extra
(it asks ``/healthz`` with the standard library).  :class:`Client` is a thin
``httpx`` client (httpx is not in the ``service`` extra: ``pip install httpx``)
that sends the bearer token and a fresh ``Idempotency-Key`` on every POST
unless told which key to use.

With ``workers=N`` (PostgreSQL) it runs ``opportune serve --workers N``: a
supervisor and N worker processes on one port; :meth:`ServiceProcess.worker_pids`
names the workers, :meth:`ServiceProcess.kill_worker` kills one with
``kill -9`` (the supervisor replaces it), and :meth:`ServiceProcess.kill` kills
the supervisor and every worker at once.

>>> with ServiceProcess(tmp_path / "t.db") as svc:                  # doctest: +SKIP
...     cell = Client(svc.url, svc.token(cell="cell-1"))
...     plan = cell.post("/plans", content=open("examples/gearbox.yaml").read(),
...                      headers={"Content-Type": "application/yaml"}).json()["id"]
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
import uuid
from pathlib import Path


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now (the OS picks it; another process may take it next).

    Returns
    -------
    int
        The port.

    Examples
    --------
    >>> 0 < free_port() < 65536
    True
    """
    return _free_ports(1)[0]


def _free_ports(n: int) -> tuple[int, ...]:
    """``n`` TCP ports free on 127.0.0.1 now, all different (every socket held while the next is picked)."""
    with contextlib.ExitStack() as held:
        socks = [held.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM)) for _ in range(n)]
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return tuple(s.getsockname()[1] for s in socks)


def _healthy(url: str) -> bool:
    """True if ``GET url`` answers 200 within a second (standard library only; loopback, so no proxy).  A
    server that answers in another protocol (an OPC UA one took the port first, say) is not healthy."""
    import http.client
    import urllib.parse

    where = urllib.parse.urlsplit(url)
    try:
        conn = http.client.HTTPConnection(where.hostname, where.port, timeout=1.0)
    except ValueError:          # not a port number in the URL
        return False
    try:
        conn.request("GET", where.path or "/")
        return conn.getresponse().status == 200
    except (OSError, ValueError, http.client.HTTPException):
        return False
    finally:
        conn.close()         # whatever answered: no socket left to the garbage collector


def _listening(port: int) -> bool:
    """True if a TCP connection to 127.0.0.1:``port`` is accepted."""
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=1.0):
            return True
    except OSError:
        return False


class ServiceProcess:
    """``opportune serve`` on 127.0.0.1 and a free port, over a SQLite file or a database URL; a context
    manager that always stops it.

    Parameters
    ----------
    db : str or os.PathLike
        A SQLite file, or a database URL (``postgresql+psycopg://...``).
    max_body : int, optional
        The server's ``--max-body`` (bytes of a request body).
    log : str or os.PathLike, optional
        Where the server's output goes (default: ``db`` with the suffix ``.log``; required with a URL).
    extra_args : tuple of str, default ()
        More arguments for ``opportune serve``.
    workers : int, default 1
        Worker processes (``--workers N``, PostgreSQL): a supervisor and N workers on one port.
    opcua : bool, default False
        Also serve OPC UA (``--opcua``) on a free loopback port (:attr:`opcua_endpoint`).
    pki : str or os.PathLike, optional
        Where the OPC UA certificates go (default: ``db`` + ``.pki``; required with a URL and
        ``opcua``).

    Raises
    ------
    ValueError
        With a database URL and no ``log``, or with ``opcua`` and no ``pki``.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from opportune.datasets import resolve
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> with ServiceProcess(folder / "cell.db") as service:
    ...     cell = Client(service.url, service.token(cell="cell-1"))
    ...     plan = cell.post("/plans", content=resolve("example:gearbox").read_text(),
    ...                      headers={"Content-Type": "application/yaml"}).json()
    ...     run = cell.post("/runs", {"plan": plan["id"], "policy": "paper"}).json()
    ...     answer = cell.post(f"/runs/{run['id']}/looks", {"visible": ["rl", "ra"]}).json()
    ...     cell.close()
    >>> plan["name"], answer["action"]["kind"], answer["action"]["part"]
    ('gearbox', 'buffer', 'rl')
    """

    def __init__(self, db: str | Path, *, max_body: int | None = None, log: str | Path | None = None,
                 extra_args: tuple[str, ...] = (), workers: int = 1, opcua: bool = False,
                 pki: str | Path | None = None):
        self.db = str(db)
        # with opcua=True, `--opcua` on a free loopback port too, its certificates in ``pki`` (default DB.pki)
        self.opcua = opcua
        self.pki = Path(pki) if pki else Path(str(db) + ".pki") if "://" not in str(db) else None
        if opcua and self.pki is None:
            raise ValueError("with a database URL and opcua=True, say where the certificates go: pki=PATH")
        self.opcua_port: int | None = None
        self.workers = workers
        if log is None and "://" in self.db:
            raise ValueError("with a database URL, say where the server's log goes: log=PATH")
        self.max_body = max_body
        self.log_path = Path(log) if log else Path(db).with_suffix(".log")
        self.extra_args = extra_args
        self.proc: subprocess.Popen | None = None
        self.port: int | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def opcua_endpoint(self) -> str:
        return f"opc.tcp://127.0.0.1:{self.opcua_port}"

    def start(self, timeout: float = 30.0) -> "ServiceProcess":
        """Start the server and wait until it answers (``/healthz``, and every worker up).

        Parameters
        ----------
        timeout : float, default 30.0
            Seconds to wait for it, per attempt (three attempts: another process may take the free
            port first).

        Returns
        -------
        ServiceProcess
            This object, started (:attr:`url` answers).

        Raises
        ------
        RuntimeError
            If the service did not start; the message ends with its log.

        Examples
        --------
        >>> import pathlib, tempfile
        >>> service = ServiceProcess(pathlib.Path(tempfile.mkdtemp()) / "cell.db").start()
        >>> service.url.startswith("http://127.0.0.1:")
        True
        >>> service.stop()
        """
        for _attempt in range(3):  # another process may take the free port first
            self.port, opcua_port = _free_ports(2)
            args = [sys.executable, "-m", "opportune.cli", "serve", "--db", self.db,
                    "--host", "127.0.0.1", "--port", str(self.port), *self.extra_args]
            if self.workers != 1:
                args += ["--workers", str(self.workers)]
            if self.max_body:
                args += ["--max-body", str(self.max_body)]
            if self.opcua:   # it listens before HTTP does: a healthy server is listening on both
                self.opcua_port = opcua_port
                args += ["--opcua", "--opcua-endpoint", self.opcua_endpoint, "--opcua-pki", str(self.pki)]
            log = open(self.log_path, "ab")
            # Its own process group: kill() reaches the workers of --workers N too.
            self.proc = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                         env={**os.environ, "PYTHONUNBUFFERED": "1"}, start_new_session=True)
            log.close()
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                if self.proc.poll() is not None:
                    break
                if "--no-http" in self.extra_args:     # OPC UA alone: listening is being up
                    if _listening(self.opcua_port):
                        return self
                elif _healthy(self.url + "/healthz") and (self.workers == 1 or len(self.worker_pids()) == self.workers):
                    return self
                time.sleep(0.05)
            self.stop()
        raise RuntimeError(f"the service did not start; its log:\n{self.log_text()[-3000:]}")

    def stop(self, timeout: float = 10.0) -> None:
        """SIGTERM (the supervisor of ``workers`` stops its workers), then SIGKILL if it has not stopped
        within ``timeout``.  Nothing to do if the server is not running.

        Parameters
        ----------
        timeout : float, default 10.0
            Seconds to wait after SIGTERM.

        Examples
        --------
        >>> import pathlib, tempfile
        >>> ServiceProcess(pathlib.Path(tempfile.mkdtemp()) / "cell.db").stop()    # never started: nothing to stop
        """
        if self.proc is None or self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()

    def kill(self) -> None:
        """``kill -9`` the server's process group (with ``workers``: the supervisor and every worker at
        once): no chance to flush or clean up.  Nothing to do if the server is not running.

        Examples
        --------
        >>> import pathlib, tempfile
        >>> ServiceProcess(pathlib.Path(tempfile.mkdtemp()) / "cell.db").kill()    # never started: nothing to kill
        """
        if self.proc is not None and self.proc.poll() is None:
            # Not reaped yet, so the group's id is still this server's: nothing else can be hit.
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait(10)

    def worker_pids(self) -> list[int]:
        """The worker processes of ``--workers N`` (children of the server process), from /proc (Linux).

        Returns
        -------
        list of int
            Their pids, ascending; empty with one worker or when the server is not running.

        Examples
        --------
        >>> import pathlib, tempfile
        >>> ServiceProcess(pathlib.Path(tempfile.mkdtemp()) / "cell.db").worker_pids()
        []
        """
        if self.workers == 1 or self.proc is None or self.proc.poll() is not None:
            return []
        children = []
        for entry in Path("/proc").iterdir():
            if not entry.name.isdigit():
                continue
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            # pid (comm) state ppid ...: the command name may hold spaces or parentheses
            fields = stat[stat.rindex(")") + 2:].split()
            if int(fields[1]) == self.proc.pid and fields[0] != "Z":
                cmdline = (entry / "cmdline").read_bytes() if (entry / "cmdline").exists() else b""
                if b"multiprocessing" in cmdline and b"resource_tracker" not in cmdline:
                    children.append(int(entry.name))
        return sorted(children)

    def kill_worker(self, pid: int | None = None) -> int:
        """``kill -9`` one worker; the supervisor starts another.

        Parameters
        ----------
        pid : int, optional
            The worker to kill (``None``, or not a worker: the first).

        Returns
        -------
        int
            The pid killed.

        Raises
        ------
        RuntimeError
            If there are no worker processes (one worker, or the server is not running).

        Examples
        --------
        >>> import pathlib, tempfile
        >>> ServiceProcess(pathlib.Path(tempfile.mkdtemp()) / "cell.db").kill_worker()
        Traceback (most recent call last):
            ...
        RuntimeError: no worker processes: start the service with workers=N > 1
        """
        pids = self.worker_pids()
        if not pids:
            raise RuntimeError("no worker processes: start the service with workers=N > 1")
        pid = pid if pid in pids else pids[0]
        os.kill(pid, signal.SIGKILL)
        return pid

    def log_text(self) -> str:
        """What the server wrote to its log so far.

        Returns
        -------
        str
            The log's text (``""`` before the server first started).

        Examples
        --------
        >>> import pathlib, tempfile
        >>> ServiceProcess(pathlib.Path(tempfile.mkdtemp()) / "cell.db").log_text()
        ''
        """
        try:
            return self.log_path.read_text(errors="replace")
        except FileNotFoundError:
            return ""

    def token(self, *, cell: str | None = None, operator: str | None = None) -> str:
        """Create a token directly in the database (as ``opportune token create`` does).

        Needs no running server: the database is made if it does not exist.

        Parameters
        ----------
        cell : str, optional
            The cell the token drives (a cell's token).
        operator : str, optional
            The operator the token belongs to (an operator's token).

        Returns
        -------
        str
            The token, for ``Authorization: Bearer``.

        Examples
        --------
        >>> import pathlib, tempfile
        >>> ServiceProcess(pathlib.Path(tempfile.mkdtemp()) / "cell.db").token(cell="cell-1").startswith("opp_")
        True
        """
        from opportune.service.auth import create_token
        from opportune.service.config import database_url
        from opportune.service.storage import Store

        store = Store(database_url(self.db))
        try:
            return create_token(store, cell=cell, operator=operator)[1]
        finally:
            store.dispose()

    def __enter__(self) -> "ServiceProcess":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


class Client:
    """An ``httpx.Client`` for one token: every request carries it, and every POST a fresh
    ``Idempotency-Key`` unless ``key=`` is given.

    Parameters
    ----------
    base_url : str
        The service's address (:attr:`ServiceProcess.url`).
    token : str or None
        The bearer token (``None``: none sent).
    timeout : float, default 30.0
        Seconds per request.

    Raises
    ------
    ImportError
        If httpx is not installed (the ``service`` extra does not install it: ``pip install httpx``).

    Examples
    --------
    >>> client = Client("http://127.0.0.1:8700", "opp_example")
    >>> client.http.headers["Authorization"]
    'Bearer opp_example'
    >>> client.close()
    """

    def __init__(self, base_url: str, token: str | None, timeout: float = 30.0):
        try:
            import httpx
        except ImportError:
            raise ImportError("opportune.service.testing.Client needs httpx, which the 'service' extra does not "
                              "install: pip install httpx (ServiceProcess itself needs only the extra)",
                              name="httpx") from None

        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.http = httpx.Client(base_url=base_url, headers=headers, timeout=timeout)

    def get(self, path: str, **kw):
        """``GET path``.

        Parameters
        ----------
        path : str
            The path, e.g. ``"/runs/1"``.
        **kw
            More arguments for ``httpx.Client.get`` (``params``, ``headers``, ...).

        Returns
        -------
        httpx.Response
            The answer, whatever its status.

        Examples
        --------
        >>> import httpx
        >>> client = Client("http://service", "opp_example")
        >>> client.http = httpx.Client(base_url="http://service", headers=client.http.headers,
        ...                            transport=httpx.MockTransport(lambda request: httpx.Response(200, text=request.url.path)))
        >>> client.get("/healthz").text
        '/healthz'
        """
        return self.http.get(path, **kw)

    def post(self, path: str, json=None, *, key: str | None | bool = None, **kw):
        """``POST path`` with a JSON body, and an ``Idempotency-Key``.

        Parameters
        ----------
        path : str
            The path, e.g. ``"/runs"``.
        json : object, optional
            The body, as JSON (``None``: give ``content=`` instead, or no body).
        key : str, bool or None, default None
            The ``Idempotency-Key``: ``None``, a fresh one; a string, that one (to send a request again);
            ``False``, none.
        **kw
            More arguments for ``httpx.Client.post`` (``content``, ``headers``, ...).

        Returns
        -------
        httpx.Response
            The answer, whatever its status.

        Examples
        --------
        >>> import httpx
        >>> client = Client("http://service", "opp_example")
        >>> echo = httpx.MockTransport(lambda request: httpx.Response(200, json=dict(request.headers)))
        >>> client.http = httpx.Client(base_url="http://service", headers=client.http.headers, transport=echo)
        >>> client.post("/runs", {"plan": "example:gearbox"}, key="k-1").json()["idempotency-key"]
        'k-1'
        """
        headers = dict(kw.pop("headers", {}) or {})
        if key is not False:
            headers["Idempotency-Key"] = key or uuid.uuid4().hex
        return self.http.post(path, json=json, headers=headers, **kw)

    def close(self) -> None:
        """Close the connections.

        Examples
        --------
        >>> Client("http://127.0.0.1:8700", None).close()
        """
        self.http.close()


class PostgresServer:
    """A throwaway PostgreSQL server in a temporary directory, on 127.0.0.1 and a free port, for tests.

    Needs the server programs (Debian: ``apt-get install postgresql``); as root it runs them as the
    ``postgres`` user, as PostgreSQL requires.  The server lives in a fresh directory under the
    system's temporary directory (the ``postgres`` user must be able to reach it) and is deleted by
    :meth:`stop`.  A context manager: ``with`` starts and stops it.

    Parameters
    ----------
    durable : bool, default False
        Run with PostgreSQL's defaults; ``False`` runs with ``fsync=off`` (tests need no durability
        against power loss; ``kill -9`` of a client loses nothing either way).

    Raises
    ------
    RuntimeError
        If PostgreSQL's server programs (``initdb``, ``pg_ctl``) are not found.

    Examples
    --------
    Starting a server takes seconds and the PostgreSQL programs:

    >>> with PostgresServer() as pg:                                    # doctest: +SKIP
    ...     url = pg.database("runs")
    ...     with ServiceProcess(url, log="service.log") as service:
    ...         token = service.token(cell="cell-1")
    """

    def __init__(self, *, durable: bool = False):
        self.durable = durable  # False: fsync=off (fast tests); True: PostgreSQL's defaults (benchmarks)
        self.root: Path | None = None
        self.data: Path | None = None
        self.port: int | None = None
        self.bindir = self._find_bindir()
        self._as = ["runuser", "-u", "postgres", "--"] if os.geteuid() == 0 else []

    @staticmethod
    def _find_bindir() -> Path:
        import glob
        import shutil

        found = shutil.which("initdb")
        if found:
            return Path(found).parent
        versions = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"), key=lambda p: int(Path(p).parts[-3]))
        if versions:
            return Path(versions[-1]).parent
        raise RuntimeError("PostgreSQL's server programs (initdb, pg_ctl) were not found: install them "
                           "(Debian: apt-get install postgresql; `make test` does)")

    def _run(self, *args: str) -> None:
        done = subprocess.run([*self._as, *args], capture_output=True, text=True)
        if done.returncode:
            raise RuntimeError(f"{' '.join(args[:2])} failed: {done.stdout}{done.stderr}")

    def start(self) -> "PostgresServer":
        """Create the data directory and start the server (``initdb``, then ``pg_ctl start``).

        Returns
        -------
        PostgresServer
            This server, started (:attr:`port` set).

        Raises
        ------
        RuntimeError
            If ``initdb`` or ``pg_ctl`` fails (with its output).

        Examples
        --------
        >>> pg = PostgresServer().start()          # doctest: +SKIP
        >>> pg.stop()                              # doctest: +SKIP
        """
        import tempfile

        self.root = Path(tempfile.mkdtemp(prefix="opportune-pg-"))
        self.data = self.root / "data"
        self.data.mkdir()
        if self._as:
            subprocess.run(["chown", "-R", "postgres", str(self.root)], check=True)
        self._run(str(self.bindir / "initdb"), "-D", str(self.data), "-A", "trust", "-U", "postgres", "-E", "UTF8")
        self.port = free_port()
        self._run(str(self.bindir / "pg_ctl"), "-D", str(self.data), "-w", "-l", str(self.root / "server.log"),
                  "-o", f"-p {self.port} -k {self.root} -c listen_addresses=127.0.0.1"
                  + ("" if self.durable else " -c fsync=off"), "start")
        return self

    def database(self, name: str) -> str:
        """Create a database.

        Parameters
        ----------
        name : str
            The database's name (a new one).

        Returns
        -------
        str
            Its SQLAlchemy URL (driver psycopg 3), for :class:`ServiceProcess` or ``opportune serve --db``.

        Examples
        --------
        >>> with PostgresServer() as pg:                                    # doctest: +SKIP
        ...     pg.database("runs")
        'postgresql+psycopg://postgres@127.0.0.1:...'
        """
        from sqlalchemy import create_engine, text

        admin = create_engine(f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/postgres",
                              isolation_level="AUTOCOMMIT")
        try:
            with admin.connect() as c:
                c.execute(text(f'CREATE DATABASE "{name}"'))
        finally:
            admin.dispose()
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/{name}"

    def stop(self) -> None:
        """Stop the server at once (``pg_ctl -m immediate``) and delete its directory; nothing to do if it
        is not running.

        Examples
        --------
        >>> PostgresServer().stop()                # doctest: +SKIP
        """
        import shutil

        if self.root is None:
            return
        try:
            if (self.data / "postmaster.pid").exists():
                self._run(str(self.bindir / "pg_ctl"), "-D", str(self.data), "-m", "immediate", "-w", "stop")
        finally:
            shutil.rmtree(self.root, ignore_errors=True)
            self.root = None

    def __enter__(self) -> "PostgresServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
