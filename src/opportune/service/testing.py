"""A real service on a loopback port, for integration tests (ours, and a cell controller's).

:class:`ServiceProcess` runs ``opportune serve`` in a subprocess on
127.0.0.1 and a free port, waits until it answers, and stops it — politely,
or with ``kill -9`` to test recovery.  :class:`Client` is a thin ``httpx``
client that sends the bearer token and a fresh ``Idempotency-Key`` on every
POST unless told which key to use.

>>> with ServiceProcess(tmp_path / "t.db") as svc:                  # doctest: +SKIP
...     cell = Client(svc.url, svc.token(cell="cell-1"))
...     plan = cell.post("/plans", content=open("examples/gearbox.yaml").read(),
...                      headers={"Content-Type": "application/yaml"}).json()["id"]
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import uuid
from pathlib import Path


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ServiceProcess:
    """``opportune serve`` on 127.0.0.1 with a SQLite file; a context manager that always stops it."""

    def __init__(self, db: str | Path, *, max_body: int | None = None, log: str | Path | None = None,
                 extra_args: tuple[str, ...] = ()):
        self.db = Path(db)
        self.max_body = max_body
        self.log_path = Path(log) if log else self.db.with_suffix(".log")
        self.extra_args = extra_args
        self.proc: subprocess.Popen | None = None
        self.port: int | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout: float = 30.0) -> "ServiceProcess":
        import httpx

        for _attempt in range(3):  # another process may take the free port first
            self.port = free_port()
            args = [sys.executable, "-m", "opportune.cli", "serve", "--db", str(self.db),
                    "--host", "127.0.0.1", "--port", str(self.port), *self.extra_args]
            if self.max_body:
                args += ["--max-body", str(self.max_body)]
            log = open(self.log_path, "ab")
            self.proc = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                         env={**os.environ, "PYTHONUNBUFFERED": "1"})
            log.close()
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                if self.proc.poll() is not None:
                    break
                try:
                    if httpx.get(self.url + "/healthz", timeout=1.0).status_code == 200:
                        return self
                except httpx.HTTPError:
                    pass
                time.sleep(0.05)
            self.stop()
        raise RuntimeError(f"the service did not start; its log:\n{self.log_text()[-3000:]}")

    def stop(self, timeout: float = 10.0) -> None:
        """SIGTERM, then SIGKILL if it has not stopped within ``timeout``."""
        if self.proc is None or self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()

    def kill(self) -> None:
        """``kill -9``: no chance to flush or clean up."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def log_text(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except FileNotFoundError:
            return ""

    def token(self, *, cell: str | None = None, operator: str | None = None) -> str:
        """Create a token directly in the database (as ``opportune token create`` does)."""
        from opportune.service.auth import create_token
        from opportune.service.config import database_url
        from opportune.service.storage import Store

        store = Store(database_url(str(self.db)))
        try:
            return create_token(store, cell=cell, operator=operator)[1]
        finally:
            store.dispose()

    def __enter__(self) -> "ServiceProcess":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


class Client:
    """An ``httpx.Client`` for one token; POSTs carry a fresh ``Idempotency-Key`` unless ``key=`` is given."""

    def __init__(self, base_url: str, token: str | None, timeout: float = 30.0):
        import httpx

        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.http = httpx.Client(base_url=base_url, headers=headers, timeout=timeout)

    def get(self, path: str, **kw):
        return self.http.get(path, **kw)

    def post(self, path: str, json=None, *, key: str | None | bool = None, **kw):
        headers = dict(kw.pop("headers", {}) or {})
        if key is not False:
            headers["Idempotency-Key"] = key or uuid.uuid4().hex
        return self.http.post(path, json=json, headers=headers, **kw)

    def close(self) -> None:
        self.http.close()
