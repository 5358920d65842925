"""The HTTP connection: uvicorn's h11 protocol with a deadline on receiving each request.

uvicorn times a connection out only while it is idle between two requests (``timeout_keep_alive``).
A client that opens a connection and sends nothing, or trickles a request line, its headers or its
body a byte at a time (slowloris), would hold the connection, and a slot of the server, for as long
as it likes.  Here every request must arrive whole within :attr:`Guarded.seconds` of the
connection's opening or of its own first byte; past that the connection is closed.  A request
whose headers are in is answered as usual, with no time limit on the answer (event streams last).

The class is uvicorn's ``http`` protocol (``uvicorn.Config(http=Guarded)``).  ``seconds`` is a class
attribute: :func:`opportune.service.server.serve` sets it in this process, and each worker process
sets it from the settings in its environment.
"""

from __future__ import annotations

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

__all__ = ["Guarded", "REQUEST_SECONDS"]

#: Default seconds a request may take to arrive whole (request line, headers and body).
REQUEST_SECONDS = 10.0

_WHOLE = (h11.DONE, h11.MUST_CLOSE, h11.CLOSED, h11.ERROR)


class Guarded(H11Protocol):
    """uvicorn's h11 protocol; a request must arrive whole within ``seconds`` (O(1) per data event)."""

    seconds: float = REQUEST_SECONDS

    def connection_made(self, transport) -> None:
        super().connection_made(transport)
        self._arrival = None
        self._arm()

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        if self.conn.their_state in _WHOLE:
            self._disarm()          # the request is in: its answer takes what it takes
        else:
            self._arm()             # part of a request (or of the next one on a kept-alive connection)

    def connection_lost(self, exc) -> None:
        self._disarm()
        super().connection_lost(exc)

    def on_response_complete(self) -> None:
        super().on_response_complete()
        # a pipelined request already buffered starts its own clock; otherwise the keep-alive timer runs
        if self.conn.their_state not in _WHOLE and self.conn.trailing_data[0]:
            self._arm()

    def _arm(self) -> None:
        if self._arrival is None and not self.transport.is_closing():
            self._arrival = self.loop.call_later(self.seconds, self._too_slow)

    def _disarm(self) -> None:
        if self._arrival is not None:
            self._arrival.cancel()
            self._arrival = None

    def _too_slow(self) -> None:
        self._arrival = None
        if self.conn.their_state not in _WHOLE and not self.transport.is_closing():
            self.logger.info("closed a connection whose request did not arrive within %.1f s", self.seconds)
            self.transport.close()
