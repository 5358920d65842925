"""A cell's OPC UA client of the sequencer (asyncua), and the text listing of the server's address space.

:class:`CellClient` connects with Basic256Sha256 Sign & Encrypt, a client certificate the server
trusts (:func:`opportune.service.opcua.client_certificate`) and the cell's service token as
password, and calls the methods of ``Objects/Opportune``; a refused call raises :class:`Refused`
with the OPC UA status and the service's message.  Every call that changes a run sends a fresh
request id unless given one: give the same one to retry a call whose answer was lost.

>>> async with CellClient(endpoint, token, certificate=cert, private_key=key) as cell:  # doctest: +SKIP
...     run = await cell.start_run(await cell.upload_plan(open("gearbox.yaml").read()), policy="paper")
...     answer = await cell.look(run, ["rl", "ra"])                   # {'action': 'buffer', 'part': 'rl', ...}
...     await cell.outcome(run, "success")
"""

from __future__ import annotations

import json
import uuid
from pathlib import Path

from asyncua import Client, ua

from opportune.service.opcua import NAMESPACE


class Refused(Exception):
    """A call the server refused: its OPC UA status and the service's message.

    Parameters
    ----------
    status : int
        The OPC UA status code.
    name : str
        The status's name, e.g. ``BadInvalidArgument``.
    message : str
        The service's message (what is wrong and what to do).

    Examples
    --------
    >>> str(Refused(0x80AB0000, "BadInvalidArgument", "unknown part 'zz' in the look"))
    "BadInvalidArgument: unknown part 'zz' in the look"
    """

    def __init__(self, status: int, name: str, message: str):
        super().__init__(f"{name}: {message}" if message else name)
        self.status = status
        self.name = name
        self.message = message


def _fresh(request_id: str | None) -> str:
    return uuid.uuid4().hex if request_id is None else request_id


class CellClient:
    """An OPC UA session on the sequencer's server, as one cell (or an operator); ``async with``
    connects and disconnects.

    Parameters
    ----------
    endpoint : str
        The server's ``opc.tcp://HOST:PORT`` URL.
    token : str or None
        The cell's (or operator's) service token, sent as the password; ``None``: an anonymous
        session (development servers on loopback only).
    certificate, private_key : str or os.PathLike, optional
        The client's certificate (trusted by the server) and key
        (:func:`opportune.service.opcua.client_certificate`): with them the session is
        Basic256Sha256 Sign & Encrypt.
    app_uri : str, default "urn:opportune:client"
        The application URI, as in the certificate.
    user : str, default "cell"
        The user name sent with the token.
    timeout : float, default 10.0
        Seconds per request.

    Examples
    --------
    Constructing connects nothing; a session needs a running server (``opportune serve --opcua``):

    >>> cell = CellClient("opc.tcp://127.0.0.1:4840", "opp_example")
    >>> cell.client.application_uri
    'urn:opportune:client'
    >>> async with CellClient(endpoint, token, certificate=cert, private_key=key) as cell:  # doctest: +SKIP
    ...     run = await cell.start_run(await cell.upload_plan(plan_text), policy="paper")
    ...     answer = await cell.look(run, ["rl", "ra"])
    ...     await cell.outcome(run, "success")
    """

    def __init__(self, endpoint: str, token: str | None, *, certificate: str | Path | None = None,
                 private_key: str | Path | None = None, app_uri: str = "urn:opportune:client", user: str = "cell",
                 timeout: float = 10.0):
        self.client = Client(endpoint, timeout=timeout)
        self.client.application_uri = app_uri
        self.certificate, self.private_key = certificate, private_key
        if token is not None:
            self.client.set_user(user)
            self.client.set_password(token)
        self.ns = 0

    async def connect(self) -> "CellClient":
        """Open the session (with the certificate, if given) and find the server's namespace.

        Returns
        -------
        CellClient
            This client, connected.

        Examples
        --------
        >>> cell = await CellClient(endpoint, token, certificate=cert, private_key=key).connect()  # doctest: +SKIP
        """
        if self.certificate is not None:
            await self.client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{self.certificate},{self.private_key}")
        await self.client.connect()
        self.ns = await self.client.get_namespace_index(NAMESPACE)
        return self

    async def disconnect(self) -> None:
        """Close the session.

        Examples
        --------
        >>> await cell.disconnect()  # doctest: +SKIP
        """
        await self.client.disconnect()

    async def __aenter__(self) -> "CellClient":
        return await self.connect()

    async def __aexit__(self, *exc) -> None:
        try:
            await self.disconnect()
        except Exception:   # the server is gone (a test killed it): nothing to close politely
            pass

    def node_id(self, name: str) -> ua.NodeId:
        """The node id of ``name`` in the server's namespace (known once connected).

        Parameters
        ----------
        name : str
            A node's string id, e.g. ``"Opportune"`` or ``"Runs/7/State"``.

        Returns
        -------
        asyncua.ua.NodeId
            The node id.

        Examples
        --------
        >>> CellClient("opc.tcp://127.0.0.1:4840", None).node_id("Opportune").Identifier
        'Opportune'
        """
        return ua.NodeId(name, self.ns)

    async def call(self, method: str, *args: ua.Variant) -> list:
        """Call the method ``Objects/Opportune/<method>``.

        Parameters
        ----------
        method : str
            The method's name, e.g. ``"Look"``.
        *args : asyncua.ua.Variant
            Its input arguments.

        Returns
        -------
        list
            Its output values.

        Raises
        ------
        Refused
            If the server refused the call: its status and the service's message.

        Examples
        --------
        >>> await cell.call("UploadPlan", ua.Variant(plan_text, ua.VariantType.String))  # doctest: +SKIP
        ['3f9a...']
        """
        request = ua.CallMethodRequest(ObjectId=self.node_id("Opportune"), MethodId=self.node_id(method),
                                       InputArguments=list(args))
        result = (await self.client.uaclient.call([request]))[0]
        if not result.StatusCode.is_good():
            infos = result.InputArgumentDiagnosticInfos or []
            message = next((d.AdditionalInfo for d in infos if d is not None and d.AdditionalInfo), "")
            raise Refused(result.StatusCode.value, result.StatusCode.name, message)
        return [v.Value for v in result.OutputArguments]

    async def upload_plan(self, text: str) -> str:
        """Upload a plan file's text.

        Parameters
        ----------
        text : str
            The plan, as a plan file holds it (YAML or JSON).

        Returns
        -------
        str
            The plan's id (its content hash: uploading it again gives the same id).

        Raises
        ------
        Refused
            If the plan is refused (``BadInvalidArgument`` with every problem).

        Examples
        --------
        >>> plan = await cell.upload_plan(open("gearbox.yaml").read())  # doctest: +SKIP
        """
        return (await self.call("UploadPlan", ua.Variant(text, ua.VariantType.String)))[0]

    async def start_run(self, plan: str, *, policy: str = "", buffer_capacity: int | None = None, label: str = "",
                        request_id: str | None = None) -> int:
        """Start a run of a plan.

        Parameters
        ----------
        plan : str
            The plan's id, or a plan file's text.
        policy : str, default ""
            The policy (``""``: the server's default).
        buffer_capacity : int, optional
            Buffer locations (``None``: unlimited).
        label : str, default ""
            A label for people (a serial number).
        request_id : str, optional
            The request's id; give the id of a call whose answer was lost to retry it (``None``: a fresh
            one).

        Returns
        -------
        int
            The run's id.

        Raises
        ------
        Refused
            If the run cannot be started.

        Examples
        --------
        >>> run = await cell.start_run(plan, policy="paper", label="SN 1042")  # doctest: +SKIP
        """
        s = ua.VariantType.String
        return (await self.call("StartRun", ua.Variant(plan, s), ua.Variant(policy, s),
                                ua.Variant(-1 if buffer_capacity is None else buffer_capacity, ua.VariantType.Int32),
                                ua.Variant(label, s), ua.Variant(_fresh(request_id), s)))[0]

    async def look(self, run_id: int, visible: list[str], request_id: str | None = None) -> dict:
        """The action for what the camera sees.

        Parameters
        ----------
        run_id : int
            The run.
        visible : list of str
            The part ids seen in the bin.
        request_id : str, optional
            As in :meth:`start_run`.

        Returns
        -------
        dict
            ``action``, ``part``, ``source``, ``seq``, ``explanation``, ``answer`` (the HTTP answer's
            JSON) and ``replayed``.

        Raises
        ------
        Refused
            If the look does not fit the run's state (``BadInvalidArgument``) or an action is pending
            (``BadInvalidState``).

        Examples
        --------
        >>> (await cell.look(run, ["rl", "ra"]))["action"]  # doctest: +SKIP
        'buffer'
        """
        s = ua.VariantType.String
        out = await self.call("Look", ua.Variant(run_id, ua.VariantType.Int64), ua.Variant(list(visible), s),
                              ua.Variant(_fresh(request_id), s))
        return dict(zip(("action", "part", "source", "seq", "explanation", "answer", "replayed"),
                        out[:5] + [json.loads(out[5]), out[6]]))

    async def outcome(self, run_id: int, outcome: str = "success", keep: str = "", request_id: str | None = None) -> dict:
        """Report the outcome of the pending action.

        Parameters
        ----------
        run_id : int
            The run.
        outcome : str, default "success"
            ``success``, ``failed`` or ``defective``.
        keep : str, default ""
            For a failed install: ``bin`` or ``buffer`` (``""``: the bin).
        request_id : str, optional
            As in :meth:`start_run`.

        Returns
        -------
        dict
            ``status`` (``complete`` once the assembly is), ``seq``, ``answer`` and ``replayed``.

        Raises
        ------
        Refused
            If no action is pending or the outcome does not fit it (``BadInvalidState``).

        Examples
        --------
        >>> (await cell.outcome(run, "success"))["status"]  # doctest: +SKIP
        'running'
        """
        s = ua.VariantType.String
        out = await self.call("ReportOutcome", ua.Variant(run_id, ua.VariantType.Int64), ua.Variant(outcome, s),
                              ua.Variant(keep, s), ua.Variant(_fresh(request_id), s))
        return {"status": out[0], "seq": out[1], "answer": json.loads(out[2]), "replayed": out[3]}

    async def cancel(self, run_id: int, request_id: str | None = None) -> dict:
        """Drop the pending action (the robot did not carry it out).

        Parameters
        ----------
        run_id : int
            The run.
        request_id : str, optional
            As in :meth:`start_run`.

        Returns
        -------
        dict
            ``seq``, ``answer`` and ``replayed``.

        Raises
        ------
        Refused
            If no action is pending.

        Examples
        --------
        >>> await cell.cancel(run)  # doctest: +SKIP
        """
        out = await self.call("Cancel", ua.Variant(run_id, ua.VariantType.Int64),
                              ua.Variant(_fresh(request_id), ua.VariantType.String))
        return {"seq": out[0], "answer": json.loads(out[1]), "replayed": out[2]}

    async def read(self, run_id: int, name: str):
        """A run's variable.

        Parameters
        ----------
        run_id : int
            The run.
        name : str
            ``State``, ``PendingAction``, ``Installed``, ... (docs/opcua.md lists them).

        Returns
        -------
        object
            The variable's value.

        Examples
        --------
        >>> await cell.read(run, "Installed")  # doctest: +SKIP
        ['ca']
        """
        return await self.client.get_node(self.node_id(f"Runs/{run_id}/{name}")).read_value()


async def drive(cell: CellClient, run_id: int, world, *, max_looks: int | None = None) -> list[dict]:
    """Drive a run to completion through a simulated bin (a :class:`~opportune.worlds.World` filled with the
    plan's units): look, do what the server decides, report success; the answers of the looks, in order.

    Installing or buffering a part takes it from the bin (an install from the buffer does not); a shake
    shakes it.  At most ``max_looks`` looks (default 20 per unit in the bin, plus 100), then
    :class:`RuntimeError`: a bin that never shows what the run needs does not loop for ever.
    O(looks) calls, each a round trip.

    >>> world = UniformBin(visible=2); world.reset(units, random.Random(7))     # doctest: +SKIP
    >>> looks = await drive(cell, run, world)                                  # doctest: +SKIP
    """
    limit = max_looks if max_looks is not None else 20 * len(world) + 100
    answers = []
    for _ in range(limit):
        answer = await cell.look(run_id, list(world.look()))
        answers.append(answer)
        if answer["action"] == "shake":
            world.shake()
        elif answer["action"] in ("install", "buffer") and answer["source"] != "buffer":
            world.take(answer["part"])
        if (await cell.outcome(run_id, "success"))["status"] == "complete":
            return answers
    raise RuntimeError(f"run {run_id} is not complete after {limit} looks")


async def listing(client: Client, root: ua.NodeId | None = None) -> str:
    """The address space under ``Objects/Opportune`` as text, one node a line.  O(nodes).

    Parameters
    ----------
    client : asyncua.Client
        A connected session (:attr:`CellClient.client`).
    root : asyncua.ua.NodeId, optional
        The node to list from (``None``: ``Objects/Opportune``).

    Returns
    -------
    str
        Each node's id, class and browse path; methods with their arguments, variables with their
        data type.

    Examples
    --------
    >>> print(await listing(cell.client))  # doctest: +SKIP
    namespace 2 = urn:opportune:sequencer
    ...
    """
    ns = await client.get_namespace_index(NAMESPACE)
    node = client.get_node(root or ua.NodeId("Opportune", ns))
    lines = [f"namespace {ns} = {NAMESPACE}"]

    async def type_name(dtype: ua.NodeId) -> str:
        return (await client.get_node(dtype).read_browse_name()).Name

    async def walk(n, path: str) -> None:
        cls = await n.read_node_class()
        nid = n.nodeid.to_string()
        if cls == ua.NodeClass.Method:
            args = {}
            for prop in await n.get_properties():
                args[(await prop.read_browse_name()).Name] = await prop.read_value()
            ins = ", ".join([f"{a.Name}: {await type_name(a.DataType)}{'[]' if a.ValueRank == 1 else ''}"
                             for a in args.get("InputArguments", [])])
            outs = ", ".join([f"{a.Name}: {await type_name(a.DataType)}{'[]' if a.ValueRank == 1 else ''}"
                              for a in args.get("OutputArguments", [])])
            lines.append(f"{nid:<34} Method    {path}({ins}) -> ({outs})")
            return
        if cls == ua.NodeClass.Variable:
            rank = await n.read_value_rank()
            lines.append(f"{nid:<34} Variable  {path}: {await type_name(await n.read_data_type())}"
                         f"{'[]' if rank == 1 else ''}")
            return
        lines.append(f"{nid:<34} Object    {path}")
        children = [c for c in await n.get_children() if c.nodeid.NamespaceIndex == ns]
        for child in sorted(children, key=lambda c: c.nodeid.to_string()):
            await walk(child, f"{path}/{(await child.read_browse_name()).Name}")

    await walk(node, "Objects/Opportune")
    return "\n".join(lines)
