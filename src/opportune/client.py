"""A small typed client for a cell controller: :class:`Cell` drives runs of an ``opportune serve`` service,
and :class:`AsyncCell` is the same client for asyncio.

With a service running (``opportune serve``) and a cell's token::

    from opportune.client import Cell, LookContradictsState

    with Cell("http://127.0.0.1:8700", token) as cell:
        plan = cell.upload_plan(Path("examples/gearbox.yaml"))
        run = cell.start_run(plan.id, label="SN 1042")
        answer = cell.look(run.id, ["rl", "ra"])                     # what the camera sees
        answer.action.kind, answer.action.part                      # ('buffer', 'rl')
        cell.outcome(run.id, "success")                             # the robot did it

With asyncio, ``async with AsyncCell(url, token) as cell:`` and ``answer = await cell.look(run.id, ["rl", "ra"])``:
the same methods as coroutines, with the same answers, retries and errors.

Every answer is a Pydantic model of :mod:`opportune.service.schemas` (the same models the
service's OpenAPI document is built from), so fields are typed and checked.

**Retries.**  A request that changes a run (start, look, outcome, cancel) is sent with a fresh
``Idempotency-Key``; when the connection fails or times out, or the service answers 5xx (or 409
``run_busy``), it is sent again with the *same* key, up to ``retries`` more times with a growing
pause.  The service answers a retry from its store of answers, so an action is never decided
twice even when the first answer was lost on the way back.  Reads and plan uploads (a plan's id
is its content hash) are retried the same way.

**Errors.**  A refusal raises a :class:`CellError` subclass carrying the service's ``status``,
``code``, ``message``, ``hint`` and ``where``: by code (e.g. :class:`LookContradictsState`,
:class:`NoPendingAction`, :class:`UnknownPart`), else by status (:class:`NotFound`,
:class:`Conflict`, :class:`InvalidRequest`, ...).  :class:`ServiceUnreachable` is raised when no
answer came back at all.

Needs ``httpx`` and ``pydantic``: ``pip install 'opportune[service]'``.
"""

from __future__ import annotations

import asyncio
import functools
import inspect
import os
import time
import uuid
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, Literal, ParamSpec, TypeVar, overload

from opportune.formats.shipped import EXAMPLE_PREFIX, PREFIX

try:
    import httpx
    from pydantic import BaseModel, ValidationError

    from opportune.service.schemas import (CancelAnswer, Health, LookAnswer, OutcomeAnswer, PlanDetail, PlanUploaded,
                                           Run, RunList, RunSummary, Trace)
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError(f"opportune.client needs httpx and pydantic ({exc.name} is missing): "
                      "pip install 'opportune[service]'", name=exc.name) from None

#: Suffixes of plan files: a one-line ``str`` ending in one is taken for a path by ``upload_plan``.
PLAN_SUFFIXES = (".yaml", ".yml", ".json", ".in2", ".alb", ".graphml", ".dot", ".gv")
#: The names of plans shipped with the package (the service reads them; nothing but the name is sent).
SHIPPED_PREFIXES = (PREFIX, EXAMPLE_PREFIX)

__all__ = [
    "Cell", "AsyncCell", "CellError", "BadRequest", "Unauthorized", "Forbidden", "NotFound", "Conflict", "LookContradictsState",
    "ActionPending", "RunComplete", "NoPendingAction", "OutcomeRefused", "RunBusy", "PayloadTooLarge",
    "UnsupportedMediaType", "InvalidRequest", "InvalidPlan", "UnknownPlan", "UnknownPart", "IdempotencyKeyReused", "KeyRequired",
    "ServerError", "Unavailable", "ServiceUnreachable", "UnexpectedAnswer",
]

R = TypeVar("R")
P = ParamSpec("P")


# ---------------------------------------------------------------- errors

class CellError(Exception):
    """A request the service refused (or could not answer): its status, code, message, hint and where."""

    status: int | None
    code: str

    def __init__(self, status: int | None, code: str, message: str, hint: str = "", *, where: str | None = None,
                 problems: list[dict] | None = None, body: dict | None = None):
        super().__init__(message)
        self.status = status
        self.code = code
        self.message = message
        self.hint = hint
        self.where = where
        self.problems = problems or []
        self.body = body

    def __str__(self) -> str:
        head = f"{self.status} {self.code}" if self.status else self.code
        where = f" at {self.where}" if self.where else ""
        hint = f" (hint: {self.hint})" if self.hint else ""
        return f"{head}: {self.message}{where}{hint}"


class BadRequest(CellError):
    """400: the request could not be read (malformed JSON, a bad Idempotency-Key)."""


class Unauthorized(CellError):
    """401: no valid bearer token."""


class Forbidden(CellError):
    """403: the token may not do this (e.g. an operator token writing)."""


class NotFound(CellError):
    """404: no such run or plan for this token (another cell's run is not found either)."""


class Conflict(CellError):
    """409: refused in the run's present state; nothing changed."""


class LookContradictsState(Conflict):
    """409 ``look_contradicts_state``: the look shows a part that cannot be in the bin."""


class ActionPending(Conflict):
    """409 ``action_pending``: report the pending action's outcome (or cancel it) before the next look."""


class RunComplete(Conflict):
    """409 ``run_complete``: the run's last part is installed (it is complete at the outcome of its last
    install: no look follows; the next assembly is a new run)."""


class NoPendingAction(Conflict):
    """409 ``no_pending_action``: an outcome or cancel with no action pending."""


class OutcomeRefused(Conflict):
    """409 ``outcome_refused``: this outcome is not possible for the pending action."""


class RunBusy(Conflict):
    """409 ``run_busy``: another server process is changing the run (retried by the client)."""


class PayloadTooLarge(CellError):
    """413: the body is larger than the service's limit."""


class UnsupportedMediaType(CellError):
    """415: the body is not JSON."""


class InvalidRequest(CellError):
    """422: an invalid request; nothing changed."""


class InvalidPlan(InvalidRequest):
    """422 ``invalid_plan``: ``problems`` lists every finding of ``opportune check``."""


class UnknownPlan(InvalidRequest):
    """422 ``unknown_plan``: upload the plan first."""


class UnknownPart(InvalidRequest):
    """422 ``unknown_part``: a look names a part the plan does not have."""


class IdempotencyKeyReused(InvalidRequest):
    """422 ``idempotency_key_reused``: the key was used for another request."""


class KeyRequired(CellError):
    """428: the request needs an Idempotency-Key (the client always sends one)."""


class ServerError(CellError):
    """5xx: the service failed on the request; nothing was changed (retried by the client)."""


class Unavailable(ServerError):
    """503: over the counting budget for now (retried by the client)."""


class ServiceUnreachable(CellError):
    """No answer: the connection failed or timed out on every attempt (``status`` is None)."""


class UnexpectedAnswer(CellError):
    """An answer that is not what the service's OpenAPI document says (a proxy's page, another server)."""


BY_CODE: dict[str, type[CellError]] = {
    "look_contradicts_state": LookContradictsState, "action_pending": ActionPending, "run_complete": RunComplete,
    "no_pending_action": NoPendingAction, "outcome_refused": OutcomeRefused, "run_busy": RunBusy,
    "invalid_plan": InvalidPlan, "unknown_plan": UnknownPlan, "unknown_part": UnknownPart,
    "idempotency_key_reused": IdempotencyKeyReused,
}
BY_STATUS: dict[int, type[CellError]] = {
    400: BadRequest, 401: Unauthorized, 403: Forbidden, 404: NotFound, 409: Conflict, 413: PayloadTooLarge,
    415: UnsupportedMediaType, 422: InvalidRequest, 428: KeyRequired, 503: Unavailable,
}


def error_from(response: httpx.Response) -> CellError:
    """The typed error of a refusal (``{"error": {status, code, message, hint, where}}``)."""
    status = response.status_code
    try:
        err = response.json()["error"]
        code, message = str(err["code"]), str(err["message"])
    except (ValueError, KeyError, TypeError):
        kind = ServerError if status >= 500 else BY_STATUS.get(status, CellError)
        return kind(status, "http_error", f"HTTP {status} without the service's error body: {response.text[:200]!r}")
    kind = BY_CODE.get(code) or BY_STATUS.get(status) or (ServerError if status >= 500 else CellError)
    return kind(status, code, message, str(err.get("hint") or ""), where=err.get("where"),
                problems=err.get("problems"), body=err)


def _retryable(error: CellError) -> bool:
    return isinstance(error, (ServerError, RunBusy))


def _run_id(run) -> int:
    if isinstance(run, bool):
        raise TypeError("a run is its id (an int) or a run answer")
    if isinstance(run, int):
        return run
    if isinstance(run, Run):
        return run.id
    rid = getattr(run, "run_id", None)
    if isinstance(rid, int):
        return rid
    raise TypeError(f"a run is its id (an int) or a run answer, not {type(run).__name__}")


# ---------------------------------------------------------------- what both clients share

#: The failures of an attempt that got no answer at all (retried; :class:`ServiceUnreachable` at the end).
NO_ANSWER = (httpx.TimeoutException, httpx.NetworkError, httpx.RemoteProtocolError)


@dataclass
class _Call(Generic[R]):
    """One request of a client method: what to send, and how its answer is read.

    A request that changes a run (``write``) gets a fresh ``Idempotency-Key`` here, once: every
    attempt of this call sends the same key.  ``pick`` takes the part of the answer the method
    returns (the whole model when None).
    """

    method: str
    path: str
    model: type[BaseModel]
    write: bool = False
    params: dict[str, Any] | None = None
    json: Any = None
    content: bytes | None = None
    headers: dict[str, str] = field(default_factory=dict)
    pick: Callable[[Any], R] | None = None

    def __post_init__(self):
        if self.write:
            self.headers = {**self.headers, "Idempotency-Key": uuid.uuid4().hex}

    @property
    def request(self) -> dict[str, Any]:
        """The arguments of ``httpx.Client.request`` (and of ``httpx.AsyncClient.request``)."""
        return {"method": self.method, "url": self.path, "params": self.params, "json": self.json,
                "content": self.content, "headers": self.headers}

    def read(self, response: httpx.Response) -> R:
        """A success's body as the model (:class:`UnexpectedAnswer` when it is not one)."""
        try:
            answer = self.model.model_validate_json(response.content)
        except ValidationError as exc:
            raise UnexpectedAnswer(response.status_code, "unexpected_answer",
                                   f"{self.method} {self.path}: the answer is not a {self.model.__name__}: "
                                   f"{exc.errors()[0]['msg'] if exc.errors() else exc}",
                                   "is the URL that of an opportune service?") from None
        return self.pick(answer) if self.pick else answer

    def unreachable(self, attempts: int, exc: Exception) -> ServiceUnreachable:
        return ServiceUnreachable(None, "unreachable", f"{self.method} {self.path}: no answer after {attempts} "
                                  f"attempt(s): {type(exc).__name__}: {exc}",
                                  "check that the service runs and the URL is right")


class _Method(Generic[P, R]):
    """A method of both clients, written once: the function builds the :class:`_Call`, and the client it is
    called on sends it (:class:`Cell` returns the answer, :class:`AsyncCell` a coroutine of it)."""

    def __init__(self, build: Callable[P, _Call[R]]):
        self.build = build
        functools.update_wrapper(self, build)
        # as the methods show themselves (help, inspect): returning the answer, not the call
        answer = str(build.__annotations__["return"]).removeprefix("_Call[").removesuffix("]")
        self.__annotations__ = {**build.__annotations__, "return": answer}
        self.__signature__ = inspect.signature(build).replace(return_annotation=answer)

    @overload
    def __get__(self, client: None, owner: type) -> _Method[P, R]: ...
    @overload
    def __get__(self, client: AsyncCell, owner: type) -> Callable[P, Coroutine[Any, Any, R]]: ...
    @overload
    def __get__(self, client: Cell, owner: type) -> Callable[P, R]: ...

    def __get__(self, client, owner=None):
        if client is None:
            return self

        if inspect.iscoroutinefunction(client._send):
            async def method(*args, **kwargs):
                return await client._send(self.build(*args, **kwargs))
        else:
            def method(*args, **kwargs):
                return client._send(self.build(*args, **kwargs))
        return functools.update_wrapper(method, self)

    def __call__(self, client: _Client, /, *args, **kwargs):
        """Called on the class, as a method is: ``Cell.look(cell, run, visible)``."""
        return self.__get__(client, type(client))(*args, **kwargs)


def _run_to_end(coroutine: Coroutine[Any, Any, R]) -> R:
    """The result of a coroutine that never suspends (:class:`Cell`'s transport blocks), with no event loop."""
    try:
        coroutine.send(None)
    except StopIteration as done:
        return done.value
    coroutine.close()
    raise RuntimeError("a blocking client's request suspended")  # pragma: no cover - a transport that awaits


class _Client:
    """Both clients' methods and their retry loop; a subclass is the transport: it sends one attempt and
    pauses between attempts (blocking in :class:`Cell`, awaiting in :class:`AsyncCell`)."""

    _http_class: type[httpx.Client | httpx.AsyncClient]

    def __init__(self, base_url: str, token: str, *, timeout: float = 30.0, retries: int = 3, backoff: float = 0.2,
                 transport: httpx.BaseTransport | httpx.AsyncBaseTransport | None = None,
                 headers: dict[str, str] | None = None):
        if retries < 0:
            raise ValueError("retries must be 0 or more")
        self.retries = retries
        self.backoff = backoff
        self.replayed = False  # whether the last answer was the service's stored answer of an earlier attempt
        self.attempts = 0      # how many attempts the last request took
        self.http = self._http_class(base_url=base_url.rstrip("/"), timeout=timeout, transport=transport,
                                     headers={**(headers or {}), "Authorization": f"Bearer {token}",
                                              "Accept": "application/json"})

    # ------------------------------------------------------------ plans

    @_Method
    def upload_plan(plan: str | bytes | os.PathLike | dict, *, format: Literal["yaml", "json", "in2"] | None = None,
                    filename: str | None = None) -> _Call[PlanUploaded]:
        """Upload a plan, validated as ``opportune check`` does; its ``id`` starts runs.

        ``plan`` is a file (a path, or a one-line ``str`` naming an existing file), a plan shipped with the
        package by name (``"salbp:ARC111"``, ``"example:gearbox"``: read by the service, nothing is sent but
        the name), the file's text (``str`` or ``bytes``: YAML, JSON or SALBP .IN2, detected, or ``format``),
        or a plan in the JSON file schema (a ``dict``).  An invalid plan raises :class:`InvalidPlan`, whose
        ``problems`` say what and where; an unknown shipped name raises :class:`CellError` (``unknown_plan``,
        its hint naming what is shipped); a one-line ``str`` ending in a plan file's suffix that names no
        file raises ``FileNotFoundError``.
        """
        if isinstance(plan, dict):
            body: dict[str, Any] = {"json": plan}
        elif isinstance(plan, str) and "\n" not in plan and plan.lower().startswith(SHIPPED_PREFIXES) \
                and not os.path.isfile(plan):
            body = {"json": {"shipped": plan}}
        else:
            if isinstance(plan, str) and "\n" not in plan and len(plan) < 4096:
                if os.path.isfile(plan):
                    plan = Path(plan)
                elif plan.strip().lower().endswith(PLAN_SUFFIXES):
                    raise FileNotFoundError(f"no such plan file: {plan!r} (pass a plan's text, or the path of an "
                                            "existing file)")
            if isinstance(plan, os.PathLike):
                filename = filename or os.path.basename(os.fspath(plan))
                with open(plan, "rb") as f:
                    plan = f.read()
            body = {"content": plan.encode("utf-8") if isinstance(plan, str) else plan,
                    "headers": {"Content-Type": "text/plain; charset=utf-8"}}
        params = {k: v for k, v in (("format", format), ("filename", filename)) if v}
        return _Call("POST", "/plans", PlanUploaded, params=params, **body)

    @_Method
    def plan(plan_id: str) -> _Call[PlanDetail]:
        """A stored plan: its document, summary and graph layout."""
        return _Call("GET", f"/plans/{plan_id}", PlanDetail)

    # ------------------------------------------------------------ runs

    @_Method
    def start_run(plan: str | PlanUploaded, *, buffer_capacity: int | None = None, label: str = "",
                  policy: str | None = None, products: int | None = None) -> _Call[Run]:
        """Start a run of a stored plan (its id, or a shipped plan's name such as ``"salbp:ARC111"``, stored for
        this cell as the run starts) in this token's cell (``buffer_capacity`` None: unlimited; ``policy``
        None: the service's default, the exact look-ahead; ``"paper"``: the paper's rule; ``products``: build
        that many copies at once on as many fixtures fed from one bin, 1–16)."""
        plan_id = plan.id if isinstance(plan, PlanUploaded) else plan
        body = {"plan": plan_id, "buffer_capacity": buffer_capacity, "label": label}
        if policy is not None:
            body["policy"] = policy
        if products is not None:
            body["products"] = products
        return _Call("POST", "/runs", Run, write=True, json=body)

    @_Method
    def look(run: int | Run, visible: list[str] | tuple[str, ...]) -> _Call[LookAnswer]:
        """The parts seen in the bin now (repeated for several units; ``[]`` for none) → the action to do.

        The answer's ``action`` (``kind``, ``part``, ``source``) is what the robot does next; its
        ``decision`` says why.  Raises :class:`LookContradictsState`, :class:`ActionPending`,
        :class:`RunComplete` or :class:`UnknownPart` when the look is refused.
        """
        if isinstance(visible, str):
            raise TypeError("visible is a list of part ids, not one string")
        return _Call("POST", f"/runs/{_run_id(run)}/looks", LookAnswer, write=True, json={"visible": list(visible)})

    @_Method
    def outcome(run: int | Run, outcome: Literal["success", "failed", "defective"] = "success", *,
                keep: Literal["bin", "buffer"] = "bin") -> _Call[OutcomeAnswer]:
        """The outcome of the pending action (``keep``: after a failed install, the part back in the bin or
        kept in a buffer location)."""
        return _Call("POST", f"/runs/{_run_id(run)}/outcomes", OutcomeAnswer, write=True,
                     json={"outcome": outcome, "keep": keep})

    @_Method
    def cancel(run: int | Run) -> _Call[CancelAnswer]:
        """Drop the pending action (the robot did not carry it out)."""
        return _Call("POST", f"/runs/{_run_id(run)}/cancel", CancelAnswer, write=True, json={})

    @_Method
    def state(run: int | Run) -> _Call[Run]:
        """The run's state: installed, buffered, in the bin, the pending action, the completions left."""
        return _Call("GET", f"/runs/{_run_id(run)}", Run)

    @_Method
    def trace(run: int | Run) -> _Call[Trace]:
        """The trace in the layout of the paper's Table 1 (the pending row last)."""
        return _Call("GET", f"/runs/{_run_id(run)}/trace", Trace)

    @_Method
    def runs(*, status: Literal["active", "complete"] | None = None, limit: int = 200,
             offset: int = 0) -> _Call[list[RunSummary]]:
        """This cell's runs, newest first."""
        params: dict[str, Any] = {"limit": limit, "offset": offset}
        if status:
            params["status"] = status
        return _Call("GET", "/runs", RunList, params=params, pick=lambda answer: answer.runs)

    @_Method
    def health() -> _Call[Health]:
        """Whether the service and its database answer, and the service's version."""
        return _Call("GET", "/healthz", Health)

    # ------------------------------------------------------------ the retry loop

    async def _exchange(self, call: _Call[R]) -> R:
        """Send ``call`` (retrying as the class says, with the same key) and read its answer."""
        self.replayed = False
        attempt = 0
        while True:
            attempt += 1
            self.attempts = attempt
            try:
                response = await self._attempt(call)
            except NO_ANSWER as exc:
                if attempt > self.retries:
                    raise call.unreachable(attempt, exc) from exc
            else:
                if response.status_code < 400:
                    self.replayed = response.headers.get("Idempotent-Replayed") == "true"
                    return call.read(response)
                error = error_from(response)
                if not _retryable(error) or attempt > self.retries:
                    raise error
            await self._pause(self.backoff * 2 ** (attempt - 1))

    # ------------------------------------------------------------ the transport (a subclass's)

    def _send(self, call: _Call[R]):
        """The answer of ``call`` (:class:`Cell`), or a coroutine of it (:class:`AsyncCell`)."""
        raise NotImplementedError

    async def _attempt(self, call: _Call) -> httpx.Response:
        raise NotImplementedError

    async def _pause(self, seconds: float) -> None:
        raise NotImplementedError


# ---------------------------------------------------------------- the clients

class Cell(_Client):
    """One cell's connection to the service: ``Cell(base_url, token)``; each method blocks until its answer.

    ``timeout`` is the seconds one attempt may take; ``retries`` how many times a request is sent
    again after a connection failure, a timeout, a 5xx or a 409 ``run_busy`` (with the same
    Idempotency-Key), pausing ``backoff`` seconds, doubled each time.  ``transport`` is an
    ``httpx`` transport (tests, proxies); ``headers`` more headers for every request.
    """

    _http_class = httpx.Client
    http: httpx.Client

    def _send(self, call: _Call[R]) -> R:
        return _run_to_end(self._exchange(call))

    async def _attempt(self, call: _Call) -> httpx.Response:
        return self.http.request(**call.request)  # blocks: the exchange never suspends

    async def _pause(self, seconds: float) -> None:
        time.sleep(seconds)  # noqa: ASYNC251 - blocks, as the whole exchange does

    def close(self) -> None:
        self.http.close()

    def __enter__(self) -> Cell:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class AsyncCell(_Client):
    """:class:`Cell` for asyncio: ``async with AsyncCell(base_url, token) as cell``, then
    ``await cell.look(run, [...])``; the same methods as coroutines, with the same arguments, retries
    (with the same Idempotency-Key), answers and errors.  ``transport`` is an ``httpx`` async transport.

    ``replayed`` and ``attempts`` are those of the request that finished last: with requests running
    at once on one client, read them from a client of each task's own.
    """

    _http_class = httpx.AsyncClient
    http: httpx.AsyncClient

    async def _send(self, call: _Call[R]) -> R:
        return await self._exchange(call)

    async def _attempt(self, call: _Call) -> httpx.Response:
        return await self.http.request(**call.request)

    async def _pause(self, seconds: float) -> None:
        await asyncio.sleep(seconds)

    async def aclose(self) -> None:
        await self.http.aclose()

    async def __aenter__(self) -> AsyncCell:
        return self

    async def __aexit__(self, *exc) -> None:
        await self.aclose()
