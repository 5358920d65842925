"""The sequencer as an OPC UA server (IEC 62541), for PLCs and robot controllers, on the service's own runs.

``opportune serve --opcua`` serves this beside the HTTP API (or alone) on the same
:class:`~opportune.service.core.Core`: the same run manager, store, tokens and idempotency records,
so a run started over OPC UA is the same run over HTTP, every method call that changes a run is
committed before it answers (a restart, even after ``kill -9``, resumes every run), and a request id
used once answers the same whichever protocol repeats it.

The address space (namespace :data:`NAMESPACE`, string node ids, so that a PLC can name them)::

    Objects/Opportune                         ns=N;s=Opportune        (every run's RunChangedEventType events)
      UploadPlan(PlanText) -> PlanId
      StartRun(Plan, Policy, BufferCapacity, Label, RequestId) -> RunId
      Look(RunId, Visible[], RequestId) -> Action, Part, Source, Seq, Explanation, Answer, Replayed
      ReportOutcome(RunId, Outcome, Keep, RequestId) -> Status, Seq, Answer, Replayed
      Cancel(RunId, RequestId) -> Seq, Answer, Replayed
      Cells/<cell>                            (its runs' RunChangedEventType events)
      Cells/<cell>/ActiveRuns                 the cell's active run ids
      Cells/<cell>/LastRefusal                why the cell's last refused call was refused
      Runs/<id>/State, StateNumber, Seq, Cell, Plan, PlanId, Policy, PendingAction, Installed, Buffered,
                AdmissibleCount, AdmissibleCountLog10, Explanation

``State`` names a PackML state (ISA-TR88): ``Idle`` (started, nothing looked at yet), ``Execute``
(deciding and acting), ``Held`` (the pending action is a shake: waiting on the bin), ``Complete``,
``Aborted`` (a run this version cannot resume); ``StateNumber`` is PackML's number of that state.
``AdmissibleCount`` is the exact count as decimal text (it overflows every OPC UA number) and
``AdmissibleCountLog10`` its logarithm.

A refused call answers a Bad status code (``BadInvalidArgument`` for a look that contradicts the
run, ``BadInvalidState`` for a call out of turn, ``BadNotFound``, ``BadUserAccessDenied``, ...)
and changes nothing; the service's message and hint are in the diagnostic information of the
argument at fault (``InputArgumentDiagnosticInfos[i].AdditionalInfo``, and its
``InputArgumentResults[i]``; every argument's when none is at fault), and in the cell's ``LastRefusal``
(for generic clients, which show a Bad status alone).

Security: endpoints ``Basic256Sha256`` Sign & Encrypt only; the server's certificate is self-signed
and generated on first start in ``PKI/own``; a client is trusted when its certificate is in
``PKI/trusted`` (read again at every check), checked when the channel opens and again at
CreateSession and ActivateSession; a SecurityPolicy None channel serves discovery only
(:mod:`opportune.service.opcua_security`).  Users authenticate with a user name (any,
e.g. the cell's) and the service's token as password (``opportune token create``): a cell's token
drives its cell's runs, an operator's reads; a cell reads the values of its own runs only
(:class:`OwnCellOnly`).  Anonymous sessions are refused, unless the server listens on loopback only
and ``anonymous_cell`` names the cell they act as (development).  A revoked token opens no session
and calls nothing at once, and its open sessions are closed within
:data:`~opportune.service.config.REVOCATION_SECONDS`.
"""

from __future__ import annotations

import asyncio
import contextvars
import ipaddress
import json
import logging
import re
import socket
import threading
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlparse

from asyncua import ua
from asyncua.crypto.permission_rules import User, UserRole

from opportune.formats.problems import CONTROL_CHARS
from opportune.limits import MAX_BUFFER, MAX_ID, MAX_KEY, MAX_LABEL
from opportune.policies.named import FORMER_NAMES, POLICIES
from opportune.service.auth import Principal, ensure_cell
from opportune.service.core import Core
from opportune.service.errors import ApiError
from opportune.service.opcua_security import Guard, GuardedServer, GuardedSession, TrustList, make_certificate, own_files
from opportune.service.opcua_security import client_certificate, client_certificate_async  # noqa: F401 (its API)
from opportune.service.opcua_transport import BoundedServer, TransportBounds
from opportune.service.plans import accept_upload

log = logging.getLogger("opportune.service.opcua")

NAMESPACE = "urn:opportune:sequencer"
APPLICATION_URI = "urn:opportune:server"
DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840"
MAX_RUN_NODES = 1000      # runs with nodes in the address space (active ones first; the oldest go first)
MAX_VISIBLE = 100_000     # parts in one look (as over HTTP)
MAX_TEXT = max(MAX_ID, MAX_LABEL, MAX_KEY)  # characters of a part id, a label, a request id (opportune.limits)
EVENTS_AT_ONCE = 200      # committed events read at once to emit their OPC UA events
PLAN_ID = re.compile(r"^[0-9a-f]{64}$")
_CONTROL = re.compile(f"[{CONTROL_CHARS}]")
#: PackML's state numbers (ISA-TR88.00.02) of the states a run goes through.
PACKML = {"Idle": 4, "Execute": 6, "Held": 11, "Complete": 17, "Aborted": 9}
#: Who reads runs to refresh their nodes: the server itself, as an operator.
SYSTEM = Principal("opcua", "operator", None, "opcua server")

_caller: contextvars.ContextVar = contextvars.ContextVar("opportune_opcua_caller", default=None)


class OpcUaError(ValueError):
    """A setting of the OPC UA server that cannot work (bad endpoint, anonymous off loopback)."""


@dataclass(frozen=True)
class OpcUaOptions:
    """How the OPC UA server listens.

    Parameters
    ----------
    endpoint : str, default "opc.tcp://127.0.0.1:4840"
        The ``opc.tcp://HOST:PORT`` URL served.
    pki : pathlib.Path, default Path("opcua-pki")
        The certificates' folder: ``own/`` the server's key and certificate, generated on first
        start; ``trusted/`` the clients' certificates.
    anonymous_cell : str, optional
        The cell anonymous sessions act as (``None``: anonymous sessions are refused; loopback
        endpoints only).
    max_run_nodes : int, default MAX_RUN_NODES
        Runs with nodes in the address space (active ones first; the oldest go first).
    transport : TransportBounds, optional
        Sizes, counts and times allowed before login (:mod:`opportune.service.opcua_transport`).

    Examples
    --------
    >>> OpcUaOptions(endpoint="opc.tcp://0.0.0.0:4841").checked()
    ('0.0.0.0', 4841)
    """

    endpoint: str = DEFAULT_ENDPOINT
    pki: Path = Path("opcua-pki")
    anonymous_cell: str | None = None
    max_run_nodes: int = MAX_RUN_NODES
    transport: TransportBounds = TransportBounds()   # sizes, counts and times before login (opcua_transport)

    def checked(self) -> tuple[str, int]:
        """The endpoint's host and port, checked before the server starts.

        Returns
        -------
        tuple of (str, int)
            The host and the port (4840 when the URL gives none).

        Raises
        ------
        OpcUaError
            Saying what to fix: not an ``opc.tcp://HOST:PORT`` URL, a bad port, or anonymous sessions on
            an endpoint that is not loopback.

        Examples
        --------
        >>> OpcUaOptions().checked()
        ('127.0.0.1', 4840)
        >>> OpcUaOptions(endpoint="http://cell").checked()
        Traceback (most recent call last):
            ...
        opportune.service.opcua.OpcUaError: the OPC UA endpoint 'http://cell' is not an opc.tcp://HOST:PORT URL: give e.g. opc.tcp://127.0.0.1:4840
        """
        url = urlparse(self.endpoint)
        if url.scheme != "opc.tcp" or not url.hostname:
            raise OpcUaError(f"the OPC UA endpoint {self.endpoint!r} is not an opc.tcp://HOST:PORT URL: "
                             f"give e.g. {DEFAULT_ENDPOINT}")
        try:
            port = url.port if url.port is not None else 4840
        except ValueError:
            raise OpcUaError(f"the OPC UA endpoint {self.endpoint!r} has a bad port: use 1-65535") from None
        if self.anonymous_cell is not None and not loopback(url.hostname):
            raise OpcUaError(f"anonymous OPC UA sessions are for development on loopback only, and "
                             f"{url.hostname!r} is not a loopback address: serve on 127.0.0.1 or drop the "
                             "anonymous cell")
        return url.hostname, port


def message_limit(max_body: int) -> int:
    """Bytes an OPC UA message may have: room for a plan of ``max_body`` bytes (``--max-body``) or a look of
    :data:`MAX_VISIBLE` parts, and for their answers, with the protocol's overhead."""
    return 4 * max_body + (1 << 20)


def loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


# ---------------------------------------------------------------- who calls

@dataclass
class Caller(User):
    """An OPC UA session's user: the service principal its token maps to."""

    principal: Principal | None = None


class Users:
    """User names and passwords: the password is a service token; anonymous sessions act as ``anonymous_cell``."""

    def __init__(self, core: Core, anonymous_cell: str | None):
        self.core = core
        self.anonymous_cell = anonymous_cell

    def get_user(self, iserver, username=None, password=None, certificate=None) -> User | None:
        if password is None:
            if self.anonymous_cell is None:
                return None
            return Caller(role=UserRole.User, name=f"anonymous@{self.anonymous_cell}",
                          principal=Principal("anonymous", "cell", self.anonymous_cell, "anonymous"))
        token = password.decode("utf-8", "replace") if isinstance(password, bytes) else str(password)
        principal = self.core.auth.token(token, fresh=True)     # a revoked token: refused at once
        if principal is None:
            return None
        return Caller(role=UserRole.User, name=principal.cell or principal.label, principal=principal)


class _Session(GuardedSession):
    """A session that makes its user known to the method calls it makes (asyncua passes them only the object)."""

    async def call(self, params):
        mark = _caller.set(self.user)
        try:
            return await super().call(params)
        finally:
            _caller.reset(mark)


class OwnCellOnly:
    """What a cell's session may read: the values of its own cell's runs only, as over HTTP (where another
    cell's run is not found).  Browsing shows every node (its attributes but its value); reading the value of
    another cell's run variable, or subscribing to it, to another cell's events or to every cell's events
    on ``Objects/Opportune``, is refused with ``BadUserAccessDenied``.  Operators read everything.

    Checked on each Read and CreateMonitoredItems request before it is served: O(nodes in the request)."""

    def __init__(self, front: "OpcUaFront"):
        from asyncua.crypto.permission_rules import SimpleRoleRuleset
        from asyncua.ua.ua_binary import struct_from_binary

        self.front = front
        self.roles = SimpleRoleRuleset()     # asyncua's own: no address-space changes by users
        read = ua.NodeId(ua.ObjectIds.ReadRequest_Encoding_DefaultBinary)
        monitor = ua.NodeId(ua.ObjectIds.CreateMonitoredItemsRequest_Encoding_DefaultBinary)
        self.decoders = {
            read: lambda body: [(r.NodeId, r.AttributeId)
                                for r in struct_from_binary(ua.ReadParameters, body).NodesToRead],
            monitor: lambda body: [(i.ItemToMonitor.NodeId, None) for i in
                                   struct_from_binary(ua.CreateMonitoredItemsParameters, body).ItemsToCreate]}

    def check_validity(self, user, action_type_id, body) -> bool:
        if not self.roles.check_validity(user, action_type_id, body):
            return False
        principal = getattr(user, "principal", None)
        decode = self.decoders.get(action_type_id)
        if decode is None or principal is None or principal.is_operator:
            return True
        try:
            wanted = decode(body.copy())
        except Exception:   # not decodable: the server's own decoding refuses it
            return True
        return all(self.front.may_read(principal, nid, attribute) for nid, attribute in wanted)


# ---------------------------------------------------------------- refusals

def status_of(err: ApiError) -> int:
    """The OPC UA status code of a refusal of the service.

    Parameters
    ----------
    err : ApiError
        The service's refusal (its HTTP status and code).

    Returns
    -------
    int
        ``BadUserAccessDenied`` (401, 403), ``BadNotFound`` (404), ``BadInvalidState`` (a run's state
        refuses it), ``BadResourceUnavailable`` (busy, 503), ``BadRequestTooLarge`` (413),
        ``BadInternalError`` (5xx), else ``BadInvalidArgument``.

    Examples
    --------
    >>> from asyncua import ua
    >>> status_of(ApiError(409, "action_pending", "an action is pending")) == ua.StatusCodes.BadInvalidState
    True
    """
    codes = ua.StatusCodes
    if err.status in (401, 403):
        return codes.BadUserAccessDenied
    if err.status == 404:
        return codes.BadNotFound
    if err.code in ("action_pending", "no_pending_action", "run_complete", "outcome_refused"):
        return codes.BadInvalidState
    if err.code == "run_busy" or err.status == 503:
        return codes.BadResourceUnavailable
    if err.status == 413:
        return codes.BadRequestTooLarge
    if err.status >= 500:
        return codes.BadInternalError
    return codes.BadInvalidArgument


def _field(where: str | None) -> str:
    """The request field an error names (``body.visible[1]`` → ``visible``)."""
    where = where or ""
    if where.startswith("header Idempotency-Key"):
        return "request_id"
    if where == "path":
        return "run_id"
    return re.split(r"[.\[]", where.removeprefix("body."), maxsplit=1)[0]


def said(err: ApiError) -> str:
    """A refusal as one line: its code, message and hint (what to do)."""
    return f"{err.code}: {err.message}" + (f" ({err.hint})" if err.hint else "")


def refusal(err: ApiError, names: list[str], fields: dict[str, str]) -> ua.CallMethodResult:
    """A Bad call result: the status, and the message and hint on the argument at fault (else on each)."""
    status = ua.StatusCode(status_of(err))
    text = said(err)
    at = fields.get(_field(err.where))
    if at not in names:     # a field this method has no argument for: every argument carries the message
        at = None
    res = ua.CallMethodResult(StatusCode=status)
    res.InputArgumentResults = [status if at in (None, n) else ua.StatusCode() for n in names]
    res.InputArgumentDiagnosticInfos = [ua.DiagnosticInfo(AdditionalInfo=text) if at in (None, n) else ua.DiagnosticInfo()
                                        for n in names]
    return res


def bad(message: str, hint: str, where: str) -> ApiError:
    return ApiError(422, "invalid_request", message, hint, where=where)


def _text(value, name: str, where: str, *, empty: bool = False, limit: int = MAX_TEXT) -> str:
    if value is None and empty:
        return ""
    if not isinstance(value, str) or (not value and not empty) or len(value) > limit or not value.isprintable():
        raise bad(f"{name} must be {'' if empty else '1-'}{limit} printable characters" + (" (or empty)" if empty else ""),
                  f"check the {name} argument", where)
    return value


def _request_id(value) -> str:
    if value is None or value == "":
        raise ApiError(400, "idempotency_key_required", "RequestId is empty: every call that changes a run needs one",
                       "send a fresh id (e.g. a UUID) with every new call and the same id when retrying it",
                       where="header Idempotency-Key")
    return _text(value, "RequestId", "header Idempotency-Key")


def _run_id(value) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 2 ** 62:
        raise bad("RunId must be a run's id (a positive integer)", "use the RunId StartRun answered", "path")
    return value


# ---------------------------------------------------------------- the server

def _arg(name: str, vtype: ua.VariantType, description: str, *, array: bool = False) -> ua.Argument:
    return ua.Argument(Name=name, DataType=ua.NodeId(vtype.value), ValueRank=1 if array else -1,
                       ArrayDimensions=[0] if array else [], Description=ua.LocalizedText(description))


S, I64, U32, I32, D, B = (ua.VariantType.String, ua.VariantType.Int64, ua.VariantType.UInt32, ua.VariantType.Int32,
                          ua.VariantType.Double, ua.VariantType.Boolean)
RUN_VARIABLES = (("Cell", S, False), ("Plan", S, False), ("PlanId", S, False), ("Policy", S, False),
                 ("State", S, False), ("StateNumber", I32, False), ("Seq", U32, False), ("PendingAction", S, False),
                 ("Installed", S, True), ("Buffered", S, True), ("AdmissibleCount", S, False),
                 ("AdmissibleCountLog10", D, False), ("Explanation", S, False))


def run_values(run: dict, explanation: str | None) -> dict:
    """A run's variables from its JSON view (:func:`opportune.service.views.run_view`)."""
    pending = run.get("pending")
    if run.get("status") == "complete":
        state = "Complete"
    elif pending and pending["action"]["kind"] == "shake":
        state = "Held"
    elif not run.get("seq"):
        state = "Idle"
    else:
        state = "Execute"
    count = run.get("count") or {}
    if explanation is None:
        explanation = ((pending or {}).get("reasons") or {}).get("explain", "")
    return {"Cell": run["cell"], "Plan": run["plan"]["name"], "PlanId": run["plan"]["id"], "Policy": run["policy"],
            "State": state, "StateNumber": PACKML[state], "Seq": run["seq"],
            "PendingAction": pending["action_text"] if pending else "",
            "Installed": list(run["state"]["installed"]), "Buffered": list(run["state"]["buffered"]),
            "AdmissibleCount": count.get("value") or "", "AdmissibleCountLog10": float(count.get("log10") or 0.0),
            "Explanation": explanation or ""}


async def _one_dimension(var) -> None:
    """Declare a variable an array of any length (asyncua declares a scalar by default)."""
    await var.write_value_rank(1)
    await var.write_array_dimensions([0])


def _explained(answer: dict) -> str:
    """The explanation of the decision of the row an answer added, completed or dropped."""
    row = answer.get("row") or answer.get("cancelled") or {}
    return (row.get("reasons") or {}).get("explain", "")


@dataclass
class _RunNodes:
    node: object
    variables: dict = field(default_factory=dict)
    seq: int = -1
    cell: str = ""
    active: bool = True


class _Server(GuardedServer, BoundedServer):
    """asyncua's server with both: its channels guarded (opcua_security), its connections bounded (opcua_transport)."""


class OpcUaFront:
    """The OPC UA server over a :class:`Core`; :meth:`start` and :meth:`stop` in one event loop."""

    def __init__(self, core: Core, options: OpcUaOptions):
        self.core = core
        self.options = options
        self.host, self.port = options.checked()
        self.server: BoundedServer | None = None
        self.ns = 0
        self._runs: dict[int, _RunNodes] = {}
        self._cells: dict[str, object] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._changed: asyncio.Queue | None = None
        self._refresher: asyncio.Task | None = None
        self._sweeper: asyncio.Task | None = None
        self.guard: Guard | None = None

    # ------------------------------------------------------------ setting up

    async def start(self) -> None:
        """Build the address space and listen.  Raises :class:`OpcUaError` if the port is taken."""
        self._free_port()        # before seconds of building the address space
        self._loop = asyncio.get_running_loop()
        self._changed = asyncio.Queue()
        self._refreshing = asyncio.Lock()   # one refresh at a time: each event is emitted once, in order
        pki = self.options.pki
        cert, key = own_files(pki)
        await make_certificate(key, cert, APPLICATION_URI, client=False, host=socket.gethostname())
        (pki / "trusted").mkdir(parents=True, exist_ok=True)
        if self.options.anonymous_cell is not None:   # its runs belong to a cell like any other
            await asyncio.to_thread(ensure_cell, self.core.store, self.options.anonymous_cell)
        trust = TrustList(pki / "trusted")
        self.guard = guard = Guard(trust, self.core.auth, anonymous=self.options.anonymous_cell is not None)
        # every connection read within bounds, each chunk checked from its header (opcua_transport); a message
        # bounded as HTTP bounds a body
        bounds = self.options.transport.lowered(max_message=message_limit(self.core.settings.max_body))
        server = _Server(guard, bounds=bounds, user_manager=Users(self.core, self.options.anonymous_cell))
        await server.init()
        guard.install(server.iserver, _Session)
        server.set_endpoint(f"opc.tcp://{self.host}:{self.port}")
        server.set_server_name("opportune")
        await server.set_application_uri(APPLICATION_URI)
        await server.load_certificate(str(cert))
        await server.load_private_key(str(key))
        server.set_certificate_validator(trust)
        policies = [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt]
        tokens = [ua.UserNameIdentityToken]
        if self.options.anonymous_cell is not None:   # development, on loopback: no security at all
            policies.append(ua.SecurityPolicyType.NoSecurity)
            tokens.append(ua.AnonymousIdentityToken)
        server.set_security_policy(policies, permission_ruleset=OwnCellOnly(self))
        server.set_identity_tokens(tokens)
        self.server = server
        await self._address_space()
        quiet = logging.getLogger("asyncua.server.server")
        quiet.disabled = True    # it logs a failure to listen with its traceback: the message below says it all
        try:
            await server.start()
        except OSError as exc:   # taken since the check
            raise self._taken(exc) from None
        finally:
            quiet.disabled = False
        self.core.manager.watch(self._on_change)
        self._refresher = asyncio.create_task(self._refresh_loop())
        self._sweeper = asyncio.create_task(guard.sweep_forever(self.core.auth.cache_seconds))
        for r in await asyncio.to_thread(self.core.manager.list, SYSTEM, status="active",
                                         limit=self.options.max_run_nodes):
            self._changed.put_nowait(r["id"])

    def _taken(self, exc: OSError) -> OpcUaError:
        return OpcUaError(f"cannot listen on {self.options.endpoint}: {exc.strerror or exc}: choose another "
                          "port (--opcua-endpoint opc.tcp://127.0.0.1:PORT)")

    def _free_port(self) -> None:
        """:class:`OpcUaError` now if the endpoint's port cannot be bound (another server holds it)."""
        try:
            family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
            with socket.socket(family, socket.SOCK_STREAM) as probe:
                probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)   # as asyncio's server will
                probe.bind((self.host, self.port))
        except OSError as exc:
            raise self._taken(exc) from None

    async def stop(self) -> None:
        for task in (self._refresher, self._sweeper):
            if task is not None:
                task.cancel()
        if self.server is not None:
            await self.server.stop()

    async def _address_space(self) -> None:
        server = self.server
        self.ns = ns = await server.register_namespace(NAMESPACE)
        root = await server.nodes.objects.add_object(ua.NodeId("Opportune", ns), ua.QualifiedName("Opportune", ns))
        await root.set_event_notifier([ua.EventNotifier.SubscribeToEvents])
        self.root = root
        self.cells = await root.add_folder(ua.NodeId("Cells", ns), ua.QualifiedName("Cells", ns))
        self.runs = await root.add_folder(ua.NodeId("Runs", ns), ua.QualifiedName("Runs", ns))
        etype = await server.create_custom_event_type(
            ns, "RunChangedEventType", ua.ObjectIds.BaseEventType,
            [("RunId", I64), ("Seq", U32), ("Kind", S), ("State", S), ("Cell", S)])
        self.event_type = etype
        self.events = await server.get_event_generator(etype, root)
        methods = (
            ("UploadPlan", self._upload, [_arg("PlanText", S, "A plan file's text (YAML, JSON or SALBP .IN2)")],
             [_arg("PlanId", S, "The plan's id, for StartRun")]),
            ("StartRun", self._start_run,
             [_arg("Plan", S, "A plan id (from UploadPlan or POST /plans), or a plan file's text"),
              _arg("Policy", S, f"The decision policy ({', '.join(POLICIES)}); empty: the service's default"),
              _arg("BufferCapacity", I32, "Buffer locations; -1: unlimited"),
              _arg("Label", S, "Free text shown on the dashboard (e.g. a serial number)"),
              _arg("RequestId", S, "A fresh id per new call, the same when retrying it")],
             [_arg("RunId", I64, "The new run's id")]),
            ("Look", self._look,
             [_arg("RunId", I64, "The run"), _arg("Visible", S, "Part ids seen in the bin now", array=True),
              _arg("RequestId", S, "A fresh id per new call, the same when retrying it")],
             [_arg("Action", S, "install, buffer or shake"), _arg("Part", S, "The part to install or buffer"),
              _arg("Source", S, "Where the part to install is: bin or buffer"),
              _arg("Seq", U32, "The run's event number after this call"),
              _arg("Explanation", S, "Why this action"), _arg("Answer", S, "The whole answer, as JSON (as over HTTP)"),
              _arg("Replayed", B, "True when this is the recorded answer of an earlier call with this RequestId")]),
            ("ReportOutcome", self._outcome,
             [_arg("RunId", I64, "The run"), _arg("Outcome", S, "success, failed or defective"),
              _arg("Keep", S, "After a failed install: bin or buffer (empty: bin)"),
              _arg("RequestId", S, "A fresh id per new call, the same when retrying it")],
             [_arg("Status", S, "active or complete"), _arg("Seq", U32, "The run's event number after this call"),
              _arg("Answer", S, "The whole answer, as JSON"), _arg("Replayed", B, "A recorded answer")]),
            ("Cancel", self._cancel,
             [_arg("RunId", I64, "The run"), _arg("RequestId", S, "A fresh id per new call, the same when retrying it")],
             [_arg("Seq", U32, "The run's event number after this call"), _arg("Answer", S, "The whole answer, as JSON"),
              _arg("Replayed", B, "A recorded answer")]),
        )
        for name, handler, inputs, outputs in methods:
            await root.add_method(ua.NodeId(name, ns), ua.QualifiedName(name, ns), self._method(handler, inputs, name),
                                  inputs, outputs)

    def _method(self, handler, inputs: list[ua.Argument], method: str):
        names = [a.Name for a in inputs]
        fields = {"plan": "Plan", "policy": "Policy", "buffer_capacity": "BufferCapacity", "label": "Label",
                  "request_id": "RequestId", "run_id": "RunId", "visible": "Visible", "outcome": "Outcome",
                  "keep": "Keep", "text": "PlanText"}

        async def call(_parent, *args):
            args = [a.Value if isinstance(a, ua.Variant) else a for a in args]
            try:
                caller = _caller.get()
                principal = getattr(caller, "principal", None)
                if principal is None:
                    raise ApiError(401, "unauthorized", "this session has no service identity",
                                   "connect with a user name and the service token as password")
                if principal.token_id != "anonymous" and \
                        await asyncio.to_thread(self.core.auth.by_id, principal.token_id) is None:
                    # revoked since the session began: refused from its next call on (one indexed read)
                    raise ApiError(401, "unauthorized", "this session's token has been revoked",
                                   "connect again with a valid token (opportune token create)")
                if len(args) != len(names):
                    raise bad(f"this method takes {len(names)} arguments ({', '.join(names)}), got {len(args)}",
                              "see the method's InputArguments", "body")
                outputs = await handler(principal, *args)
            except ApiError as err:
                res = refusal(err, names, fields)
                if principal is not None and principal.cell:     # where a generic client reads why
                    await self._refused(principal.cell, f"{method}: {res.StatusCode.name}: {said(err)}")
                return res
            return outputs

        return call

    # ------------------------------------------------------------ methods

    async def _upload(self, principal: Principal, text) -> list[ua.Variant]:
        return [ua.Variant(await self._plan_id(principal, text), S)]

    async def _plan_id(self, principal: Principal, text, name: str = "PlanText", where: str = "body.text") -> str:
        """Check and store a plan's text (UploadPlan's ``PlanText``, or StartRun's ``Plan``); its id."""
        if not isinstance(text, str) or not text.strip():
            raise bad(f"{name} must be a plan file's text", "send the YAML, JSON or .IN2 text", where)
        if principal.is_operator:
            raise ApiError(403, "forbidden", "an operator token reads plans and runs; only a cell's token can "
                           "upload a plan", "use the token of the cell that will assemble it")
        if _CONTROL.search(text):     # as over HTTP: no NUL or escape reaches the store or the logs
            raise bad(f"{name} holds a control character (such as U+0000 or ESC) at character "
                      f"{_CONTROL.search(text).start() + 1}", "send the plan file's text as it is", where)
        raw = text.encode("utf-8", "surrogatepass")
        if len(raw) > self.core.settings.max_body:
            raise ApiError(413, "body_too_large", f"the plan is larger than the limit of {self.core.settings.max_body} "
                           "bytes", "send a smaller plan; the limit is set with `opportune serve --max-body`",
                           where=where)
        _status, answer = await asyncio.to_thread(accept_upload, self.core.store, self.core.book, principal, raw, None)
        return answer["id"]

    async def _start_run(self, principal: Principal, plan, policy, capacity, label, request_id) -> list[ua.Variant]:
        key = _request_id(request_id)
        policy = _text(policy, "Policy", "body.policy", empty=True) or None
        if policy is not None and policy not in POLICIES and policy not in FORMER_NAMES:
            raise bad(f"unknown policy {policy!r}", f"use one of {', '.join(POLICIES)}, or empty for the default",
                      "body.policy")
        if isinstance(capacity, bool) or not isinstance(capacity, int) or not (
                capacity == -1 or 0 <= capacity <= MAX_BUFFER):    # HTTP's limits; -1 stands for its null
            raise bad(f"BufferCapacity must be an integer from 0 to {MAX_BUFFER:,}, or -1 for unlimited, not "
                      f"{str(capacity)[:40]}", "e.g. 2 (buffer locations), or -1", "body.buffer_capacity")
        label = _text(label, "Label", "body.label", empty=True)
        if not isinstance(plan, str) or not plan:
            raise bad("Plan must be a plan id or a plan file's text", "use the PlanId UploadPlan answered", "body.plan")
        plan_id = plan if PLAN_ID.match(plan) else await self._plan_id(principal, plan, "Plan", "body.plan")
        # the body a POST /runs would send: the same RequestId answers the same over HTTP and OPC UA
        body = {"plan": plan_id, "cell": None, "buffer_capacity": None if capacity < 0 else capacity, "label": label,
                "policy": policy}
        _status, text, _replayed = await asyncio.to_thread(self.core.manager.create, principal, body, key, "/runs")
        run_id = json.loads(text)["id"]
        await self._refresh_now(run_id)
        return [ua.Variant(run_id, I64)]

    async def _command(self, principal: Principal, run_id: int, kind: str, path: str, request: dict, key: str):
        status, text, replayed = await asyncio.to_thread(self.core.manager.command, principal, run_id, kind, request,
                                                         key, f"/runs/{run_id}/{path}")
        await self._refresh_now(run_id)
        return json.loads(text), text, replayed

    async def _look(self, principal: Principal, run_id, visible, request_id) -> list[ua.Variant]:
        run_id, key = _run_id(run_id), _request_id(request_id)
        if visible is None:
            visible = []      # an empty array arrives as null
        if not isinstance(visible, list) or len(visible) > MAX_VISIBLE:
            raise bad(f"Visible must be an array of at most {MAX_VISIBLE:,} part ids", "e.g. [\"rl\", \"ra\"]",
                      "body.visible")
        for i, part in enumerate(visible):
            _text(part, f"Visible[{i}]", f"body.visible[{i}]")
        answer, text, replayed = await self._command(principal, run_id, "look", "looks", {"visible": visible}, key)
        action = answer["action"]
        return [ua.Variant(action["kind"], S), ua.Variant(action.get("part") or "", S),
                ua.Variant(action.get("source") or "", S), ua.Variant(answer["seq"], U32),
                ua.Variant(answer["decision"].get("explain", ""), S), ua.Variant(text, S), ua.Variant(replayed, B)]

    async def _outcome(self, principal: Principal, run_id, outcome, keep, request_id) -> list[ua.Variant]:
        run_id, key = _run_id(run_id), _request_id(request_id)
        if outcome not in ("success", "failed", "defective"):
            raise bad(f"Outcome must be success, failed or defective, not {str(outcome)[:40]!r}", "e.g. success",
                      "body.outcome")
        keep = keep or "bin"
        if keep not in ("bin", "buffer"):
            raise bad(f"Keep must be bin or buffer, not {str(keep)[:40]!r}", "empty: bin", "body.keep")
        answer, text, replayed = await self._command(principal, run_id, "outcome", "outcomes",
                                                     {"outcome": outcome, "keep": keep}, key)
        return [ua.Variant(answer["run"]["status"], S), ua.Variant(answer["seq"], U32), ua.Variant(text, S),
                ua.Variant(replayed, B)]

    async def _cancel(self, principal: Principal, run_id, request_id) -> list[ua.Variant]:
        run_id, key = _run_id(run_id), _request_id(request_id)
        answer, text, replayed = await self._command(principal, run_id, "cancel", "cancel", {}, key)
        return [ua.Variant(answer["seq"], U32), ua.Variant(text, S), ua.Variant(replayed, B)]

    def may_read(self, principal: Principal, nid: ua.NodeId, attribute: int | None) -> bool:
        """Whether a cell may read attribute ``attribute`` of node ``nid`` (None: subscribe to it)."""
        if nid.NamespaceIndex != self.ns or not isinstance(nid.Identifier, str):
            return True
        parts = nid.Identifier.split("/")
        if parts[0] == "Opportune":     # every cell's events: operators only
            return attribute is not None
        if attribute is not None and attribute != ua.AttributeIds.Value:
            return True                 # a node's name, class, type, ...: the structure is no secret
        if parts[0] == "Cells" and len(parts) >= 2:
            return parts[1] == principal.cell
        if parts[0] == "Runs" and len(parts) >= 2 and parts[1].isdigit():
            nodes = self._runs.get(int(parts[1]))
            return nodes is None or nodes.cell == principal.cell
        return True

    # ------------------------------------------------------------ keeping the runs' nodes up to date

    def _on_change(self, run_id: int) -> None:
        """From the thread that committed a change (HTTP's or this server's): queue the run for a refresh."""
        loop, queue = self._loop, self._changed
        if loop is not None and queue is not None:
            try:
                loop.call_soon_threadsafe(queue.put_nowait, run_id)
            except RuntimeError:   # the loop has stopped: the server is going down
                pass

    async def _refresh_now(self, run_id: int) -> None:
        """Before a method answers: the run's variables show what it did (a client reads its own writes)."""
        try:
            async with self._refreshing:
                await self._refresh(run_id)
        except Exception:     # the call itself is committed and answered; the queued refresh tries again
            log.exception("OPC UA: refreshing run %s failed", run_id)

    async def _refresh_loop(self) -> None:
        while True:
            run_id = await self._changed.get()
            try:
                async with self._refreshing:
                    await self._refresh(run_id)
            except asyncio.CancelledError:
                raise
            except Exception:     # a refresh that fails leaves the nodes as they were: the next change retries
                log.exception("OPC UA: refreshing run %s failed", run_id)

    async def _refresh(self, run_id: int) -> None:
        """Bring a run's nodes up to its committed events, with one event per change since the last refresh
        (read :data:`EVENTS_AT_ONCE` at a time); a run seen for the first time gets its nodes from its last
        event (one indexed read), or from its view if nothing was done in it yet."""
        nodes = self._runs.get(run_id)
        manager = self.core.manager
        if nodes is not None:
            while True:
                new = await asyncio.to_thread(manager.events_after, run_id, nodes.seq, EVENTS_AT_ONCE)
                for _seq, kind, answer in new:
                    await self._show(run_id, nodes, kind, answer["run"], run_values(answer["run"], _explained(answer)))
                if len(new) < EVENTS_AT_ONCE:
                    return
        last = await asyncio.to_thread(manager.last_event, run_id)
        if last is not None:
            _seq, kind, answer = last
            run, values = answer["run"], run_values(answer["run"], _explained(answer))
        else:   # a run nothing was done in yet: its view (which builds its sequencer)
            kind = "start"
            try:
                run = await asyncio.to_thread(manager.view, SYSTEM, run_id)
                values = run_values(run, "")
            except ApiError as err:
                if err.code != "run_replay_mismatch":
                    return
                row = await asyncio.to_thread(manager.row, SYSTEM, run_id)
                run = {"cell": row["cell"], "seq": row["seq"], "status": "active"}
                values = {"State": "Aborted", "StateNumber": PACKML["Aborted"], "Cell": row["cell"]}
        await self._show(run_id, await self._add_run(run_id, run["cell"]), kind, run, values)

    async def _show(self, run_id: int, nodes: "_RunNodes", kind: str, run: dict, values: dict) -> None:
        """Write a run's variables and emit its ``RunChangedEventType`` event."""
        for name, value in values.items():
            var, vtype = nodes.variables[name]
            await self.server.write_attribute_value(var.nodeid, ua.DataValue(ua.Variant(value, vtype)))
        first = nodes.seq < 0
        nodes.seq = run["seq"]
        active = run["status"] != "complete"
        if first or active != nodes.active:     # the cell's list of active runs changes
            nodes.active = active
            await self._cell_runs(nodes.cell)
        message = (f"run {run_id}: {kind}, {values['State']}"
                   + (f", pending {values['PendingAction']}" if values.get("PendingAction") else ""))
        for events in (self.events, self._cells[nodes.cell][1]):    # every cell's, and the run's cell's
            ev = events.event
            ev.SourceNode, ev.SourceName = nodes.node.nodeid, f"Run {run_id}"
            ev.RunId, ev.Seq, ev.Kind, ev.State, ev.Cell = run_id, nodes.seq, kind, values["State"], nodes.cell
            ev.Severity = 100
            await events.trigger(message=message)

    async def _add_run(self, run_id: int, cell: str) -> _RunNodes:
        ns = self.ns
        if len(self._runs) >= self.options.max_run_nodes:     # room: the oldest finished run first, else the oldest
            old = min((r for r, n in self._runs.items() if not n.active), default=min(self._runs))
            gone = self._runs.pop(old)
            await self.server.delete_nodes([gone.node], recursive=True)
            await self._cell_runs(gone.cell)
        obj = await self.runs.add_object(ua.NodeId(f"Runs/{run_id}", ns), ua.QualifiedName(str(run_id), ns))
        nodes = _RunNodes(obj, cell=cell)
        for name, vtype, array in RUN_VARIABLES:
            initial = [] if array else ua.get_default_value(vtype)
            var = await obj.add_variable(ua.NodeId(f"Runs/{run_id}/{name}", ns), ua.QualifiedName(name, ns),
                                         ua.Variant(initial, vtype))
            if array:
                await _one_dimension(var)
            nodes.variables[name] = (var, vtype)
        self._runs[run_id] = nodes
        return nodes

    async def _cell_runs(self, cell: str) -> None:
        """The cell's ``ActiveRuns`` variable (its node made on the cell's first run)."""
        await self._cell(cell)
        var = self._cells[cell][0]
        active = sorted(r for r, n in self._runs.items() if n.cell == cell and n.active)
        await var.write_value(ua.Variant(active, I64))

    async def _refused(self, cell: str, text: str) -> None:
        """Write a refused call's status and message to ``Cells/<cell>/LastRefusal`` (a generic client shows a
        method's Bad status only; it reads the why there)."""
        try:
            async with self._refreshing:
                await self._cell(cell)
                await self._cells[cell][2].write_value(ua.Variant(text[:2000], S))
        except Exception:     # the refusal itself is answered; its copy for generic clients is a courtesy
            log.warning("OPC UA: writing cell %s's LastRefusal failed", cell)

    async def _cell(self, cell: str) -> None:
        """The cell's object (made on its first run or refusal): its active runs, last refusal and runs' events."""
        ns = self.ns
        if cell not in self._cells:
            obj = await self.cells.add_object(ua.NodeId(f"Cells/{cell}", ns), ua.QualifiedName(cell, ns))
            await obj.set_event_notifier([ua.EventNotifier.SubscribeToEvents])
            var = await obj.add_variable(ua.NodeId(f"Cells/{cell}/ActiveRuns", ns), ua.QualifiedName("ActiveRuns", ns),
                                         ua.Variant([], I64))
            await _one_dimension(var)
            refused = await obj.add_variable(ua.NodeId(f"Cells/{cell}/LastRefusal", ns),
                                             ua.QualifiedName("LastRefusal", ns), ua.Variant("", S))
            self._cells[cell] = (var, await self.server.get_event_generator(self.event_type, obj), refused)


# ---------------------------------------------------------------- running it

class OpcUaThread:
    """The OPC UA server in a thread of its own (its own event loop), beside an HTTP server in the main thread."""

    def __init__(self, core: Core, options: OpcUaOptions):
        self.front = OpcUaFront(core, options)
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._stop: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.thread = threading.Thread(target=self._main, name="opcua", daemon=True)

    def start(self, timeout: float = 60.0) -> "OpcUaThread":
        """Start and wait until it listens; raises what stopped it from starting."""
        self.thread.start()
        if not self._ready.wait(timeout):
            raise OpcUaError(f"the OPC UA server did not start within {timeout:.0f} s")
        if self._error is not None:
            raise self._error
        return self

    def _main(self) -> None:
        asyncio.run(self._serve())

    async def _serve(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        try:
            await self.front.start()
        except BaseException as exc:  # handed to the thread that waits in start()
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        await self._stop.wait()
        await self.front.stop()

    def stop(self, timeout: float = 10.0) -> None:
        if self._loop is not None and self._stop is not None:
            try:
                self._loop.call_soon_threadsafe(self._stop.set)
            except RuntimeError:
                pass
        self.thread.join(timeout)


def serve_alone(core: Core, options: OpcUaOptions, on_ready=lambda: None) -> None:
    """Serve OPC UA only, in this thread, until SIGINT or SIGTERM."""
    import signal

    async def main():
        front = OpcUaFront(core, options)
        await front.start()
        on_ready()
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await stop.wait()
        await front.stop()

    asyncio.run(main())
