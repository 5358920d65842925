"""OPC UA bounded before login: a hostile client's headers, HEL, trickle, idle and crowd are refused from the
chunk header, with counted bytes read and held (the server's :class:`TransportMeter`), and a normal client still
works after them.

The server runs in this process (:class:`OpcUaThread`), so that its counters and this process's memory can be
read; timeouts are lowered (its ``bounds``) rather than waited for, and no wall-clock time is asserted.
"""

from __future__ import annotations

import asyncio
import hashlib
import inspect
import socket
import struct
import threading
import time
from dataclasses import replace

import pytest

pytest.importorskip("asyncua")

from asyncua import Server, ua  # noqa: E402
from asyncua.server.binary_server_asyncio import OPCUAProtocol  # noqa: E402
from asyncua.server.internal_session import InternalSession  # noqa: E402
from asyncua.ua.ua_binary import struct_from_binary, struct_to_binary, uatcp_to_binary  # noqa: E402

from conftest import GEARBOX, run_cli  # noqa: E402
from opportune.service import opcua_transport as transport  # noqa: E402
from opportune.service.auth import create_token  # noqa: E402
from opportune.service.config import Settings  # noqa: E402
from opportune.service.core import build  # noqa: E402
from opportune.service.opcua import OpcUaOptions, OpcUaThread, client_certificate, message_limit  # noqa: E402
from opportune.service.opcua_client import CellClient  # noqa: E402
from opportune.service.opcua_transport import TransportBounds  # noqa: E402
from opportune.service.storage import Store  # noqa: E402
from opportune.service.testing import free_port  # noqa: E402

APP = "urn:opportune:test-bounds"
BIG = 2 ** 31 - 1
codes = ua.StatusCodes


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """One in-process OPC UA server (its address space takes seconds to build), a cell's token and a client
    certificate it trusts; each test sets the server's bounds it needs."""
    root = tmp_path_factory.mktemp("opcua-bounds")
    store = Store(f"sqlite:///{root / 'b.db'}")
    core = build(Settings(db_url=store.url), store)
    _id, token = create_token(store, cell="cell-1")
    cert = client_certificate(root / "client", APP, trust_in=root / "pki")
    endpoint = f"opc.tcp://127.0.0.1:{free_port()}"
    # anonymous sessions on (loopback, development): one more door open, its None security policy letting a
    # client send chunks asyncua reads without decrypting them
    thread = OpcUaThread(core, OpcUaOptions(endpoint=endpoint, pki=root / "pki", anonymous_cell="dev")).start()
    yield thread.front.server, endpoint, token, cert
    thread.stop()
    core.close()


@pytest.fixture
def server(served):
    """The server, with its default bounds again after the test, and its meter's peak reset before (once the
    connections of earlier tests are gone)."""
    srv = served[0]
    default = srv.bounds
    deadline = time.monotonic() + 10
    while srv.meter.open and time.monotonic() < deadline:
        time.sleep(0.01)
    srv.meter.reset_peak()
    yield srv
    srv.bounds = default


# ---------------------------------------------------------------- a raw client

def hello(url: str, receive=65535, send=65535, message=0, chunks=0) -> bytes:
    return uatcp_to_binary(ua.MessageType.Hello, ua.Hello(ProtocolVersion=0, ReceiveBufferSize=receive,
                                                          SendBufferSize=send, MaxMessageSize=message,
                                                          MaxChunkCount=chunks, EndpointUrl=url))


_OPEN: list[socket.socket] = []     # every raw connection a test opened: closed after it, whatever it did


@pytest.fixture(autouse=True)
def _close_raw_connections():
    yield
    while _OPEN:
        _OPEN.pop().close()


def connect(endpoint: str) -> socket.socket:
    host, port = endpoint.removeprefix("opc.tcp://").split(":")
    sock = socket.create_connection((host, int(port)), timeout=20)
    _OPEN.append(sock)
    return sock


def read_exactly(sock: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        got = sock.recv(n - len(data))
        if not got:
            raise EOFError(f"closed after {len(data)} of {n} bytes")
        data += got
    return data


def answer(sock: socket.socket):
    """The next message the server sends: ``(type, decoded body)`` for ACK and ERR."""
    kind, _flag, size = struct.unpack("<3scI", read_exactly(sock, 8))
    body = ua.utils.Buffer(read_exactly(sock, size - 8))
    if kind == b"ACK":
        return kind, struct_from_binary(ua.Acknowledge, body)
    if kind == b"ERR":
        return kind, struct_from_binary(ua.ErrorMessage, body)
    return kind, body


def closed(sock: socket.socket) -> bool:
    """Whether the server has closed the connection (waiting for it; the socket's timeout bounds the wait)."""
    try:
        while sock.recv(65536):
            pass
    except ConnectionResetError:
        pass
    return True


def refused_with(sock: socket.socket, code: int) -> str:
    """The ERR the server answered with ``code``, then closed; its reason."""
    kind, err = answer(sock)
    assert kind == b"ERR", kind
    assert err.Error.value == code, (ua.StatusCode(err.Error.value).name, err.Reason)
    assert closed(sock)
    return err.Reason


def opened(endpoint: str, **kw) -> tuple[socket.socket, ua.Acknowledge]:
    sock = connect(endpoint)
    sock.sendall(hello(endpoint, **kw))
    kind, ack = answer(sock)
    assert kind == b"ACK"
    return sock, ack


def header(kind: bytes, size: int, flag: bytes = b"F") -> bytes:
    return kind + flag + struct.pack("<I", size) + (struct.pack("<I", 0) if kind != b"HEL" else b"")


class Rss:
    """This process's resident memory, sampled every few milliseconds in a thread: its peak over the block."""

    def __init__(self):
        self.peak = self.before = self.now()
        self._stop = threading.Event()

    @staticmethod
    def now() -> int:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * 4096

    def _sample(self):
        while not self._stop.wait(0.005):
            self.peak = max(self.peak, self.now())

    def __enter__(self):
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self.now())


def settle(server, received: int) -> None:
    """Wait until the server's loop has read ``received`` bytes or has nothing more to read (a second)."""
    deadline = time.monotonic() + 5
    while server.meter.received < received and time.monotonic() < deadline:
        time.sleep(0.01)


# ---------------------------------------------------------------- sizes from the header

@pytest.mark.parametrize("kind", [b"OPN", b"MSG"])
@pytest.mark.parametrize("size", [BIG, 10 << 20, 65536])
def test_an_oversized_chunk_header_after_hello_is_refused_before_its_body(served, server, kind, size):
    endpoint = served[1]
    start = server.meter.received
    sock, _ack = opened(endpoint)
    sock.sendall(header(kind, size))
    reason = refused_with(sock, codes.BadTcpMessageTooLarge)
    assert f"{size:,}" in reason
    # read: the HEL and this header, nothing more; held: no more than the HEL at any time
    assert server.meter.received - start == len(hello(endpoint)) + 12
    assert server.meter.peak_held <= transport.HELLO_SIZE
    settle_held(server)


def test_a_huge_header_then_50_mb_is_read_no_further_and_memory_stays(served, server):
    """The probe's attack: memory rose by 300 MB and the server read 135 MiB in 15 s at a full core."""
    endpoint = served[1]
    start = server.meter.received
    piece = bytes(1 << 16)
    sent = 0
    with Rss() as rss:
        sock, _ack = opened(endpoint)
        sock.sendall(header(b"MSG", BIG))
        try:
            for _ in range((50 << 20) // len(piece)):
                sock.sendall(piece)
                sent += len(piece)
        except OSError:     # reset by the server: what it does not read, the kernel's buffers took
            pass
        sock.close()
        settle(server, start + 1)
    read = server.meter.received - start
    assert read <= len(hello(endpoint)) + 12 + (256 << 10), read     # at most one read of the event loop more
    assert sent < 50 << 20
    assert rss.peak - rss.before < 20 << 20, (rss.before, rss.peak)
    settle_held(server)


def test_a_hello_announcing_huge_buffers_is_clamped_in_ack(served, server):
    endpoint = served[1]
    sock, ack = opened(endpoint, receive=2 ** 32 - 1, send=2 ** 32 - 1, message=2 ** 32 - 1, chunks=2 ** 32 - 1)
    assert ack.ReceiveBufferSize == transport.RECEIVE_BUFFER and ack.SendBufferSize == transport.SEND_BUFFER
    assert ack.MaxMessageSize == server.bounds.max_message == message_limit(Settings().max_body)
    assert ack.MaxChunkCount == server.bounds.max_chunks == -(-ack.MaxMessageSize // transport.RECEIVE_BUFFER)
    # the buffer the client announced is not the one the server reads: a chunk over ACK's is refused
    sock.sendall(header(b"OPN", transport.RECEIVE_BUFFER + 1))
    refused_with(sock, codes.BadTcpMessageTooLarge)
    # "no limit" (0) gets the server's limits too
    sock, ack = opened(endpoint, message=0, chunks=0)
    assert (ack.MaxMessageSize, ack.MaxChunkCount) == (server.bounds.max_message, server.bounds.max_chunks)
    sock.close()


def test_a_hello_with_a_smaller_send_buffer_bounds_the_chunks_read(served, server):
    endpoint = served[1]
    sock, _ack = opened(endpoint, send=transport.MIN_BUFFER)
    sock.sendall(header(b"OPN", transport.MIN_BUFFER + 1))
    refused_with(sock, codes.BadTcpMessageTooLarge)


@pytest.mark.parametrize("first, code", [
    (header(b"MSG", 100), codes.BadTcpMessageTypeInvalid),          # not HEL first
    (header(b"HEL", BIG), codes.BadTcpMessageTooLarge),              # a HEL claiming 2 GiB
    (b"XYZF" + struct.pack("<I", 100), codes.BadTcpMessageTypeInvalid),
    (header(b"HEL", 4), codes.BadTcpMessageTypeInvalid),             # a size smaller than its header
    (header(b"HEL", 17) + bytes(9), codes.BadTcpInternalError),      # a HEL that cannot be decoded
])
def test_a_bad_first_header_is_refused(served, server, first, code):
    sock = connect(served[1])
    sock.sendall(first)
    refused_with(sock, code)
    settle_held(server)


@pytest.mark.parametrize("hel, code", [
    (dict(receive=100), codes.BadConnectionRejected),      # under OPC UA's 8,192
    (dict(send=0), codes.BadConnectionRejected),
])
def test_a_hello_with_buffers_too_small_is_refused(served, server, hel, code):
    sock = connect(served[1])
    sock.sendall(hello(served[1], **hel))
    refused_with(sock, code)


def test_a_second_hello_and_a_long_url_are_refused(served, server):
    endpoint = served[1]
    sock, _ack = opened(endpoint)
    sock.sendall(hello(endpoint))
    refused_with(sock, codes.BadTcpMessageTypeInvalid)
    sock = connect(endpoint)
    sock.sendall(hello("opc.tcp://" + "x" * 5000))        # over 4,096 bytes, within HELLO_SIZE
    refused_with(sock, codes.BadTcpEndpointUrlInvalid)


def opn_chunk(size: int, seq: int, flag: bytes = b"C") -> bytes:
    """An OPN chunk of the None security policy, the ``seq``-th of request 1 (asyncua keeps an intermediate one
    whole, undecoded)."""
    security = struct_to_binary(ua.AsymmetricAlgorithmHeader(SecurityPolicyURI="http://opcfoundation.org/UA/SecurityPolicy#None"))
    body = security + struct.pack("<II", seq, 1)
    return header(b"OPN", size, flag) + body + bytes(size - 12 - len(body))


def test_a_message_before_login_is_bounded_by_its_chunks_headers(served, server):
    """Chunks each within the buffer, a message over LOGIN_MESSAGE: the chunk that passes it is refused from its
    header (its body never read), and nothing is held after."""
    endpoint = served[1]
    start = server.meter.received
    sock, _ack = opened(endpoint)
    sent = len(hello(endpoint))
    size = 60000
    for seq in range(1, 1 + transport.LOGIN_MESSAGE // size):
        sock.sendall(opn_chunk(size, seq))
        sent += size
    sock.sendall(header(b"OPN", size, b"C"))
    sent += 12
    assert "before login" in refused_with(sock, codes.BadRequestTooLarge)
    assert server.meter.received - start == sent
    assert server.meter.peak_held <= transport.LOGIN_MESSAGE
    settle_held(server)


def test_a_flood_of_bad_chunks_before_login_closes_at_the_first(served, server, caplog):
    """asyncua logs a traceback for each chunk it cannot read and reads on: before login, the first closes."""
    endpoint = served[1]
    before = server.meter.refused["bad chunk before login"]
    sock, _ack = opened(endpoint)
    try:
        sock.sendall(b"".join(header(b"OPN", 13) + b"\0" for _ in range(10_000)))
    except OSError:
        pass
    refused_with(sock, codes.BadSecurityChecksFailed)
    assert server.meter.refused["bad chunk before login"] == before + 1
    assert sum("processing message" in r.getMessage() for r in caplog.records) <= 1


def settle_held(server) -> None:
    """Wait for the server to have closed its side (it releases what a connection held then); assert it did."""
    deadline = time.monotonic() + 10
    while server.meter.held and time.monotonic() < deadline:
        time.sleep(0.01)
    assert server.meter.held == 0


def test_all_connections_together_hold_at_most_max_buffered(served, server):
    endpoint = served[1]
    server.bounds = server.bounds.lowered(max_buffered=100_000)
    first, _ack = opened(endpoint)
    first.sendall(header(b"OPN", 60000, b"C"))      # announced, body not sent: 60,000 bytes reserved
    deadline = time.monotonic() + 10
    while server.meter.held < 60000 and time.monotonic() < deadline:
        time.sleep(0.01)
    second, _ack = opened(endpoint)
    second.sendall(header(b"OPN", 60000, b"C"))
    refused_with(second, codes.BadTcpNotEnoughResources)
    first.close()


class _Transport:
    """What a protocol's transport is asked: pausing, resuming, writing, closing."""

    def __init__(self):
        self.paused, self.closed, self.written = False, False, b""

    def pause_reading(self):
        assert not self.paused
        self.paused = True

    def resume_reading(self):
        assert self.paused
        self.paused = False

    def write(self, data):
        self.written += data

    def close(self):
        self.closed = True


class _IServer:
    max_pending_messages_per_connection = 500


def test_a_connection_is_not_read_while_its_waiting_chunks_pass_the_bound():
    """Flow control, counted: chunks read faster than they are served stop the reading at QUEUED_BYTES (never
    more than one chunk past it), and the reading resumes as they are served; nothing is refused or lost."""
    bounds, meter = TransportBounds(), transport.TransportMeter()
    protocol = transport.BoundedProtocol(_IServer(), [], [], [], bounds.limits(), bounds=bounds, meter=meter)
    protocol.transport = link = _Transport()
    size, n = transport.RECEIVE_BUFFER, 40
    chunk = header(b"MSG", size) + bytes(size - 12)
    protocol.data_received(hello("opc.tcp://x:1") + chunk * n)      # as if read at once
    served, most = 0, 0
    while not protocol.messages.empty():
        most = max(most, protocol._queued)
        assert meter.held == protocol._queued          # what is waiting is what is held
        # not read while chunks read wait beyond the bound; read again once they are served
        assert link.paused == (protocol._queued >= transport.QUEUED_BYTES)
        assert link.paused or not protocol._pending
        hdr, _buf = protocol.messages.get_nowait()
        protocol._served(hdr)
        served += 1
    assert served == n + 1 and not link.paused and not link.closed and meter.held == 0
    assert transport.QUEUED_BYTES <= most < transport.QUEUED_BYTES + size


def test_a_client_that_does_not_read_its_answers_is_not_read():
    """asyncio says the answers waiting to be sent passed its high-water mark: nothing more is read (no more
    answers made) until they have gone."""
    bounds, meter = TransportBounds(), transport.TransportMeter()
    protocol = transport.BoundedProtocol(_IServer(), [], [], [], bounds.limits(), bounds=bounds, meter=meter)
    protocol.transport = link = _Transport()
    protocol.pause_writing()
    protocol.data_received(hello("opc.tcp://x:1") + header(b"MSG", 100) + bytes(88))
    assert link.paused and protocol.messages.empty() and meter.held == 0
    protocol.resume_writing()
    assert not link.paused and protocol.messages.qsize() == 2


# ---------------------------------------------------------------- times and counts

def test_a_trickled_hello_is_closed_at_the_stated_time(served, server):
    endpoint = served[1]
    server.bounds = server.bounds.lowered(hello_seconds=0.5)
    before = server.meter.refused["no HEL in time"]
    message = hello(endpoint)
    sock = connect(endpoint)
    sent = 0
    try:
        for byte in message:      # one byte every 0.1 s: 6 s for the whole HEL, 12 times the bound
            sock.send(bytes([byte]))
            sent += 1
            time.sleep(0.1)
            if server.meter.refused["no HEL in time"] > before:
                break
    except OSError:
        pass
    assert sent < len(message)
    assert server.meter.refused["no HEL in time"] == before + 1
    kind, err = answer(sock)
    assert kind == b"ERR" and err.Error.value == codes.BadTimeout
    assert closed(sock)


def test_a_connection_that_never_activates_a_session_is_closed(served, server):
    endpoint = served[1]
    server.bounds = server.bounds.lowered(login_seconds=0.5)
    sock, _ack = opened(endpoint)
    assert "no activated session within 0.5 s" in refused_with(sock, codes.BadTimeout)


def test_a_connection_whose_session_is_closed_is_closed_at_a_later_check(served, server):
    """Logged in (anonymously, no crypto: quick) within the bound, then the session closed and the connection kept:
    the next check closes it."""
    from asyncua import Client

    endpoint = served[1]
    server.bounds = server.bounds.lowered(login_seconds=1.0)
    before = server.meter.refused["no session in time"]

    async def drive():
        client = Client(endpoint)
        await client.connect()
        assert all(p.logged_in for p in server.meter.open)
        await client.close_session()          # the connection stays open, without a session
        for _ in range(1000):
            if server.meter.refused["no session in time"] > before:
                break
            await asyncio.sleep(0.01)
        try:
            await client.disconnect_socket()
        except Exception:
            pass

    asyncio.run(drive())
    assert server.meter.refused["no session in time"] == before + 1


def test_connections_beyond_the_caps_are_refused(served, server):
    endpoint = served[1]
    server.bounds = server.bounds.lowered(max_unauthenticated=4)
    idle = [connect(endpoint) for _ in range(4)]
    deadline = time.monotonic() + 10
    while len(server.meter.open) < 4 and time.monotonic() < deadline:
        time.sleep(0.01)
    extra = connect(endpoint)
    refused_with(extra, codes.BadTcpServerTooBusy)
    for sock in idle:
        sock.close()
    while server.meter.open and time.monotonic() < deadline:
        time.sleep(0.01)
    sock, _ack = opened(endpoint)        # room again
    sock.close()


def test_a_logged_in_client_works_within_the_caps(served, server):
    """With room for one connection without a session, a client logs in, and frees it for the next one; the
    total cap counts logged-in connections too."""
    srv, endpoint, token, (cert, key) = served
    server.bounds = server.bounds.lowered(max_unauthenticated=1, max_connections=2)

    async def drive():
        async with CellClient(endpoint, token, certificate=cert, private_key=key, app_uri=APP) as cell:
            idle = connect(endpoint)        # the one without a session
            await asyncio.sleep(0.2)
            crowd = connect(endpoint)
            refused_with(crowd, codes.BadTcpServerTooBusy)
            idle.close()
            run = await cell.start_run(GEARBOX.read_text(), policy="paper")
            return (await cell.look(run, ["rl", "ra"]))["action"]

    assert asyncio.run(drive()) == "buffer"
    settle_held(server)


def test_a_normal_client_still_works_after_the_attacks(served, server):
    srv, endpoint, token, (cert, key) = served
    for size in (BIG, 10 << 20):            # the attacks again, then the client
        sock, _ack = opened(endpoint)
        sock.sendall(header(b"MSG", size))
        refused_with(sock, codes.BadTcpMessageTooLarge)

    async def drive():
        async with CellClient(endpoint, token, certificate=cert, private_key=key, app_uri=APP) as cell:
            plan = await cell.upload_plan(GEARBOX.read_text())
            run = await cell.start_run(plan, policy="paper")
            answer = await cell.look(run, ["rl", "ra"])
            return answer["action"], await cell.read(run, "State")

    assert asyncio.run(drive()) == ("buffer", "Execute")
    settle_held(server)


# ---------------------------------------------------------------- settings and asyncua's internals

def test_bounds_may_be_lowered_not_raised():
    bounds = TransportBounds()
    assert bounds.lowered(max_message=1 << 40).max_message == transport.MAX_MESSAGE
    assert bounds.lowered(max_connections=5).max_connections == 5
    with pytest.raises(ValueError, match="max_connections must be above 0 and at most 100"):
        TransportBounds(max_connections=101)
    with pytest.raises(ValueError, match="hello_seconds"):
        TransportBounds(hello_seconds=0)
    assert replace(bounds, login_seconds=1.5).login_seconds == 1.5


@pytest.mark.parametrize("option, value, says", [
    ("--opcua-max-connections", "1000", "at most 100"), ("--opcua-login-seconds", "31", "at most 30"),
    ("--opcua-login-seconds", "0", "above 0")])
def test_serve_options_may_lower_the_bounds_not_raise_them(option, value, says):
    result = run_cli("serve", "--opcua", option, value)
    assert result.exit_code == 1 and option in result.output and says in result.output


def test_serve_hands_the_lowered_bounds_to_the_server(tmp_path, monkeypatch):
    """``opportune serve`` gives the OPC UA server the bounds asked (the tests above show the server keeps them);
    HEL's time and the connections without a session are within them."""
    import opportune.service.server

    got = {}
    monkeypatch.setattr(opportune.service.server, "serve", lambda **kw: got.update(kw))
    result = run_cli("serve", "--db", tmp_path / "s.db", "--opcua", "--no-http", "--opcua-max-connections", "2",
                     "--opcua-login-seconds", "3")
    assert result.exit_code == 0, result.output
    assert got["opcua"].transport == TransportBounds(max_connections=2, max_unauthenticated=2, login_seconds=3,
                                                     hello_seconds=3)
    run_cli("serve", "--db", tmp_path / "s.db", "--opcua", "--no-http")
    assert got["opcua"].transport == TransportBounds()


#: sha256 of asyncua 2.1's ``Server.start`` source (white space folded), which :meth:`BoundedServer.start` repeats
#: with its own listener.
SERVER_START_DIGEST = "4d3567e20cc7a09fe2a1271f9736c19e37316b0dbb7b7a3a79dcde0ba50869c3"


def test_the_asyncua_internals_the_hook_uses_are_there(served):
    """The hook replaces ``Server.start`` and ``OPCUAProtocol.data_received`` and uses these of asyncua's names: if
    asyncua changes them, this fails, and opcua_transport must be read against the new asyncua."""
    start = inspect.getsource(Server.start)
    assert "BinaryServer(self.iserver, ipaddress, port, self.limits)" in start
    digest = hashlib.sha256(" ".join(start.split()).encode()).hexdigest()
    assert digest == SERVER_START_DIGEST, (
        "asyncua's Server.start changed: compare it with BoundedServer.start and update both")
    protocol = inspect.getsource(OPCUAProtocol)
    for name in ("self.messages", "self.processor", "self._process_one_msg(header, buf)", "def data_received",
                 "def connection_made", "def connection_lost"):
        assert name in protocol, name
    assert inspect.signature(OPCUAProtocol.__init__).parameters.keys() >= {
        "iserver", "policies", "clients", "closing_tasks", "limits"}
    assert hasattr(InternalSession, "is_activated")
    server = served[0]
    sock, _ack = opened(served[1])
    assert all(isinstance(p, transport.BoundedProtocol) for p in server.meter.open) and server.meter.open
    sock.close()
