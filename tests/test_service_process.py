"""The test harness's own service process starts on a port another protocol's server took first.

Under parallel tests another worker's OPC UA server may take the port :class:`ServiceProcess` picked
before the service binds it; the health check then reads OPC UA bytes where it expects HTTP.  It must
count that as not healthy (and the service, which cannot bind, is started again on new ports), never
raise.
"""

from __future__ import annotations

import socket
import threading

import pytest

pytest.importorskip("httpx")

from opportune.service import testing  # noqa: E402


class ForeignServer:
    """A loopback TCP server answering every connection as an OPC UA server answers a stray HTTP request."""

    REPLY = b"ERRF-\x00\x00\x00\x00\x00\x00\x80the first message must be HEL\r\n"

    def __init__(self):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen()
        self.port = self.sock.getsockname()[1]
        self.answered = 0
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            with conn:
                conn.recv(4096)
                self.answered += 1      # before the reply: the client may be done as soon as it has it
                conn.sendall(self.REPLY)

    def close(self):
        self.sock.close()


@pytest.fixture
def foreign():
    server = ForeignServer()
    yield server
    server.close()


def test_a_port_answered_in_another_protocol_is_not_healthy(foreign):
    assert testing._healthy(f"http://127.0.0.1:{foreign.port}/healthz") is False
    assert foreign.answered == 1


def test_the_two_ports_picked_for_http_and_opcua_differ():
    for _ in range(200):
        http_port, opcua_port = testing._free_ports(2)
        assert http_port != opcua_port


def test_the_service_starts_again_when_its_first_port_was_taken_by_another_protocol(foreign, tmp_path,
                                                                                   monkeypatch):
    real = testing._free_ports
    picks = [(foreign.port, real(2)[1])]
    monkeypatch.setattr(testing, "_free_ports", lambda n: picks.pop() if picks else real(n))
    with testing.ServiceProcess(tmp_path / "s.db") as service:
        assert service.port != foreign.port
        assert testing._healthy(service.url + "/healthz")
    assert foreign.answered >= 1        # the first start's health check met the foreign server
