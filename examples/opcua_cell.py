"""A reference cell over OPC UA: a simulated bin driven through ``opportune serve --opcua``, end to end.

The cell uploads its plan, starts a run, and then, until the run is complete: looks into its bin
(a simulated one here: a camera that sees ``--visible`` parts drawn at random), calls ``Look``, does
what the server decided (takes the part out of the bin to install or buffer it, or shakes the bin),
and reports the outcome with ``ReportOutcome``.  A real cell replaces the simulated bin by its camera
and its robot; the calls are the same.

    python examples/opcua_cell.py example:gearbox --endpoint opc.tcp://127.0.0.1:4840 --token opp_... \\
        --cert cell-1-pki/cert.der --key cell-1-pki/key.pem --app-uri urn:example:cell-1

The client certificate must be in the server's trust list (``opcua-pki/trusted/``):
``opportune.service.opcua.client_certificate`` makes one and copies it there.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random

from opportune import load_plan
from opportune.service.opcua_client import CellClient, drive
from opportune.worlds import UniformBin


async def main(args) -> None:
    plan = load_plan(args.plan)
    units = [p.id for p in plan.parts for _ in range(p.quantity)]
    world = UniformBin(visible=args.visible)
    world.reset(units, random.Random(args.seed))
    async with CellClient(args.endpoint, args.token, certificate=args.cert, private_key=args.key,
                          app_uri=args.app_uri, user=args.user) as cell:
        # the plan as JSON, whatever file it came from (YAML, .IN2, GraphML, ...)
        run = await cell.start_run(await cell.upload_plan(json.dumps(plan.to_dict())), policy=args.policy,
                                   label=args.label)
        print(f"run {run} of {plan.name}")
        for n, answer in enumerate(await drive(cell, run, world), start=1):
            where = " (from buffer)" if answer["source"] == "buffer" else ""
            print(f"{n:3}  seen {' '.join(answer['answer']['row']['visible']) or '-':<12} "
                  f"{answer['action']} {answer['part']}{where}")
        print("installed:", " ".join(await cell.read(run, "Installed")))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plan", help="a plan file, or a shipped plan (example:gearbox, salbp:KILBRID)")
    ap.add_argument("--endpoint", default="opc.tcp://127.0.0.1:4840")
    ap.add_argument("--token", required=True, help="the cell's token (opportune token create CELL)")
    ap.add_argument("--user", default="cell", help="the user name (not checked: the token is what counts)")
    ap.add_argument("--cert", required=True, help="the client's certificate (DER), trusted by the server")
    ap.add_argument("--key", required=True, help="its private key (PEM)")
    ap.add_argument("--app-uri", default="urn:opportune:client", help="the application URI in the certificate")
    ap.add_argument("--policy", default="", help="the decision policy (empty: the server's default)")
    ap.add_argument("--label", default="", help="free text shown on the dashboard")
    ap.add_argument("--visible", type=int, default=2, help="parts the simulated camera sees at each look")
    ap.add_argument("--seed", type=int, default=0, help="the simulated bin's seed (same seed, same looks)")
    asyncio.run(main(ap.parse_args()))
