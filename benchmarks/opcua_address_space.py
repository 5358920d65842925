"""The text listing of the OPC UA address space in docs/opcua.md, browsed from a running server.

Starts ``opportune serve --opcua`` on loopback over a throwaway database, starts one run of the
gearbox in cell ``cell-1`` over OPC UA, browses ``Objects/Opportune`` (every node id, each method with
its arguments, each variable with its data type) and prints it; ``--write docs/opcua.md`` replaces
the listing between the page's ``<!-- address-space -->`` markers.

    .venv/bin/python benchmarks/opcua_address_space.py
    .venv/bin/python benchmarks/opcua_address_space.py --write docs/opcua.md

With ``--endpoint``, it browses a server of yours instead (as ``--token``'s cell or operator, with a
client certificate the server trusts), and starts nothing:

    .venv/bin/python benchmarks/opcua_address_space.py --endpoint opc.tcp://127.0.0.1:4840 \
        --token opp_... --cert cell-1-pki/cert.der --key cell-1-pki/key.pem --app-uri urn:example:cell-1
"""

from __future__ import annotations

import argparse
import asyncio
import re
import tempfile
from pathlib import Path

from opportune.datasets import example_path
from opportune.service.opcua import client_certificate
from opportune.service.opcua_client import CellClient, listing
from opportune.service.testing import ServiceProcess

APP = "urn:opportune:listing"
MARKERS = re.compile(r"(<!-- address-space -->\n```text\n).*?(```\n<!-- /address-space -->)", re.S)


def address_space() -> str:
    tmp = Path(tempfile.mkdtemp(prefix="opcua-listing-"))
    cert, key = client_certificate(tmp / "client", APP, trust_in=tmp / "pki")
    with ServiceProcess(tmp / "listing.db", opcua=True, pki=tmp / "pki", extra_args=("--no-http",)) as svc:
        token = svc.token(cell="cell-1")

        async def browse() -> str:
            async with CellClient(svc.opcua_endpoint, token, certificate=cert, private_key=key, app_uri=APP) as cell:
                run = await cell.start_run(example_path("gearbox").read_text(), request_id="listing")
                for _ in range(200):        # its nodes appear once the server has seen the new run
                    try:
                        await cell.read(run, "State")
                        break
                    except Exception:
                        await asyncio.sleep(0.05)
                return await listing(cell.client)

        return asyncio.run(browse())


def browse_yours(args) -> str:
    async def browse() -> str:
        async with CellClient(args.endpoint, args.token, certificate=args.cert, private_key=args.key,
                              app_uri=args.app_uri) as cell:
            return await listing(cell.client)

    return asyncio.run(browse())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", type=Path, help="a page whose <!-- address-space --> block to replace")
    ap.add_argument("--endpoint", help="browse this server instead of a throwaway one")
    ap.add_argument("--token", help="with --endpoint: a cell's or an operator's token")
    ap.add_argument("--cert", help="with --endpoint: the client's certificate (DER), trusted by the server")
    ap.add_argument("--key", help="with --endpoint: its private key (PEM)")
    ap.add_argument("--app-uri", default="urn:opportune:client", help="the application URI in the certificate")
    args = ap.parse_args()
    if args.endpoint and not (args.token and args.cert and args.key):
        ap.error("--endpoint needs --token, --cert and --key")
    text = browse_yours(args) if args.endpoint else address_space()
    if args.write is None:
        print(text)
        return
    page = args.write.read_text(encoding="utf-8")
    new, n = MARKERS.subn(lambda m: m.group(1) + text + "\n" + m.group(2), page)
    if n != 1:
        raise SystemExit(f"{args.write}: no <!-- address-space --> ... <!-- /address-space --> block around a "
                         "```text block")
    args.write.write_text(new, encoding="utf-8")


if __name__ == "__main__":
    main()
