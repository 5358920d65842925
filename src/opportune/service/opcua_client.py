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
    """A call the server refused: its OPC UA status (``name``, e.g. ``BadInvalidArgument``) and message."""

    def __init__(self, status: int, name: str, message: str):
        super().__init__(f"{name}: {message}" if message else name)
        self.status = status
        self.name = name
        self.message = message


def _fresh(request_id: str | None) -> str:
    return uuid.uuid4().hex if request_id is None else request_id


class CellClient:
    """An OPC UA session on the sequencer's server, as one cell (or an operator); ``async with`` connects."""

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
        if self.certificate is not None:
            await self.client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{self.certificate},{self.private_key}")
        await self.client.connect()
        self.ns = await self.client.get_namespace_index(NAMESPACE)
        return self

    async def disconnect(self) -> None:
        await self.client.disconnect()

    async def __aenter__(self) -> "CellClient":
        return await self.connect()

    async def __aexit__(self, *exc) -> None:
        try:
            await self.disconnect()
        except Exception:   # the server is gone (a test killed it): nothing to close politely
            pass

    def node_id(self, name: str) -> ua.NodeId:
        return ua.NodeId(name, self.ns)

    async def call(self, method: str, *args: ua.Variant) -> list:
        """Call ``Objects/Opportune/<method>``; its output values, or :class:`Refused`."""
        request = ua.CallMethodRequest(ObjectId=self.node_id("Opportune"), MethodId=self.node_id(method),
                                       InputArguments=list(args))
        result = (await self.client.uaclient.call([request]))[0]
        if not result.StatusCode.is_good():
            infos = result.InputArgumentDiagnosticInfos or []
            message = next((d.AdditionalInfo for d in infos if d is not None and d.AdditionalInfo), "")
            raise Refused(result.StatusCode.value, result.StatusCode.name, message)
        return [v.Value for v in result.OutputArguments]

    async def upload_plan(self, text: str) -> str:
        return (await self.call("UploadPlan", ua.Variant(text, ua.VariantType.String)))[0]

    async def start_run(self, plan: str, *, policy: str = "", buffer_capacity: int | None = None, label: str = "",
                        request_id: str | None = None) -> int:
        """Start a run of a plan (its id, or a plan file's text); its id."""
        s = ua.VariantType.String
        return (await self.call("StartRun", ua.Variant(plan, s), ua.Variant(policy, s),
                                ua.Variant(-1 if buffer_capacity is None else buffer_capacity, ua.VariantType.Int32),
                                ua.Variant(label, s), ua.Variant(_fresh(request_id), s)))[0]

    async def look(self, run_id: int, visible: list[str], request_id: str | None = None) -> dict:
        """The action for what the camera sees: ``{action, part, source, seq, explanation, answer, replayed}``."""
        s = ua.VariantType.String
        out = await self.call("Look", ua.Variant(run_id, ua.VariantType.Int64), ua.Variant(list(visible), s),
                              ua.Variant(_fresh(request_id), s))
        return dict(zip(("action", "part", "source", "seq", "explanation", "answer", "replayed"),
                        out[:5] + [json.loads(out[5]), out[6]]))

    async def outcome(self, run_id: int, outcome: str = "success", keep: str = "", request_id: str | None = None) -> dict:
        s = ua.VariantType.String
        out = await self.call("ReportOutcome", ua.Variant(run_id, ua.VariantType.Int64), ua.Variant(outcome, s),
                              ua.Variant(keep, s), ua.Variant(_fresh(request_id), s))
        return {"status": out[0], "seq": out[1], "answer": json.loads(out[2]), "replayed": out[3]}

    async def cancel(self, run_id: int, request_id: str | None = None) -> dict:
        out = await self.call("Cancel", ua.Variant(run_id, ua.VariantType.Int64),
                              ua.Variant(_fresh(request_id), ua.VariantType.String))
        return {"seq": out[0], "answer": json.loads(out[1]), "replayed": out[2]}

    async def read(self, run_id: int, name: str):
        """A run's variable (``State``, ``PendingAction``, ``Installed``, ...)."""
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
    """The address space under ``Objects/Opportune`` as text, one node a line: its node id, class and browse path;
    methods with their arguments, variables with their data type.  O(nodes)."""
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
