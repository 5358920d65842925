"""OPC UA's TCP transport, bounded before login: every size, count, byte and time a client can make the server
spend is checked from a chunk's 8-byte header before its body is read.

asyncua's server reads a chunk whole whatever its header claims (a header claiming 2**31 - 1 bytes kept it
reading, copying its buffer on every read), keeps up to 500 received chunks per connection, and waits 30 s for a
session whatever a connection does meanwhile.  :class:`BoundedProtocol` replaces its per-connection reading
(``OPCUAProtocol.data_received``) and hands asyncua the same ``(header, body)`` chunks, within these bounds:

* a chunk larger than the receive buffer acknowledged in ACK (:data:`RECEIVE_BUFFER`, or the client's smaller
  send buffer; before HEL, :data:`HELLO_SIZE`) is refused from its header: ERR ``Bad_TcpMessageTooLarge``, then
  the connection is closed; a message (its chunks) larger than the stated message size or chunk count, likewise
  with ``Bad_RequestTooLarge`` (before login the message size is :data:`LOGIN_MESSAGE`);
* HEL's buffer sizes are clamped, as the specification lets a server revise them in ACK (asyncua acknowledges
  the smaller of the client's and the server's); a HEL announcing buffers under OPC UA's minimum of 8,192 bytes
  is refused (``Bad_ConnectionRejected``), as is a second HEL or anything but HEL first
  (``Bad_TcpMessageTypeInvalid``);
* a connection's chunks waiting to be served are at most :data:`QUEUED_BYTES` (or :data:`QUEUED_CHUNKS`): past
  that, or while its answers wait to be sent past the transport's high-water mark (a client that does not read
  them), the server stops reading it (TCP's own flow control: nothing is refused); all
  connections together hold at most :data:`MAX_BUFFERED` bytes (chunks announced and not yet served, messages
  being assembled): a chunk that would pass it is refused (``Bad_TcpNotEnoughResources``);
* at most :data:`MAX_CONNECTIONS` connections, of which :data:`MAX_UNAUTHENTICATED` without an activated session:
  one more is answered ``Bad_TcpServerTooBusy`` and closed at once;
* a connection without a whole HEL after :data:`HELLO_SECONDS`, or without an activated session after
  :data:`LOGIN_SECONDS` (and at each :data:`LOGIN_SECONDS` after), is answered ``Bad_Timeout`` and closed;
* before login, a chunk asyncua cannot read (it would log a traceback and read on) is answered
  ``Bad_SecurityChecksFailed`` and the connection closed.

Memory a connection holds is therefore at most a message (before login :data:`LOGIN_MESSAGE`) plus
:data:`QUEUED_BYTES` and a chunk waiting, plus one read of the event loop (256 KiB), and is given back when it
closes.
"""

from __future__ import annotations

import asyncio
import logging
import struct
from collections import Counter
from dataclasses import dataclass, field, fields, replace

from asyncua import Server, ua
from asyncua.common.connection import TransportLimits
from asyncua.common.utils import Buffer
from asyncua.crypto import uacrypto
from asyncua.server.binary_server_asyncio import BinaryServer, OPCUAProtocol
from asyncua.ua.ua_binary import header_from_binary, struct_from_binary, uatcp_to_binary

log = logging.getLogger(__name__)

# ---------------------------------------------------------------- the limits (docs/opcua.md, "Bounded before login")

RECEIVE_BUFFER = 65535          # bytes: the largest chunk the server receives (ACK's ReceiveBufferSize at most)
SEND_BUFFER = 65535             # bytes: the largest chunk the server sends (ACK's SendBufferSize at most)
MIN_BUFFER = 8192               # bytes: the smallest buffer a HEL may announce (OPC UA Part 6)
HELLO_SIZE = 8192               # bytes: the largest HEL (its endpoint URL is at most 4,096 bytes)
MAX_URL = 4096                  # bytes of HEL's endpoint URL (OPC UA Part 6)
MAX_MESSAGE = 64 << 20          # bytes: the ceiling of a message, whatever --max-body asks
LOGIN_MESSAGE = 128 << 10       # bytes: the largest message before the connection's session is activated
QUEUED_BYTES = 256 << 10        # bytes of a connection's chunks waiting to be served before it is read no more
QUEUED_CHUNKS = 64              # chunks waiting to be served, likewise (asyncua's queue holds 500)
MAX_BUFFERED = 128 << 20        # bytes held for all connections together (announced chunks, messages assembled)
MAX_CONNECTIONS = 100           # connections at once
MAX_UNAUTHENTICATED = 16        # connections at once without an activated session
HELLO_SECONDS = 10.0            # from opening to a whole HEL
LOGIN_SECONDS = 30.0            # from opening to an activated session

_SECURE = (b"OPN", b"MSG", b"CLO")
_FLAGS = {b"HEL": b"F", b"OPN": b"FCA", b"MSG": b"FCA", b"CLO": b"F"}


@dataclass(frozen=True)
class TransportBounds:
    """The transport's limits; each may be lowered (``serve`` options, tests), none raised past its constant."""

    max_message: int = MAX_MESSAGE
    max_buffered: int = MAX_BUFFERED
    max_connections: int = MAX_CONNECTIONS
    max_unauthenticated: int = MAX_UNAUTHENTICATED
    hello_seconds: float = HELLO_SECONDS
    login_seconds: float = LOGIN_SECONDS

    def __post_init__(self):
        for f in fields(self):
            value, ceiling = getattr(self, f.name), f.default
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= ceiling:
                raise ValueError(f"the OPC UA transport's {f.name} must be above 0 and at most {ceiling}, "
                                 f"not {value!r}")

    def lowered(self, **limits) -> "TransportBounds":
        """These bounds with each of ``limits`` lowered to it (a higher value leaves the bound as it is).

        Parameters
        ----------
        **limits
            Field names and values, e.g. ``max_connections=10``.

        Returns
        -------
        TransportBounds
            A new one; this one is unchanged.

        Raises
        ------
        ValueError
            A value of 0 or less (a bound cannot be switched off).

        Examples
        --------
        >>> bounds = TransportBounds().lowered(max_connections=10, login_seconds=60)
        >>> bounds.max_connections, bounds.login_seconds
        (10, 30.0)
        """
        return replace(self, **{name: min(value, getattr(self, name)) for name, value in limits.items()})

    @property
    def max_chunks(self) -> int:
        """Chunks a message may have (ACK's MaxChunkCount): a whole message in chunks of the receive buffer."""
        return -(-self.max_message // RECEIVE_BUFFER)

    def limits(self) -> TransportLimits:
        """asyncua's own limits (what ACK states), the same as these."""
        return TransportLimits(max_recv_buffer=RECEIVE_BUFFER, max_send_buffer=SEND_BUFFER,
                               max_chunk_count=self.max_chunks, max_message_size=self.max_message)


@dataclass
class TransportMeter:
    """What the transport did: counted work, for tests and benchmarks (one per server, its event loop only)."""

    received: int = 0                                 # bytes read from clients' sockets
    held: int = 0                                     # bytes held now (chunks announced and not served, messages)
    peak_held: int = 0
    refused: Counter = field(default_factory=Counter)   # connections closed, by reason
    open: set = field(default_factory=set)            # the connections being served

    def reset_peak(self) -> None:
        self.peak_held = self.held


class _Refusal(Exception):
    def __init__(self, code: int, reason: str, key: str):
        super().__init__(reason)
        self.code, self.reason, self.key = code, reason, key


class BoundedProtocol(OPCUAProtocol):
    """asyncua's connection, read within :class:`TransportBounds` (see the module's description)."""

    def __init__(self, *args, bounds: TransportBounds, meter: TransportMeter, **kw):
        super().__init__(*args, **kw)
        self.bounds, self.meter = bounds, meter
        self._pending = bytearray()      # bytes read, not yet handed to asyncua
        self._received = 0               # bytes read from this connection
        self._chunk: int | None = None   # the size of the chunk being read (its header accepted)
        self._chunk_limit = HELLO_SIZE
        self._hello = False
        self._message = [0, 0]           # bytes and chunks of the message being received
        self._parts = 0                  # bytes of a message's chunks served, held by asyncua until its last
        self._queued = 0                 # bytes of chunks handed to asyncua and not yet served
        self._reserved = 0               # this connection's share of meter.held
        self._paused = False
        self._unsent = False             # answers not yet sent pass the transport's high-water mark
        self._done = False
        self._timers: list[asyncio.TimerHandle] = []
        self._queue_room = min(QUEUED_CHUNKS, (self.messages.maxsize or QUEUED_CHUNKS + 1) - 1)

    # ------------------------------------------------------------ opening and closing

    def connection_made(self, transport) -> None:
        meter, bounds = self.meter, self.bounds
        waiting = sum(1 for p in meter.open if not p.logged_in)
        if len(meter.open) >= bounds.max_connections or waiting >= bounds.max_unauthenticated:
            which = "connections" if len(meter.open) >= bounds.max_connections else "connections without a session"
            self._done = True
            _send_error(transport, ua.StatusCodes.BadTcpServerTooBusy, f"too many {which}: try again later")
            transport.close()
            meter.refused[f"too many {which}"] += 1
            log.warning("OPC UA: closing the connection from %s after 0 bytes read: too many %s",
                        transport.get_extra_info("peername"), which)
            return
        super().connection_made(transport)
        if self.transport is None:      # asyncua's own cap
            self._done = True
            return
        meter.open.add(self)
        loop = asyncio.get_running_loop()
        self._timers = [loop.call_later(bounds.hello_seconds, self._expire, "hello"),
                        loop.call_later(bounds.login_seconds, self._expire, "login")]

    def connection_lost(self, ex) -> None:
        self._done = True
        for timer in self._timers:
            timer.cancel()
        self.meter.open.discard(self)
        self._release(self._reserved)
        self._pending = bytearray()
        super().connection_lost(ex)

    @property
    def logged_in(self) -> bool:
        """Whether this connection's session is activated."""
        session = getattr(self.processor, "session", None)
        return session is not None and session.is_activated()

    def _expire(self, what: str) -> None:
        if self._done:
            return
        if what == "hello" and not self._hello:
            self._refuse(_Refusal(ua.StatusCodes.BadTimeout, f"no HEL within {self.bounds.hello_seconds:g} s",
                                  "no HEL in time"))
        elif what == "login":
            if not self.logged_in:
                self._refuse(_Refusal(ua.StatusCodes.BadTimeout, "no activated session within "
                                      f"{self.bounds.login_seconds:g} s", "no session in time"))
            else:   # checked again: a connection whose session was closed does not stay open for ever
                self._timers[1] = asyncio.get_running_loop().call_later(self.bounds.login_seconds, self._expire,
                                                                        "login")

    def _refuse(self, refusal: _Refusal) -> None:
        """ERR with the refusal's status and reason, then close; nothing more is read."""
        self._done = True
        self.meter.refused[refusal.key] += 1
        log.warning("OPC UA: closing the connection from %s after %d bytes read: %s", self.peer_name,
                    self._received, refusal.reason)
        self._pending = bytearray()
        if self.transport is not None:
            _send_error(self.transport, refusal.code, refusal.reason)
            self.transport.close()

    # ------------------------------------------------------------ reading

    def data_received(self, data: bytes) -> None:
        self.meter.received += len(data)
        self._received += len(data)
        if self._done:
            return
        self._pending += data
        self._read_or_refuse()

    def _read_or_refuse(self) -> None:
        try:
            self._read()
        except _Refusal as refusal:
            self._refuse(refusal)

    def _read(self) -> None:
        """Hand every whole chunk read to asyncua while it has room; a chunk's header is checked as soon as it is
        here, before its body."""
        pending = self._pending
        while not self._done:
            if self._queued >= QUEUED_BYTES or self.messages.qsize() >= self._queue_room or self._unsent:
                if not self._paused and self.transport is not None:
                    self._paused = True
                    self.transport.pause_reading()
                return
            if self._chunk is None:
                if len(pending) < 8:
                    break
                self._chunk = self._accept(bytes(pending[:8]))
            if len(pending) < self._chunk:
                break
            chunk = bytes(pending[:self._chunk])
            del pending[:self._chunk]
            self._chunk = None
            self._hand_over(chunk)
        if self._paused and self.transport is not None and not self._done:
            self._paused = False
            self.transport.resume_reading()

    def _accept(self, header: bytes) -> int:
        """The size of the chunk this header announces, reserved; :class:`_Refusal` if it is out of bounds."""
        kind, flag, size = struct.unpack("<3scI", header)
        bad_type = ua.StatusCodes.BadTcpMessageTypeInvalid
        if not self._hello and kind != b"HEL":
            raise _Refusal(bad_type, "the first message must be HEL", "not HEL first")
        if self._hello and kind == b"HEL":
            raise _Refusal(bad_type, "a second HEL", "not HEL first")
        if kind not in _FLAGS or flag not in _FLAGS[kind]:
            raise _Refusal(bad_type, f"unknown message type {kind!r} or chunk type {flag!r}", "bad header")
        if size <= (12 if kind in _SECURE else 8):
            raise _Refusal(bad_type, f"a {kind.decode()} chunk of {size} bytes: too small for its header",
                           "bad header")
        if size > self._chunk_limit:
            raise _Refusal(ua.StatusCodes.BadTcpMessageTooLarge, f"a chunk of {size:,} bytes; the limit is "
                           f"{self._chunk_limit:,} bytes", "chunk too large")
        if kind != b"CLO" and kind != b"HEL":
            limit = self.bounds.max_message if self.logged_in else min(LOGIN_MESSAGE, self.bounds.max_message)
            total, chunks = self._message[0] + size, self._message[1] + 1
            if total > limit or chunks > self.bounds.max_chunks:
                raise _Refusal(ua.StatusCodes.BadRequestTooLarge,
                               f"a message of more than {limit:,} bytes or {self.bounds.max_chunks} chunks"
                               + ("" if self.logged_in else " before login"), "message too large")
            self._message = [total, chunks] if flag == b"C" else [0, 0]
        if self.meter.held + size > self.bounds.max_buffered:
            raise _Refusal(ua.StatusCodes.BadTcpNotEnoughResources, "the server holds too many bytes for its "
                           "connections: try again later", "server buffers full")
        self._reserved += size
        self.meter.held += size
        self.meter.peak_held = max(self.meter.peak_held, self.meter.held)
        return size

    def _hand_over(self, chunk: bytes) -> None:
        buf = Buffer(chunk)
        header = header_from_binary(buf)
        if header.MessageType == ua.MessageType.Hello:
            self._hello_received(buf.copy())
        self._queued += len(chunk)
        self.messages.put_nowait((header, buf))   # room: _read stops before its queue is full

    def _hello_received(self, body: Buffer) -> None:
        try:
            hello = struct_from_binary(ua.Hello, body)
        except Exception:
            raise _Refusal(ua.StatusCodes.BadTcpInternalError, "a HEL that cannot be decoded", "bad header") from None
        if hello.ReceiveBufferSize < MIN_BUFFER or hello.SendBufferSize < MIN_BUFFER:
            raise _Refusal(ua.StatusCodes.BadConnectionRejected, f"HEL's buffers must be at least {MIN_BUFFER} "
                           "bytes (OPC UA Part 6)", "bad header")
        if len((hello.EndpointUrl or "").encode("utf-8")) > MAX_URL:
            raise _Refusal(ua.StatusCodes.BadTcpEndpointUrlInvalid, f"HEL's endpoint URL is over {MAX_URL} bytes",
                           "bad header")
        self._hello = True
        # asyncua acknowledges (and checks) chunks up to the smaller of its receive buffer and the client's send one
        self._chunk_limit = min(RECEIVE_BUFFER, hello.SendBufferSize)

    async def _process_one_msg(self, header, buf) -> bool:
        try:
            return await super()._process_one_msg(header, buf)
        except Exception as exc:
            if self.logged_in:      # asyncua logs it and reads on
                raise
            # before login, a chunk asyncua cannot read (garbage, a failed security check) closes the connection:
            # else a flood of tiny bad chunks is a flood of logged tracebacks
            log.debug("OPC UA: a chunk from %s failed", self.peer_name, exc_info=True)
            self._refuse(_Refusal(ua.StatusCodes.BadSecurityChecksFailed, "a chunk that cannot be read before "
                                  f"login ({type(exc).__name__})", "bad chunk before login"))
            return False
        finally:
            self._served(header)

    def pause_writing(self) -> None:
        """A client that does not read its answers is not read either (its answers would pile up in memory)."""
        self._unsent = True

    def resume_writing(self) -> None:
        self._unsent = False
        if self._paused and not self._done:
            self._read_or_refuse()

    def _served(self, header) -> None:
        size = header.packet_size
        self._queued -= size
        if header.MessageType in (ua.MessageType.SecureOpen, ua.MessageType.SecureMessage) \
                and header.ChunkType == ua.ChunkType.Intermediate:
            self._parts += size         # asyncua keeps it until the message's last chunk
        else:
            self._release(size + self._parts)
            self._parts = 0
        if self._paused and not self._done:
            self._read_or_refuse()

    def _release(self, size: int) -> None:
        size = min(size, self._reserved)
        self._reserved -= size
        self.meter.held -= size


def _send_error(transport, code: int, reason: str) -> None:
    try:
        transport.write(uatcp_to_binary(ua.MessageType.Error, ua.ErrorMessage(ua.StatusCode(code), reason)))
    except Exception:      # the connection is going anyway
        pass


# ---------------------------------------------------------------- the server

class BoundedBinaryServer(BinaryServer):
    """asyncua's listening socket, making a :class:`BoundedProtocol` for each connection with ``server``'s bounds of
    the moment."""

    def __init__(self, server: "BoundedServer", host, port):
        super().__init__(server.iserver, host, port, server.limits)
        self.server = server

    def _make_protocol(self) -> BoundedProtocol:
        bounds = self.server.bounds
        return BoundedProtocol(iserver=self.iserver, policies=self._policies, clients=self.clients,
                               closing_tasks=self.closing_tasks, limits=bounds.limits(), bounds=bounds,
                               meter=self.server.meter)


class BoundedServer(Server):
    """asyncua's :class:`~asyncua.Server` whose connections are read within ``bounds``; ``meter`` counts their work.

    ``bounds`` may be changed before a connection opens (it applies to the connections opened since)."""

    def __init__(self, bounds: TransportBounds = TransportBounds(), **kw):
        super().__init__(**kw)
        self.bounds = bounds
        self.meter = TransportMeter()
        self.limits = bounds.limits()

    async def start(self) -> None:
        """asyncua 2.1's ``Server.start``, with :class:`BoundedBinaryServer` for its ``BinaryServer``
        (tests/test_opcua_bounds.py fails if asyncua's changes)."""
        iserver = self.iserver
        iserver.max_connections = MAX_CONNECTIONS + 1         # ours refuse first, with ERR
        iserver.max_pending_activation_seconds = 0            # ours closes, at bounds.login_seconds
        if iserver.certificate is not None:
            uacrypto.check_certificate(iserver.certificate, self._application_uri, _hostname())
        await self._setup_server_nodes()
        await iserver.start()
        try:
            host, port = self._get_bind_socket_info()
            self.bserver = BoundedBinaryServer(self, host, port)
            self.bserver.set_policies(self._policies)
            await self.bserver.start()
        except Exception:
            log.debug("OPC UA: could not listen", exc_info=True)
            await iserver.stop()
            raise


def _hostname() -> str:
    import socket

    return socket.gethostname()
