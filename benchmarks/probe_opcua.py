"""A hostile client against ``opportune serve --opcua`` before login: what the server reads, holds and keeps.

One server subprocess (OPC UA alone, loopback, default options); each probe is a raw TCP client speaking just
enough OPC UA (HEL, then chunk headers that lie).  Per probe: the server's answer, the bytes the server process
read from the probe's connections (as its log says when it closes one; an older server does not say), the CPU
time it spent, its resident memory
before, at its peak (sampled every 20 ms) and after, and how long the connection stayed open after the probe's
last byte (or after it opened, for the probes about time).  Then a certificate-authenticated client drives a
run, and the server's memory a minute after the last attack is compared with before the first.

    .venv/bin/python benchmarks/probe_opcua.py                # the table, about 2 minutes
    .venv/bin/python benchmarks/probe_opcua.py --stream-mb 10 --settle 5 --only HEL

It uses only the service's public pieces (no transport internals), so it also measures an older version.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import re
import socket
import struct
import tempfile
import threading
import time
from pathlib import Path

from asyncua import ua
from asyncua.ua.ua_binary import struct_from_binary, uatcp_to_binary

from opportune.datasets import example_path
from opportune.service.opcua import client_certificate
from opportune.service.opcua_client import CellClient
from opportune.service.testing import ServiceProcess

APP = "urn:opportune:probe"
BIG = 2 ** 31 - 1
MB = 1 << 20


class Process:
    """The server process's counters and a sampler of its resident memory."""

    def __init__(self, pid: int):
        self.pid = pid
        self.peak = 0
        self._stop = threading.Event()
        threading.Thread(target=self._sample, daemon=True).start()

    def rss(self) -> int:
        with open(f"/proc/{self.pid}/status") as f:
            return next(int(line.split()[1]) << 10 for line in f if line.startswith("VmRSS:"))

    def cpu(self) -> float:
        """Seconds of CPU the server has used (user and system)."""
        with open(f"/proc/{self.pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def _sample(self):
        while not self._stop.wait(0.02):
            try:
                self.peak = max(self.peak, self.rss())
            except OSError:
                return

    def stop(self):
        self._stop.set()


def hello(url: str, size: int = 65535) -> bytes:
    return uatcp_to_binary(ua.MessageType.Hello, ua.Hello(ProtocolVersion=0, ReceiveBufferSize=size,
                                                          SendBufferSize=size, MaxMessageSize=0 if size == 65535
                                                          else size, MaxChunkCount=0 if size == 65535 else size,
                                                          EndpointUrl=url))


def header(kind: bytes, size: int) -> bytes:
    return kind + b"F" + struct.pack("<I", size) + struct.pack("<I", 0)


def connect(endpoint: str, timeout: float) -> socket.socket:
    host, port = endpoint.removeprefix("opc.tcp://").split(":")
    return socket.create_connection((host, int(port)), timeout=timeout)


def answer(sock: socket.socket) -> str:
    """The server's next message, as text: ``ACK ...``, its ERR's status, or ``closed``."""
    try:
        head = b""
        while len(head) < 8:
            got = sock.recv(8 - len(head))
            if not got:
                return "closed"
            head += got
        kind, _flag, size = struct.unpack("<3scI", head)
        body = b""
        while len(body) < size - 8:
            got = sock.recv(size - 8 - len(body))
            if not got:
                break
            body += got
    except ConnectionResetError:
        return "reset"
    except TimeoutError:
        return "still open"
    if kind == b"ACK":
        ack = struct_from_binary(ua.Acknowledge, ua.utils.Buffer(body))
        return (f"ACK recv {ack.ReceiveBufferSize}, send {ack.SendBufferSize}, msg {ack.MaxMessageSize:,}, "
                f"chunks {ack.MaxChunkCount}")
    if kind == b"ERR":
        err = struct_from_binary(ua.ErrorMessage, ua.utils.Buffer(body))
        return ua.StatusCode(err.Error.value).name
    return kind.decode(errors="replace")


def wait_closed(sock: socket.socket, limit: float) -> float | None:
    """Seconds until the server closes (None: still open after ``limit``)."""
    start = time.monotonic()
    sock.settimeout(limit)
    try:
        while sock.recv(65536):
            pass
    except ConnectionResetError:
        pass
    except TimeoutError:
        return None
    return time.monotonic() - start


def stream(sock: socket.socket, total: int, limit: float) -> int:
    """Send ``total`` zero bytes (or for ``limit`` seconds, or until the server resets); bytes sent."""
    piece, sent, end = bytes(1 << 16), 0, time.monotonic() + limit
    try:
        while sent < total and time.monotonic() < end:
            sock.sendall(piece)
            sent += len(piece)
    except OSError:
        pass
    return sent


# ---------------------------------------------------------------- the probes: (result, seconds open)

def huge_then_stream(endpoint, kind, args):
    sock = connect(endpoint, args.limit)
    sock.sendall(hello(endpoint))
    ack = answer(sock)
    sock.sendall(header(kind, BIG))
    sent = stream(sock, args.stream_mb * MB, args.limit)
    start = time.monotonic()
    got = answer(sock)
    closed = wait_closed(sock, args.limit)
    sock.close()
    return f"{ack.split(' ')[0]}, then {got}; client sent {sent / MB:.1f} MB", \
        None if closed is None else time.monotonic() - start


def whole_chunk(endpoint, args):
    sock = connect(endpoint, args.limit)
    sock.sendall(hello(endpoint))
    answer(sock)
    sock.sendall(header(b"MSG", 10 * MB))
    sent = stream(sock, 10 * MB - 12, args.limit)
    start = time.monotonic()
    got = answer(sock)
    closed = wait_closed(sock, args.limit)
    return f"{got}; client sent {sent / MB:.1f} MB", None if closed is None else time.monotonic() - start


def huge_hello(endpoint, args):
    sock = connect(endpoint, args.limit)
    sock.sendall(hello(endpoint, 2 ** 32 - 1))
    got = answer(sock)
    sock.close()
    return got, "-"


def trickle(endpoint, args):
    message = hello(endpoint)
    sock = connect(endpoint, 1.0)
    start = time.monotonic()
    sent, got = 0, "still open"
    while sent < len(message) and time.monotonic() - start < args.limit:
        try:
            sock.send(message[sent:sent + 1])
        except OSError:
            got = "reset"
            break
        sent += 1
        got = answer(sock)          # waits a second for the server: a byte a second
        if got != "still open":
            break
    seconds = time.monotonic() - start
    sock.close()
    return f"{got} after {sent} of {len(message)} HEL bytes", None if got == "still open" else seconds


def idle(endpoint, args):
    sock = connect(endpoint, args.limit)
    start = time.monotonic()
    sock.sendall(hello(endpoint))
    answer(sock)
    got = answer(sock)
    closed = wait_closed(sock, args.limit)
    return f"ACK, then {got}", None if closed is None else time.monotonic() - start


def bad_chunks(endpoint, args):
    sock = connect(endpoint, args.limit)
    sock.sendall(hello(endpoint))
    answer(sock)
    tiny = (b"OPNF" + struct.pack("<I", 13) + struct.pack("<I", 0) + b"\0") * 10_000
    try:
        sock.sendall(tiny)
    except OSError:
        pass
    start = time.monotonic()
    got = answer(sock)
    closed = wait_closed(sock, args.limit)
    return f"{got}", None if closed is None else time.monotonic() - start


def crowd(endpoint, args):
    socks, refused, answers = [], 0, set()
    for _ in range(args.crowd):
        try:
            sock = connect(endpoint, 2.0)
        except OSError:
            refused += 1
            continue
        socks.append(sock)
    time.sleep(0.5)
    for sock in socks:
        sock.settimeout(0.05)
        got = answer(sock)        # an idle connection hears nothing
        if got != "still open":
            refused += 1
            answers.add(got)
    for sock in socks:
        sock.close()
    return f"{args.crowd - refused} kept, {refused} refused ({', '.join(sorted(answers)) or '-'})", "-"


def parallel(endpoint, args):
    results = []

    def one():
        results.append(huge_then_stream(endpoint, b"MSG", argparse.Namespace(stream_mb=10, limit=args.limit)))

    threads = [threading.Thread(target=one) for _ in range(16)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    closed = [s for _r, s in results if s is not None]
    return f"16 x (MSG 2^31-1 + 10 MB): {len(closed)} closed", max(closed) if closed else None


def normal_client(endpoint, token, cert, key) -> str:
    async def drive():
        async with CellClient(endpoint, token, certificate=cert, private_key=key, app_uri=APP) as cell:
            run = await cell.start_run(example_path("gearbox").read_text(), policy="paper")
            return (await cell.look(run, ["rl", "ra"]))["action"]

    return f"a look answered {asyncio.run(drive())}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stream-mb", type=int, default=50, help="megabytes streamed after a lying header")
    ap.add_argument("--limit", type=float, default=45.0, help="most seconds a probe waits or streams")
    ap.add_argument("--crowd", type=int, default=200, help="idle connections opened at once")
    ap.add_argument("--settle", type=float, default=60.0, help="seconds after the attacks before the last RSS")
    ap.add_argument("--only", default="", help="the probes whose name contains this")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="probe-opcua-"))
    cert, key = client_certificate(tmp / "client", APP, trust_in=tmp / "pki")
    probes = [
        ("OPN header 2^31-1 after HEL, then stream", lambda e: huge_then_stream(e, b"OPN", args)),
        ("MSG header 2^31-1 after HEL, then stream", lambda e: huge_then_stream(e, b"MSG", args)),
        ("MSG chunk of 10 MiB, sent whole", lambda e: whole_chunk(e, args)),
        ("HEL announcing 4 GiB buffers", lambda e: huge_hello(e, args)),
        ("HEL trickled, a byte a second", lambda e: trickle(e, args)),
        ("HEL, then no session", lambda e: idle(e, args)),
        ("10,000 tiny bad OPN chunks after HEL", lambda e: bad_chunks(e, args)),
        (f"{args.crowd} idle connections", lambda e: crowd(e, args)),
        ("16 at once: MSG 2^31-1 + 10 MB each", lambda e: parallel(e, args)),
    ]
    probes = [(name, probe) for name, probe in probes if args.only in name]
    rows = []
    with ServiceProcess(tmp / "probe.db", opcua=True, pki=tmp / "pki",
                        extra_args=("--no-http", "--no-access-log")) as svc:
        token = svc.token(cell="probe")
        proc = Process(svc.proc.pid)
        print(f"warming up: {normal_client(svc.opcua_endpoint, token, cert, key)}", flush=True)
        time.sleep(1.0)
        first = proc.rss()
        for name, probe in probes:
            before, cpu, log = proc.rss(), proc.cpu(), len(svc.log_text())
            proc.peak = before
            result, seconds = probe(svc.opcua_endpoint)
            time.sleep(0.5)
            said = [int(n) for n in re.findall(r"after (\d+) bytes read", svc.log_text()[log:])]
            read = f"{sum(said):,} ({len(said)} closed)" if said else "not said"
            rows.append((name, result, read, proc.cpu() - cpu, before, proc.peak, proc.rss(), seconds))
            print(f"{name}: {result}", flush=True)
        ok = normal_client(svc.opcua_endpoint, token, cert, key)
        time.sleep(args.settle)
        last = proc.rss()
        proc.stop()
    print(f"\nserver: opportune serve --opcua --no-http (pid {svc.proc.pid}); {os.cpu_count()} cores, "
          f"load {' '.join(f'{x:.2f}' for x in os.getloadavg())}\n")
    print("| probe | result | bytes read by server | server CPU s | RSS before MB | peak MB | after MB | open for s |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for name, result, read, cpu, before, peak, after, seconds in rows:
        open_for = "still open" if seconds is None else seconds if isinstance(seconds, str) else f"{seconds:.2f}"
        print(f"| {name} | {result} | {read} | {cpu:.2f} | {before / MB:.0f} | {peak / MB:.0f} | {after / MB:.0f} "
              f"| {open_for} |")
    print(f"\nafter the attacks: {ok}; RSS before the first probe {first / MB:.0f} MB, "
          f"{args.settle:.0f} s after the last {last / MB:.0f} MB ({(last - first) / MB:+.0f} MB)")


if __name__ == "__main__":
    main()
