"""``openel-async serve RIG.yaml``: host a rig's components and serve their surface layer
over Zenoh until interrupted (Ctrl-C or SIGTERM).

Safe by default: a peer listening on 127.0.0.1 only (``--listen`` to change the endpoint,
``--config`` for a Zenoh JSON5 file of your own, e.g. TLS or access control for a LAN),
no multicast or gossip scouting.
"""

from __future__ import annotations

import argparse
import signal
import sys

import anyio
import structlog

from ..errors import BadParameterError

log = structlog.get_logger(__name__)


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    serve = sub.add_parser(
        "serve",
        help="host the components of a rig file and serve their HAL4RT surface layer over Zenoh",
    )
    serve.add_argument(
        "rig", help="rig file (YAML): namespace and components (driver, device, params)"
    )
    serve.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help="Zenoh endpoint to listen on (default tcp/127.0.0.1:7447; repeatable)",
    )
    serve.add_argument(
        "--config", metavar="FILE", help="Zenoh JSON5 configuration (replaces the safe defaults)"
    )
    serve.add_argument("--namespace", help="key-expression namespace (default: the rig file's)")


def run(args: argparse.Namespace) -> int:
    try:
        return anyio.run(_serve, args, backend="asyncio")
    except BadParameterError as exc:
        print(f"openel-async serve: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


async def _serve(args: argparse.Namespace) -> int:
    from openel_zenoh import SurfaceServer, close_session, open_session
    from openel_zenoh.config import DEFAULT_ENDPOINT, file_config, server_config

    from ..surface import Surface
    from ..surface.rig import load_rig, open_rig

    spec = load_rig(args.rig)
    namespace = args.namespace or spec.namespace
    listen = args.listen or [DEFAULT_ENDPOINT]
    config = file_config(args.config) if args.config else server_config(listen)
    session = await open_session(config)
    try:
        async with (
            open_rig(spec) as components,
            Surface(components) as surface,
            SurfaceServer(surface, session, namespace),
        ):
            where = f"config {args.config}" if args.config else ", ".join(listen)
            names = ", ".join(
                f"{e.device_kind}[{e.logical_id}]={e.component.device_name}"
                for e in surface.entries
            )
            print(
                f"serving {len(components)} components on {where}, namespace {namespace!r}: {names}",
                flush=True,
            )
            with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
                async for signum in signals:
                    log.info("serve_stopping", signal=signal.Signals(signum).name)
                    break
    finally:
        await close_session(session)
    return 0
