"""Hostile clients of the OPC UA server, after the transport: who may open a session, and what a session may do.

One server in this process (:class:`~opportune.service.opcua.OpcUaThread`) serves the whole module, with
default options (no anonymous sessions), its token check on an injected clock (so the revocation bound
is checked by moving the clock, not by waiting), and its sweep of revoked sessions forced by the test.

* A client without a certificate, on a SecurityPolicy None channel, gets discovery and nothing else:
  no session (with a user name and the cell's token as a plain-text password, or anonymous), no read,
  no browse, no call, no RegisterServer.
* A channel opened with a certificate not in the trust list gets no session either, even when the
  session it asks for names a trusted client's (public) certificate; the refusal is one line in the log.
* A revoked token: a new session is refused at once; an open session's reads are refused within the
  token cache time, and the sweep closes it (its subscriptions with it).
* Refusals say what and what to do, where a generic client sees them (``Cells/<cell>/LastRefusal``).
* A session touches its own subscriptions only, and writes nothing.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time

import pytest

pytest.importorskip("asyncua")

from asyncua import Client as UaClient  # noqa: E402
from asyncua import ua  # noqa: E402

from conftest import GEARBOX  # noqa: E402
from opportune.service.auth import create_token, revoke_token  # noqa: E402
from opportune.limits import MAX_BUFFER as MAX_BUFFER_CAPACITY  # noqa: E402
from opportune.service.config import Settings  # noqa: E402
from opportune.service.core import build  # noqa: E402
from opportune.service.opcua import OpcUaOptions, OpcUaThread  # noqa: E402
from opportune.service.opcua_client import CellClient, Refused  # noqa: E402
from opportune.service.opcua_security import client_certificate, client_certificate_async  # noqa: E402
from opportune.service.testing import free_port  # noqa: E402

APP = "urn:opportune:hostile-test"
STRANGER = "urn:opportune:stranger"


class Clock:
    """Monotonic seconds that move only when the test says so."""

    def __init__(self):
        self.now = time.monotonic()

    def __call__(self) -> float:
        return self.now


class Server:
    def __init__(self, tmp):
        self.pki = tmp / "pki"
        self.cert = client_certificate(tmp / "client", APP, trust_in=self.pki)
        self.stranger = client_certificate(tmp / "stranger", STRANGER)        # not in the trust list
        # a cache time that the background sweep never reaches during the tests: the test moves the clock
        self.core = build(Settings(db_url=f"sqlite:///{tmp / 'h.db'}", token_cache_seconds=3600.0))
        self.clock = self.core.auth.clock = Clock()
        self.endpoint = f"opc.tcp://127.0.0.1:{free_port()}"
        self.thread = OpcUaThread(self.core, OpcUaOptions(endpoint=self.endpoint, pki=self.pki)).start()
        self.front = self.thread.front

    def token(self, cell="cell-1") -> tuple[str, str]:
        return create_token(self.core.store, cell=cell)

    def cell(self, token, cert=None, app=APP) -> CellClient:
        cert, key = cert or self.cert
        return CellClient(self.endpoint, token, certificate=cert, private_key=key, app_uri=app, user="cell-1")

    def on_server(self, coroutine):
        """Run a coroutine in the server's event loop; its result."""
        return asyncio.run_coroutine_threadsafe(coroutine, self.thread._loop).result(30)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    s = Server(tmp_path_factory.mktemp("opcua-hostile"))
    yield s
    s.thread.stop()
    s.core.close()


@pytest.fixture(scope="module")
def run_of_cell_1(server):
    """A run of cell-1's, started over OPC UA: ``(token, run id)``."""
    _, token = server.token()

    async def start():
        async with server.cell(token) as c:
            return await c.start_run(GEARBOX.read_text(), policy="paper")

    return token, asyncio.run(start())


# ---------------------------------------------------------------- no security: discovery only

async def none_channel(endpoint: str) -> UaClient:
    """A client on a SecurityPolicy None channel, no certificate, no session yet."""
    client = UaClient(endpoint, timeout=5)
    await client.connect_socket()
    await client.send_hello()
    await client.open_secure_channel()
    return client


def session_parameters(endpoint: str, certificate: bytes | None = None) -> ua.CreateSessionParameters:
    params = ua.CreateSessionParameters()
    params.ClientDescription = ua.ApplicationDescription(ApplicationUri=APP, ApplicationType=ua.ApplicationType.Client)
    params.EndpointUrl = endpoint
    params.SessionName = "hostile"
    params.ClientNonce = b"n" * 32
    params.ClientCertificate = certificate
    params.RequestedSessionTimeout = 60_000
    return params


def user_name(token: str) -> ua.ActivateSessionParameters:
    params = ua.ActivateSessionParameters()
    params.UserIdentityToken = ua.UserNameIdentityToken(PolicyId="username", UserName="cell-1",
                                                        Password=token.encode(), EncryptionAlgorithm=None)
    return params


def test_a_client_without_a_certificate_gets_discovery_and_nothing_else(server, run_of_cell_1):
    token, run = run_of_cell_1
    ns = server.front.ns
    state = ua.NodeId(f"Runs/{run}/State", ns)

    async def probe():
        client = await none_channel(server.endpoint)
        try:
            # discovery is served, and names Sign & Encrypt endpoints only
            endpoints = await client.get_endpoints()
            assert endpoints and {(e.SecurityPolicyUri.rsplit("#")[-1], e.SecurityMode) for e in endpoints} == \
                {("Basic256Sha256", ua.MessageSecurityMode.SignAndEncrypt)}
            with pytest.raises(ua.UaStatusCodeError) as refused:
                await client.uaclient.create_session(session_parameters(server.endpoint))
            assert refused.value.code == ua.StatusCodes.BadSecurityModeRejected
            with pytest.raises(ua.UaStatusCodeError) as refused:       # activating without a session
                await client.uaclient.activate_session(user_name(token))
            assert refused.value.code == ua.StatusCodes.BadSessionIdInvalid
            # nothing of the address space: reading the run's variable, browsing, calling
            read = ua.ReadParameters(NodesToRead=[ua.ReadValueId(NodeId=state, AttributeId=ua.AttributeIds.Value)])
            browse = ua.BrowseParameters(NodesToBrowse=[ua.BrowseDescription(
                NodeId=ua.NodeId("Runs", ns), BrowseDirection=ua.BrowseDirection.Forward, IncludeSubtypes=True,
                ResultMask=63)])
            call = [ua.CallMethodRequest(ObjectId=ua.NodeId("Opportune", ns), MethodId=ua.NodeId("Cancel", ns),
                                         InputArguments=[ua.Variant(run, ua.VariantType.Int64),
                                                         ua.Variant("x", ua.VariantType.String)])]
            for request in (client.uaclient.read(read), client.uaclient.browse(browse), client.uaclient.call(call)):
                with pytest.raises(ua.UaStatusCodeError) as refused:
                    await request
                assert refused.value.code == ua.StatusCodes.BadUserAccessDenied
            # nor may anyone register a server with this one (asyncua serves it without a session)
            with pytest.raises(ua.UaStatusCodeError) as refused:
                await client.uaclient.register_server(ua.RegisteredServer(ServerUri="urn:evil", IsOnline=True))
            assert refused.value.code == ua.StatusCodes.BadServiceUnsupported
        finally:
            client.disconnect_socket()

    asyncio.run(probe())


def test_a_session_on_a_none_channel_is_refused_even_where_anonymous_sessions_are_on(tmp_path):
    """With ``--opcua-anonymous`` (development, loopback), a None channel may carry anonymous sessions only: a
    password would travel in plain text, so a user-name token is refused at ActivateSession."""
    core = build(Settings(db_url=f"sqlite:///{tmp_path / 'a.db'}"))
    _, token = create_token(core.store, cell="cell-1")
    endpoint = f"opc.tcp://127.0.0.1:{free_port()}"
    thread = OpcUaThread(core, OpcUaOptions(endpoint=endpoint, pki=tmp_path / "pki", anonymous_cell="dev")).start()

    async def probe():
        client = await none_channel(endpoint)
        try:
            await client.uaclient.create_session(session_parameters(endpoint))
            with pytest.raises(ua.UaStatusCodeError) as refused:
                await client.uaclient.activate_session(user_name(token))
            assert refused.value.code == ua.StatusCodes.BadIdentityTokenRejected
            read = ua.ReadParameters(NodesToRead=[ua.ReadValueId(NodeId=ua.NodeId("Opportune", 2),
                                                                 AttributeId=ua.AttributeIds.BrowseName)])
            with pytest.raises(ua.UaStatusCodeError) as refused:     # the session is not activated: nothing
                await client.uaclient.read(read)
            assert refused.value.code == ua.StatusCodes.BadUserAccessDenied
        finally:
            client.disconnect_socket()
        async with CellClient(endpoint, None) as dev:      # what the option is for: anonymous, as cell dev
            run = await dev.start_run(GEARBOX.read_text(), policy="paper")
            assert await dev.read(run, "Cell") == "dev"

    try:
        asyncio.run(probe())
    finally:
        thread.stop()
        core.close()


# ---------------------------------------------------------------- the trust list

def test_an_untrusted_certificate_gets_no_session_and_one_line_in_the_log(server, caplog):
    _, token = server.token()
    trusted_der = server.cert[0].read_bytes()

    async def probe():
        # an untrusted client, as any client does it
        with pytest.raises(ua.UaStatusCodeError) as refused:
            await server.cell(token, server.stranger, STRANGER).connect()
        assert refused.value.code == ua.StatusCodes.BadCertificateUntrusted
        # the same channel, asking for a session in the name of the trusted client (its certificate is public)
        client = UaClient(server.endpoint, timeout=5)
        client.application_uri = STRANGER
        await client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{server.stranger[0]},{server.stranger[1]}")
        await client.connect_socket()
        try:
            await client.send_hello()
            await client.open_secure_channel()
            with pytest.raises(ua.UaStatusCodeError) as refused:
                await client.uaclient.create_session(session_parameters(server.endpoint, trusted_der))
            assert refused.value.code == ua.StatusCodes.BadCertificateUntrusted
        finally:
            client.disconnect_socket()

    with caplog.at_level(logging.INFO):
        asyncio.run(probe())
    ours = [r for r in caplog.records if r.name == "opportune.service.opcua_security" and r.levelno >= logging.WARNING]
    assert any("BadCertificateUntrusted" in r.getMessage() and "urn:opportune:stranger" in r.getMessage()
               for r in ours), [r.getMessage() for r in ours]
    served = [r for r in caplog.records if r.name.startswith(("asyncua.server", "opportune"))]
    assert all(r.exc_info is None and "\n" not in r.getMessage() for r in served), \
        [r.getMessage() for r in served if r.exc_info]
    assert len(ours) == 2, [r.getMessage() for r in ours]     # one line per refused channel
    assert not [r for r in served if "BadCertificate" in r.getMessage() and r not in ours]   # and no other


def test_a_session_must_name_the_certificate_of_its_channel(server, tmp_path):
    """Two trusted clients: one's channel cannot carry a session in the other's name."""
    other = client_certificate(tmp_path / "other", "urn:opportune:other", trust_in=server.pki)
    _, token = server.token()

    async def probe():
        client = UaClient(server.endpoint, timeout=5)
        client.application_uri = APP
        await client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{server.cert[0]},{server.cert[1]}")
        await client.connect_socket()
        try:
            await client.send_hello()
            await client.open_secure_channel()
            with pytest.raises(ua.UaStatusCodeError) as refused:
                await client.uaclient.create_session(session_parameters(server.endpoint, other[0].read_bytes()))
            assert refused.value.code == ua.StatusCodes.BadCertificateInvalid
        finally:
            client.disconnect_socket()
        async with server.cell(token, other, "urn:opportune:other") as c:   # its own channel: served
            assert await c.upload_plan(GEARBOX.read_text())

    asyncio.run(probe())


# ---------------------------------------------------------------- revocation

class Notifications:
    def __init__(self):
        self.got = []

    def datachange_notification(self, node, value, data):
        self.got.append(value)


def test_a_revoked_token_loses_new_sessions_at_once_and_open_ones_within_the_bound(server):
    token_id, token = server.token()
    subscriptions = server.front.server.iserver.subscription_service.subscriptions

    async def probe():
        async with server.cell(token) as c:
            run = await c.start_run(GEARBOX.read_text(), policy="paper")
            sub = await c.client.create_subscription(20, Notifications())
            await sub.subscribe_data_change(c.client.get_node(c.node_id(f"Runs/{run}/Seq")))
            revoke_token(server.core.store, token_id)
            # a method call asks the database: refused at once
            with pytest.raises(Refused) as refused:
                await c.look(run, ["rl", "ra"])
            assert refused.value.name == "BadUserAccessDenied" and "revoked" in refused.value.message
            # a new session: refused at ActivateSession at once (the clock has not moved)
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                await server.cell(token).connect()
            # the open session's reads: served from the token cache until it expires (the bound), then refused
            assert await c.read(run, "State") == "Idle"
            server.clock.now += server.core.auth.cache_seconds
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                await c.read(run, "State")
            # the sweep (every cache_seconds) closes the session, and its subscription with it
            assert sub.subscription_id in subscriptions
            assert await asyncio.wrap_future(asyncio.run_coroutine_threadsafe(server.front.guard.sweep(),
                                                                              server.thread._loop)) == 1
            assert sub.subscription_id not in subscriptions

    asyncio.run(probe())


# ---------------------------------------------------------------- refusals a generic client can read

def test_start_run_checks_as_http_does_and_says_why_where_a_generic_client_reads(server):
    from opportune.service.bodies import RunIn

    _, token = server.token()
    # HTTP's limits: the same constant, refused below 0 and above it
    for capacity in (-5, MAX_BUFFER_CAPACITY + 1):
        with pytest.raises(ValueError):
            RunIn.model_validate({"plan": "0" * 64, "buffer_capacity": capacity})

    async def probe():
        async with server.cell(token) as c:
            refusal = c.client.get_node(c.node_id("Cells/cell-1/LastRefusal"))
            for capacity in (-5, -2, MAX_BUFFER_CAPACITY + 1):
                with pytest.raises(Refused) as refused:
                    await c.start_run(GEARBOX.read_text(), buffer_capacity=capacity)
                assert refused.value.name == "BadInvalidArgument"
                assert f"from 0 to {MAX_BUFFER_CAPACITY:,}, or -1 for unlimited" in refused.value.message
                said = await refusal.read_value()
                assert said.startswith("StartRun: BadInvalidArgument: invalid_request: BufferCapacity") and \
                    "(e.g. 2" in said, said
            assert await c.start_run(GEARBOX.read_text(), buffer_capacity=MAX_BUFFER_CAPACITY)
            run = await c.start_run(GEARBOX.read_text(), buffer_capacity=-1)
            assert await c.read(run, "State") == "Idle"
            # control characters in a plan's text: the same message whichever method carries it
            for char in ("\x00", "\x1b", "\x7f", "\x85"):
                text = GEARBOX.read_text().replace("gearbox", f"gear{char}box", 1)
                messages = []
                for call in (c.upload_plan(text), c.start_run(text)):
                    with pytest.raises(Refused) as refused:
                        await call
                    assert refused.value.name == "BadInvalidArgument"
                    messages.append(refused.value.message.split(" holds ", 1)[1])
                    assert "control character" in refused.value.message and "send the plan" in refused.value.message
                    assert (await refusal.read_value()).endswith(refused.value.message)
                assert messages[0] == messages[1], messages
            # every argument of a refused call carries the message when no one argument is at fault
            request = ua.CallMethodRequest(ObjectId=c.node_id("Opportune"), MethodId=c.node_id("StartRun"),
                                           InputArguments=[ua.Variant("x", ua.VariantType.String)])
            result = (await c.client.uaclient.call([request]))[0]
            assert result.StatusCode.name == "BadInvalidArgument"
            assert all("takes 5 arguments" in d.AdditionalInfo for d in result.InputArgumentDiagnosticInfos)

    asyncio.run(probe())


def test_an_empty_look_of_any_type_is_an_empty_look(server):
    """asyncua's client cannot send an untyped empty array (it cannot guess its type: ``Variant([],
    VariantType.String)``); a generic client's empty array of another type, or a null, is an empty look."""
    _, token = server.token()
    with pytest.raises(ua.UaError):
        ua.Variant([])

    async def probe():
        async with server.cell(token) as c:
            run = await c.start_run(GEARBOX.read_text(), policy="paper")
            for k, empty in enumerate((ua.Variant([], ua.VariantType.String), ua.Variant(None),
                                       ua.Variant([], ua.VariantType.Int32), ua.Variant([], ua.VariantType.Variant))):
                out = await c.call("Look", ua.Variant(run, ua.VariantType.Int64), empty,
                                   ua.Variant(f"empty-{k}", ua.VariantType.String))
                assert out[0] == "shake", out
                await c.outcome(run, "success")
            with pytest.raises(Refused) as refused:      # a look of numbers is no look
                await c.call("Look", ua.Variant(run, ua.VariantType.Int64), ua.Variant([1], ua.VariantType.Int32),
                             ua.Variant("numbers", ua.VariantType.String))
            assert "Visible[0] must be" in refused.value.message

    asyncio.run(probe())


# ---------------------------------------------------------------- certificates for clients

def test_client_certificate_works_inside_a_running_event_loop(tmp_path):
    async def inside():
        made = client_certificate(tmp_path / "sync", "urn:x:sync")            # blocks, but works
        awaited = await client_certificate_async(tmp_path / "async", "urn:x:async", trust_in=tmp_path / "pki")
        return made, awaited

    (cert, key), (cert2, _key2) = asyncio.run(inside())
    assert cert.read_bytes() and key.stat().st_mode & 0o777 == 0o600
    assert (tmp_path / "pki" / "trusted" / "urn_x_async.der").read_bytes() == cert2.read_bytes()


def test_opportune_opcua_cert_makes_a_certificate_a_generic_client_connects_with(server, tmp_path):
    from typer.testing import CliRunner

    from opportune.cli import app

    folder = tmp_path / "uaexpert"
    r = CliRunner().invoke(app, ["opcua", "cert", str(folder), "--app-uri", "urn:example:uaexpert"])
    assert r.exit_code == 0, r.output
    cert, key = folder / "cert.der", folder / "key.pem"
    assert f"wrote {cert}" in r.output and f"wrote {key}" in r.output
    assert "urn:example:uaexpert" in r.output and "trusted/" in r.output and "copy" in r.output
    _, token = server.token()

    async def connect():
        async with server.cell(token, (cert, key), "urn:example:uaexpert") as c:
            return await c.upload_plan(GEARBOX.read_text())

    with pytest.raises(ua.uaerrors.BadCertificateUntrusted):    # not trusted yet
        asyncio.run(connect())
    r = CliRunner().invoke(app, ["opcua", "cert", str(folder), "--app-uri", "urn:example:uaexpert",
                                 "--trust-in", str(server.pki)])
    assert r.exit_code == 0 and "kept" in r.output and "trusted" in r.output, r.output
    assert asyncio.run(connect())                               # trusted now, without a restart
    r = CliRunner().invoke(app, ["opcua", "cert", str(folder), "--app-uri", "urn:example:uaexpert", "--json"])
    doc = json.loads(r.stdout)
    assert doc == {"certificate": str(cert), "key": str(key), "made": False, "app_uri": "urn:example:uaexpert",
                   "trusted": None}, r.output
    r = CliRunner().invoke(app, ["opcua", "cert", str(tmp_path / "bad"), "--app-uri", "no uri\x1b[2J"])
    assert r.exit_code == 1 and "\x1b" not in r.output and "not a URI" in r.output, r.output


# ---------------------------------------------------------------- another session's subscriptions

def test_a_session_cannot_touch_another_sessions_subscriptions(server):
    """asyncua serves the subscription services by subscription id alone, and ids are small sequential
    integers: another cell's session could take over (TransferSubscriptions), delete, watch through or
    silence a subscription.  Every such request naming a subscription of another session is refused."""
    _, mine = server.token()
    _, theirs = server.token("cell-2")
    subscriptions = server.front.server.iserver.subscription_service.subscriptions

    async def probe():
        async with server.cell(mine) as a, server.cell(theirs) as b:
            run = await a.start_run(GEARBOX.read_text(), policy="paper")
            sub = await a.client.create_subscription(20, Notifications())
            await sub.subscribe_data_change(a.client.get_node(a.node_id(f"Runs/{run}/Seq")))
            sid = sub.subscription_id
            owner = subscriptions[sid].session_id
            clock = ua.ReadValueId(NodeId=ua.NodeId(ua.ObjectIds.Server_ServerStatus_CurrentTime),
                                   AttributeId=ua.AttributeIds.Value)
            item = ua.MonitoredItemCreateRequest(ItemToMonitor=clock, MonitoringMode=ua.MonitoringMode.Reporting,
                                                 RequestedParameters=ua.MonitoringParameters(ClientHandle=7))
            uac = b.client.uaclient
            for name, attempt in (
                    ("transfer", uac.transfer_subscriptions(ua.TransferSubscriptionsParameters(SubscriptionIds=[sid]))),
                    ("delete", uac.delete_subscriptions([sid])),
                    ("add an item", uac.create_monitored_items(ua.CreateMonitoredItemsParameters(
                        SubscriptionId=sid, ItemsToCreate=[item]))),
                    ("delete an item", uac.delete_monitored_items(ua.DeleteMonitoredItemsParameters(
                        SubscriptionId=sid, MonitoredItemIds=[1]))),
                    ("silence", uac.set_publishing_mode(ua.SetPublishingModeParameters(
                        PublishingEnabled=False, SubscriptionIds=[sid])))):
                with pytest.raises(ua.UaStatusCodeError) as refused:
                    await attempt
                assert refused.value.code == ua.StatusCodes.BadSubscriptionIdInvalid, name
            assert sid in subscriptions and subscriptions[sid].session_id == owner
            await sub.delete()                     # its own session may
            assert sid not in subscriptions
            # nor may a session write what the server shows (a run's state is the service's, not the client's)
            for session in (a, b):
                with pytest.raises(ua.UaStatusCodeError) as refused:
                    await session.client.get_node(session.node_id(f"Runs/{run}/State")).write_value(
                        ua.DataValue(ua.Variant("Complete", ua.VariantType.String)))
                assert refused.value.code in (ua.StatusCodes.BadUserAccessDenied, ua.StatusCodes.BadNotWritable)
            assert await a.read(run, "State") == "Idle"

    asyncio.run(probe())


# ---------------------------------------------------------------- the log: one line a failed request

def test_a_request_that_fails_in_asyncuas_processor_is_one_line_in_the_log():
    """asyncua logs any exception of a request with its traceback ("Error while processing message"),
    e.g. a client signature that does not verify at ActivateSession: a client could fill the log at will.
    Through the server's filter it is one escaped line with the exception's type, at WARNING."""
    import io
    import logging

    from cryptography.exceptions import InvalidSignature

    from opportune.service import opcua_security

    logger = logging.getLogger("asyncua.server.uaprocessor")
    logger.addFilter(opcua_security._SAID)
    out = io.StringIO()
    handler = logging.StreamHandler(out)
    handler.setFormatter(logging.Formatter("%(levelname)s %(message)s"))
    logger.addHandler(handler)
    try:
        for exc in (InvalidSignature(), ValueError("bad \x1b[2J thing")):
            try:
                raise exc
            except Exception:
                logger.exception("Error while processing message")
    finally:
        logger.removeHandler(handler)
    lines = out.getvalue().splitlines()
    assert lines == ["WARNING OPC UA: a request failed (InvalidSignature: ); answered BadInternalError",
                     "WARNING OPC UA: a request failed (ValueError: bad \\x1b[2J thing); answered BadInternalError"]
    assert "Traceback" not in out.getvalue() and "\x1b" not in out.getvalue()
