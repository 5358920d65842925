"""Who may talk to the OPC UA server: certificates, the trust list, Sign & Encrypt, and revoked tokens.

asyncua answers discovery (``GetEndpoints``, ``FindServers``) on a SecurityPolicy None channel, as
OPC UA requires, but left to itself it also lets such a channel create and activate a session with
a user name and password sent in plain text, and serves that session without a permission check;
it checks a client's certificate only at ``CreateSession``, and only the certificate the client
names there (not the one that opened the channel).  :class:`Guard` closes these doors without
touching the transport:

* every secure channel's policy is made by :class:`GuardedPolicy`, which checks the client's
  certificate against the trust list when the channel opens (``OpenSecureChannel``) and marks the
  channel; a None channel gets a policy too (discovery only, no endpoint is advertised for it);
* :class:`GuardedSession` refuses ``CreateSession`` on a None channel (unless anonymous development
  sessions are on) or an untrusted one, or when the certificate it names is not the channel's, and
  checks the trust list and the token again at ``ActivateSession``;
* :class:`ChannelRules` refuses every request but discovery on a channel that may not have a
  session, and every request of a session whose token has been revoked (checked at most every
  :data:`~opportune.service.config.REVOCATION_SECONDS`);
* :meth:`Guard.sweep` closes the sessions of revoked tokens (their subscriptions go with them),
  every :data:`~opportune.service.config.REVOCATION_SECONDS`;
* a session names its own subscriptions only (asyncua serves the subscription services by id alone).

The channel a request came on is known to the session through a context variable: asyncua serves
each connection in a task of its own, and the channel's policy is made in that task.
"""

from __future__ import annotations

import asyncio
import contextvars
import datetime as _dt
import hashlib
import logging
import re
import weakref
from dataclasses import dataclass
from pathlib import Path

from asyncua import Server, ua
from asyncua.crypto.permission_rules import User, UserRole
from asyncua.crypto.security_policies import SecurityPolicyFactory, SecurityPolicyNone
from asyncua.server.internal_session import InternalSession, SessionState
from asyncua.common.utils import ServiceError

from opportune.formats.problems import CONTROL_CHARS

log = logging.getLogger(__name__)

#: Requests a channel serves before (or without) a session: discovery, and opening and closing sessions.
DISCOVERY = frozenset(ua.NodeId(i) for i in (
    ua.ObjectIds.GetEndpointsRequest_Encoding_DefaultBinary, ua.ObjectIds.FindServersRequest_Encoding_DefaultBinary,
    ua.ObjectIds.CloseSecureChannelRequest_Encoding_DefaultBinary))

_CONTROL = re.compile(f"[{CONTROL_CHARS}]")
_channel: contextvars.ContextVar = contextvars.ContextVar("opportune_opcua_channel", default=None)


# ---------------------------------------------------------------- certificates

def own_files(pki: Path) -> tuple[Path, Path]:
    """The server's certificate (DER) and private key (PEM) in a PKI folder."""
    return pki / "own" / "cert.der", pki / "own" / "key.pem"


async def make_certificate(key: Path, cert: Path, app_uri: str, *, client: bool, host: str = "127.0.0.1") -> None:
    """A self-signed application certificate (RSA 2048, a year) for ``app_uri`` with its key, unless both
    exist and are valid for it; the key is readable by its owner only.  Making the RSA key takes a
    moment of CPU (docs/opcua.md says how long)."""
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    key.parent.mkdir(parents=True, exist_ok=True)
    cert.parent.mkdir(parents=True, exist_ok=True)
    use = [ExtendedKeyUsageOID.CLIENT_AUTH if client else ExtendedKeyUsageOID.SERVER_AUTH]
    await setup_self_signed_certificate(key, cert, app_uri, host, use, {"organizationName": "opportune"})
    key.chmod(0o600)


def _trusted_name(app_uri: str) -> str:
    return f"{re.sub(r'[^A-Za-z0-9._-]', '_', app_uri)}.der"


def client_files(folder: str | Path) -> tuple[Path, Path]:
    """A client's certificate (DER) and private key (PEM) in ``folder``."""
    folder = Path(folder)
    return folder / "cert.der", folder / "key.pem"


async def client_certificate_async(folder: str | Path, app_uri: str = "urn:opportune:client", *,
                                   trust_in: str | Path | None = None) -> tuple[Path, Path]:
    """:func:`client_certificate` for async code: the same, awaited; the key (a moment of CPU) is made in a
    thread, so the event loop goes on serving meanwhile.

    Parameters
    ----------
    folder, app_uri, trust_in
        As :func:`client_certificate`.

    Returns
    -------
    tuple of Path
        ``(certificate, key)``.

    Examples
    --------
    >>> cert, key = await client_certificate_async("cell-1-pki", trust_in="opcua-pki")   # doctest: +SKIP
    """
    cert, key = client_files(folder)
    await asyncio.to_thread(asyncio.run, make_certificate(key, cert, app_uri, client=True))
    if trust_in is not None:
        trusted = Path(trust_in) / "trusted"
        trusted.mkdir(parents=True, exist_ok=True)
        (trusted / _trusted_name(app_uri)).write_bytes(cert.read_bytes())
    return cert, key


def client_certificate(folder: str | Path, app_uri: str = "urn:opportune:client", *,
                       trust_in: str | Path | None = None) -> tuple[Path, Path]:
    """A client's self-signed certificate and key in ``folder`` (made once), copied into the server's
    trust list ``trust_in`` (a PKI folder) if given.

    Works with or without a running event loop (inside one, it is made in a thread of its own; in
    async code, :func:`client_certificate_async` does not block the loop).

    Parameters
    ----------
    folder
        Where the certificate (``cert.der``) and the key (``key.pem``, its owner's only) go.
    app_uri
        The client's application URI: the client must connect with it.
    trust_in
        A server's PKI folder (``--opcua-pki``): the certificate is copied into its ``trusted/``.

    Returns
    -------
    tuple of Path
        ``(certificate, key)``.

    Examples
    --------
    >>> cert, key = client_certificate("cell-1-pki", trust_in="opcua-pki")        # doctest: +SKIP
    """
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return asyncio.run(client_certificate_async(folder, app_uri, trust_in=trust_in))
    # inside a running loop asyncio.run cannot be called: the same in a thread of its own (its errors raised here)
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1, thread_name_prefix="opcua-certificate") as pool:
        return pool.submit(asyncio.run, client_certificate_async(folder, app_uri, trust_in=trust_in)).result()


def shown(text) -> str:
    """``text`` (a path, a URI) safe for a terminal: control characters escaped."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", str(text))


def describe(der: bytes | None) -> str:
    """A certificate as one line of a log: its subject, application URI and SHA-256 (its first 16 hex digits)."""
    if not der:
        return "no certificate"
    digest = hashlib.sha256(der).hexdigest()[:16]
    try:
        from cryptography import x509

        cert = x509.load_der_x509_certificate(der)
        uri = ""
        try:
            names = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
            uri = ", ".join(names.get_values_for_type(x509.UniformResourceIdentifier))
        except x509.ExtensionNotFound:
            pass
        subject = cert.subject.rfc4514_string()
    except Exception:  # not a certificate at all: its digest says enough
        return f"an unreadable certificate (SHA-256 {digest}...)"
    return shown(f"{subject}, URI {uri or '-'}, SHA-256 {digest}...")


class TrustList:
    """The clients' certificates in the folder ``PKI/trusted`` (DER or PEM; read again on each check, so adding or
    removing a client's certificate needs no restart).  Called by asyncua at ``CreateSession`` (its own validator:
    the certificate's URI and use); :meth:`refusal` at ``OpenSecureChannel`` and ``ActivateSession``."""

    def __init__(self, folder: Path):
        self.folder = folder

    async def __call__(self, cert, app_description) -> None:
        from asyncua.crypto.truststore import TrustStore
        from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions

        store = TrustStore([self.folder], [])
        await store.load()
        options = CertificateValidatorOptions.TRUSTED_VALIDATION | CertificateValidatorOptions.PEER_CLIENT
        await CertificateValidator(options, store).validate(cert, app_description)

    def certificates(self) -> set[bytes]:
        """The DER bytes of every certificate in the folder.  O(files in it)."""
        from cryptography import x509
        from cryptography.hazmat.primitives.serialization import Encoding

        found = set()
        for path in sorted(self.folder.glob("*")) if self.folder.is_dir() else ():
            try:
                data = path.read_bytes()
                cert = (x509.load_pem_x509_certificate(data) if data.lstrip().startswith(b"-----")
                        else x509.load_der_x509_certificate(data))
            except (OSError, ValueError):   # not a certificate: it trusts nobody
                continue
            found.add(cert.public_bytes(Encoding.DER))
        return found

    def refusal(self, der: bytes | None) -> int | None:
        """None if the certificate ``der`` is in the trust list and valid now, else the status refusing it."""
        from cryptography import x509

        if not der:
            return ua.StatusCodes.BadCertificateInvalid
        try:
            cert = x509.load_der_x509_certificate(der)
        except ValueError:
            return ua.StatusCodes.BadCertificateInvalid
        if der not in self.certificates():
            return ua.StatusCodes.BadCertificateUntrusted
        now = _dt.datetime.now(_dt.timezone.utc)
        if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
            return ua.StatusCodes.BadCertificateTimeInvalid
        return None


# ---------------------------------------------------------------- channels and sessions

@dataclass
class Channel:
    """A secure channel as the session sees it: Sign & Encrypt or not, the client's certificate, and why it was
    refused when it opened (None: trusted)."""

    secure: bool
    certificate: bytes | None = None
    refused: int | None = None


class GuardedPolicy:
    """Makes each channel's security policy (as asyncua's :class:`SecurityPolicyFactory` does), checking the
    client's certificate against the trust list as the channel opens and giving the policy the
    :class:`ChannelRules` of that channel."""

    def __init__(self, factory: SecurityPolicyFactory, guard: "Guard"):
        self.factory = factory
        self.guard = guard
        self.secure = factory.cls is not SecurityPolicyNone

    def matches(self, uri, mode=None) -> bool:
        return self.factory.matches(uri, mode)

    def create(self, peer_certificate):
        if not self.secure:     # a certificate sent on a None channel proves nothing: dropped
            policy, channel = self.factory.create(None), Channel(False)
        else:
            policy = self.factory.create(peer_certificate)
            channel = Channel(True, policy.peer_certificate, self.guard.trust.refusal(policy.peer_certificate))
            before = _channel.get()     # asyncua makes the policy twice as a channel opens: one line, not two
            if channel.refused is not None and before != channel:
                self.guard.refused("secure channel", channel.refused, channel.certificate)
        policy.permissions = ChannelRules(self.guard, channel, self.factory.permission_ruleset)
        _channel.set(channel)
        return policy


class ChannelRules:
    """The permission check asyncua asks before serving each request of a session (not discovery, nor the
    session services themselves): refused on a channel that may not have a session, for a session not
    activated, and for a token revoked (:meth:`Guard.alive`); else the front's own rules (``rules``)."""

    def __init__(self, guard: "Guard", channel: Channel, rules):
        self.guard, self.channel, self.rules = guard, channel, rules

    def check_validity(self, user, action_type_id, body) -> bool:
        if action_type_id in DISCOVERY:
            return True
        if not self.guard.may_have_session(self.channel):
            return False
        principal = getattr(user, "principal", None)
        if principal is None or not self.guard.alive(principal):
            return False
        return self.rules is None or self.rules.check_validity(user, action_type_id, body)


class GuardedSession(InternalSession):
    """A session that may only be created and activated on a trusted Sign & Encrypt channel (or, for anonymous
    development sessions, a None channel with an anonymous token), with the channel's own certificate, and
    whose token is checked afresh at ``ActivateSession``."""

    guard: "Guard"

    async def create_session(self, params, sockname=None):
        channel = _channel.get()      # one that may have a session (Guard.install's factory checked it)
        if channel.secure and params.ClientCertificate != channel.certificate:
            self.guard.refused("session", ua.StatusCodes.BadCertificateInvalid, params.ClientCertificate,
                               "not the certificate its channel was opened with")
            self.nonce = b""            # asyncua keeps the session: an ActivateSession on it is refused below
            await self.close_session()
            raise ServiceError(ua.StatusCodes.BadCertificateInvalid)
        self.channel_certificate = channel.certificate
        return await super().create_session(params, sockname)

    def activate_session(self, params, peer_certificate):
        channel = _channel.get()
        if not self.guard.may_have_session(channel):
            raise ServiceError(self.guard.session_refusal(channel))
        if channel.secure:
            refused = self.guard.trust.refusal(channel.certificate)     # the trust list, read again
            if refused is None and channel.certificate != getattr(self, "channel_certificate", None):
                refused = ua.StatusCodes.BadCertificateInvalid            # another client's session
            if refused is not None:
                self.guard.refused("session", refused, channel.certificate)
                raise ServiceError(refused)
        else:
            token = params.UserIdentityToken
            anonymous = token is None or isinstance(token, ua.AnonymousIdentityToken) or (
                isinstance(token, ua.ExtensionObject) and token.TypeId == ua.NodeId(ua.ObjectIds.Null))
            if not anonymous:   # a password on a None channel travels in plain text: never
                raise ServiceError(ua.StatusCodes.BadIdentityTokenRejected)
        result = super().activate_session(params, peer_certificate)
        self.guard.sessions.add(self)
        return result


    # asyncua serves the subscription services by subscription id alone (small sequential integers): a session
    # may name its own subscriptions only, and take over (TransferSubscriptions) those of its own token's
    # sessions only, as OPC UA requires; any other is answered as if it did not exist.

    def _own(self, ids) -> None:
        subscriptions = self.subscription_service.subscriptions
        for sid in ids or ():
            sub = subscriptions.get(sid)
            if sub is not None and sub.session_id != self.session_id:
                raise ServiceError(ua.StatusCodes.BadSubscriptionIdInvalid)

    async def create_monitored_items(self, params):
        self._own([params.SubscriptionId])
        return await super().create_monitored_items(params)

    async def modify_monitored_items(self, params):
        self._own([params.SubscriptionId])
        return await super().modify_monitored_items(params)

    async def set_monitoring_mode(self, params):
        self._own([params.SubscriptionId])
        return await super().set_monitoring_mode(params)

    async def set_publishing_mode(self, params):
        self._own(params.SubscriptionIds)
        return await super().set_publishing_mode(params)

    def republish(self, params):
        self._own([params.SubscriptionId])
        return super().republish(params)

    async def delete_subscriptions(self, ids):
        self._own(ids)
        return await super().delete_subscriptions(ids)

    async def delete_monitored_items(self, params):
        self._own([params.SubscriptionId])
        return await super().delete_monitored_items(params)

    def publish(self, acks=None):
        self._own([a.SubscriptionId for a in acks or ()])
        return super().publish(acks)

    def modify_subscription(self, params):
        self._own([params.SubscriptionId])
        return super().modify_subscription(params)

    async def transfer_subscriptions(self, params, callback):
        mine = getattr(getattr(self, "user", None), "principal", None)
        owners = {s.session_id: getattr(getattr(s, "user", None), "principal", None) for s in self.guard.sessions}
        for sid in params.SubscriptionIds or ():
            sub = self.subscription_service.subscriptions.get(sid)
            owner = owners.get(sub.session_id) if sub is not None else None
            if sub is not None and (mine is None or owner is None or owner.token_id != mine.token_id):
                raise ServiceError(ua.StatusCodes.BadSubscriptionIdInvalid)
        return await super().transfer_subscriptions(params, callback)


class Guard:
    """The checks of one OPC UA server: its trust list, whether anonymous development sessions are on (a None
    channel may then carry them), and how tokens are checked (``auth``, an
    :class:`~opportune.service.auth.Authenticator`)."""

    def __init__(self, trust: TrustList, auth, *, anonymous: bool):
        self.trust = trust
        self.auth = auth
        self.anonymous = anonymous
        self.sessions: weakref.WeakSet = weakref.WeakSet()

    def may_have_session(self, channel: Channel | None) -> bool:
        if channel is None:
            return False
        if channel.secure:
            return channel.refused is None
        return self.anonymous

    @staticmethod
    def session_refusal(channel: Channel | None) -> int:
        """The status refusing a session on a channel that may not have one (logged when the channel opened)."""
        if channel is not None and channel.secure:
            return channel.refused
        return ua.StatusCodes.BadSecurityModeRejected

    def refused(self, what: str, status: int, der: bytes | None, why: str = "") -> None:
        """One line in the log: what was refused, why, and which certificate (no traceback)."""
        name = ua.StatusCode(status).name
        log.warning("OPC UA: %s refused (%s%s): %s; add the client's certificate to the trust list "
                    "(opportune opcua cert) if it is to connect", what, name, f", {why}" if why else "", describe(der))

    def alive(self, principal) -> bool:
        """Whether a session's token is still valid (checked against the database at most every
        :data:`~opportune.service.config.REVOCATION_SECONDS`)."""
        return principal.token_id == "anonymous" or self.auth.alive(principal.token_id)

    def wrap(self, policies: list, certificate, private_key, rules) -> list:
        """The server's policy factories, each made a :class:`GuardedPolicy`, with a None one for discovery."""
        if not any(p.cls is SecurityPolicyNone for p in policies):
            policies = [*policies, SecurityPolicyFactory(SecurityPolicyNone, ua.MessageSecurityMode.None_,
                                                         certificate, private_key, permission_ruleset=rules)]
        return [GuardedPolicy(p, self) for p in policies]

    def install(self, iserver, session_class: type) -> None:
        """Make the server's sessions ``session_class`` (a :class:`GuardedSession`) guarded by this guard, and
        refuse ``RegisterServer`` (asyncua serves it without a session, on any channel: nobody registers here)."""
        cls = type("Session", (session_class,), {"guard": self})

        def create_session(name, user=User(role=UserRole.Anonymous), external=False):
            # refused before the session exists: asyncua would otherwise keep a half-made one on the connection
            channel = _channel.get()
            if external and not self.may_have_session(channel):
                raise ServiceError(self.session_refusal(channel))
            return cls(iserver, iserver.aspace, iserver.subscription_service, name, user=user, external=external)

        iserver.create_session = create_session

        def unsupported(*_args, **_kw):
            raise ServiceError(ua.StatusCodes.BadServiceUnsupported)

        iserver.register_server = iserver.register_server2 = unsupported
        logging.getLogger("asyncua.server.uaprocessor").addFilter(_SAID)     # once: a filter is added once

    async def sweep(self) -> int:
        """Close the sessions whose token has been revoked (their subscriptions are deleted: no notification
        reaches them after this); how many.  One database read for all the sessions' tokens."""
        open_ = [s for s in list(self.sessions) if s.state != SessionState.Closed
                 and getattr(getattr(s, "user", None), "principal", None) is not None]
        ids = {s.user.principal.token_id for s in open_} - {"anonymous"}
        if not ids:
            return 0
        revoked = await asyncio.to_thread(self.auth.revoked, ids)
        closed = 0
        for session in open_:
            if session.user.principal.token_id in revoked:
                await session.close_session(True)
                self.sessions.discard(session)
                closed += 1
        if closed:
            log.warning("OPC UA: closed %d session(s) of revoked tokens", closed)
        return closed

    async def sweep_forever(self, period: float) -> None:
        while True:
            await asyncio.sleep(period)
            try:
                await self.sweep()
            except asyncio.CancelledError:
                raise
            except Exception:     # a database that does not answer now: the next round tries again
                log.warning("OPC UA: checking the sessions' tokens failed; trying again in %.1f s", period)


class _Said(logging.Filter):
    """Drops asyncua's own line for a certificate refusal (:meth:`Guard.refused` has said it, with the
    certificate), and makes its "Error while processing message" one line without a traceback: a client
    can provoke it at will (a signature that does not verify, a request the processor cannot read), so a
    traceback per request would let any client fill the log.  The line keeps the exception's type and
    its message, escaped."""

    def filter(self, record: logging.LogRecord) -> bool:
        if str(record.msg).startswith("sending service fault response") and "BadCertificate" in str(record.args):
            return False
        if record.exc_info and str(record.msg).startswith("Error while processing message"):
            exc = record.exc_info[1]
            record.msg = "OPC UA: a request failed (%s: %s); answered BadInternalError"
            record.args = (type(exc).__name__, shown(str(exc))[:300])
            record.exc_info = record.exc_text = None
            record.levelno, record.levelname = logging.WARNING, "WARNING"
        return True


_SAID = _Said()


class GuardedServer(Server):
    """asyncua's server whose channels' policies are :class:`GuardedPolicy`'s of ``guard``."""

    def __init__(self, guard: Guard, **kw):
        super().__init__(**kw)
        self.guard = guard

    async def _setup_server_nodes(self) -> None:
        await super()._setup_server_nodes()
        iserver = self.iserver
        self._policies[:] = self.guard.wrap(self._policies, iserver.certificate, iserver.private_key,
                                            self._permission_ruleset)
