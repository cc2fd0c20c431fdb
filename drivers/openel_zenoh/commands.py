"""The Zenoh driver's subcommands of ``openel-async`` (entry-point group
``openel_async.commands``; the framework's command line imports no driver):

- ``openel-async serve RIG.yaml``: host a rig's components and serve their surface layer over
  Zenoh until interrupted (Ctrl-C or SIGTERM). Safe by default: a peer listening on
  127.0.0.1 only (``--listen`` to change the endpoint, ``--config`` for a Zenoh JSON5 file of
  your own, e.g. TLS or access control for a LAN), no multicast or gossip scouting.
  It also serves the rig's e-stop (``openel/<ns>/rig/estop``, ``.../release``:
  openel_zenoh.estop), its components' RTC lifecycle and configuration
  (``openel/<ns>/rig/lifecycle``, ``.../conf``: openel_zenoh.lifecycle), and SIGQUIT e-stops the rig (unless its ``safety.estop_on_sigquit``
  is false).
- ``openel-async estop``: e-stop every component of a served rig at once (``--release``:
  release it), print one line per component.
- ``openel-async hal4rt exec FILE.xml``: send a ``<Device>`` message to a running server and
  print the reply as XML.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from typing import TYPE_CHECKING, TypeAlias

from openel_async.cli.commands import EXIT_USAGE, CliCommand, load_bytes, no_such_file
from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger

log = get_logger(__name__)

if TYPE_CHECKING:
    import anyio

    from openel_async.surface.messages import Device

    from . import wire

    SubParsers: TypeAlias = argparse._SubParsersAction[argparse.ArgumentParser]


# -- serve --------------------------------------------------------------------------------------


def add_serve_parser(sub: SubParsers) -> argparse.ArgumentParser:
    serve: argparse.ArgumentParser = sub.add_parser(
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
    serve.add_argument(
        "--sim",
        action="store_true",
        help="run the rig against simulated peers: every bus becomes a simulated one with the "
        "simulated devices at the same addresses",
    )
    serve.add_argument(
        "--max-clients",
        type=int,
        default=256,
        metavar="N",
        help="clients the server keeps state for at once (default 256); a client without a "
        "liveliness token is forgotten when idle, a new one beyond N live ones is refused",
    )
    serve.add_argument(
        "--client-idle-timeout",
        type=float,
        default=60.0,
        metavar="SECONDS",
        help="forget a client without a liveliness token after this long idle (default 60)",
    )
    serve.add_argument(
        "--stop-on-eof",
        action="store_true",
        help="also stop when standard input reaches its end (a parent process that started "
        "the server with a pipe on its stdin stops it by closing the pipe, or by dying)",
    )
    return serve


def run_serve(args: argparse.Namespace) -> int:
    import anyio

    from .gate import GatedEventLoop

    if no_such_file("openel-async serve", args.rig):
        return EXIT_USAGE
    if args.max_clients < 1 or not 0 < args.client_idle_timeout < float("inf"):
        bad = "--max-clients" if args.max_clients < 1 else "--client-idle-timeout"
        print(f"openel-async serve: {bad}: expected a value > 0", file=sys.stderr)
        return EXIT_USAGE
    try:
        # A gated loop: plain reads are answered on Zenoh's thread while the loop is idle.
        return anyio.run(
            _serve, args, backend="asyncio", backend_options={"loop_factory": GatedEventLoop}
        )
    except BadParameterError as exc:
        print(f"openel-async serve: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


async def _serve(args: argparse.Namespace) -> int:
    import anyio

    from openel_async.rig import Rig, load_rig, open_rig
    from openel_async.surface import Surface

    from . import SurfaceServer, close_session, open_session
    from .config import DEFAULT_ENDPOINT, file_config, server_config
    from .estop import RigEstopServer
    from .lifecycle_server import RigLifecycleServer

    spec = load_rig(args.rig)
    namespace = args.namespace or spec.namespace
    listen = args.listen or [DEFAULT_ENDPOINT]
    config = file_config(args.config) if args.config else server_config(listen)
    session = await open_session(config)
    opened: list[Rig] = []
    try:
        async with (
            open_rig(spec, sim=args.sim, handle_sigquit=True) as rig,
            RigEstopServer(rig, session, namespace),  # before the server's liveliness token
            Surface(list(rig.components.values())) as surface,
            RigLifecycleServer(surface, session, namespace) as lifecycle,
            SurfaceServer(
                surface,
                session,
                namespace,
                max_clients=args.max_clients,
                client_idle_timeout=args.client_idle_timeout,
                admit=lifecycle.lifecycle.admit,
            ),
        ):
            opened.append(rig)
            for bus, description in rig.bus_descriptions.items():
                print(f"bus {bus}: {description}", flush=True)
            where = f"config {args.config}" if args.config else ", ".join(listen)
            names = ", ".join(
                f"{e.device_kind}[{e.logical_id}]={e.component.device_name}"
                for e in surface.entries
            )
            async with anyio.create_task_group() as tg:
                if getattr(args, "stop_on_eof", False):
                    tg.start_soon(_stop_on_eof, tg.cancel_scope)
                with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
                    # ready once a signal stops it cleanly: the line a parent waits for
                    print(
                        f"serving {len(rig.components)} components on {where}, "
                        f"namespace {namespace!r}: {names}",
                        flush=True,
                    )
                    async for signum in signals:
                        log.info("serve_stopping", signal=signal.Signals(signum).name)
                        break
                tg.cancel_scope.cancel()
    finally:
        await close_session(session)
        if opened:
            print(opened[0].exit_line().strip(), flush=True)
    return 0


async def _stop_on_eof(scope: anyio.CancelScope) -> None:
    """Cancel ``scope`` at the end of standard input. Read in the event loop, not in a
    thread: a thread blocked in read() would keep the process alive after a signal stopped
    the server, until the parent closed the pipe."""
    await read_to_eof(sys.stdin.fileno())
    log.info("serve_stopping", reason="end of standard input")
    scope.cancel()


async def read_to_eof(fd: int) -> None:
    """Return once ``fd`` reaches its end (what it reads is discarded); cancellable at any
    time. What cannot be waited on (a regular file, /dev/null) is read straight: it never
    blocks."""
    import anyio
    import anyio.lowlevel

    pollable = True
    while True:
        if pollable:
            try:
                await anyio.wait_readable(fd)
            except PermissionError:  # epoll refuses regular files and /dev/null
                pollable = False
        else:
            await anyio.lowlevel.checkpoint()
        try:
            if not os.read(fd, 65536):
                return
        except BlockingIOError:  # a spurious wake-up
            continue


SERVE = CliCommand("serve", add_serve_parser, run_serve)
"""``openel-async serve``."""


# -- estop ----------------------------------------------------------------------------------------

EXIT_NO_SERVER = 1
"""``openel-async estop``: no rig served (or no reply) within the timeout."""
EXIT_ESTOP_FAILED = 3
"""``openel-async estop``: the server answered, but some component's e-stop failed."""


def add_estop_parser(sub: SubParsers) -> argparse.ArgumentParser:
    estop: argparse.ArgumentParser = sub.add_parser(
        "estop",
        help="e-stop every component of a rig served by 'openel-async serve' at once",
        description="E-stop every component of a served rig at once, in one round trip: each "
        "actuator goes into its protocol's emergency state and every component to Error with "
        "error id 8 (ESTOP), latched: re_init is refused until the e-stop is released "
        "(--release). Prints one line per component. Exit status: 0 done, 1 no rig served "
        "(or no reply) within the timeout, 2 usage error, 3 some component's e-stop failed.",
    )
    estop.add_argument(
        "--release",
        action="store_true",
        help="release the e-stop: re_init recovers the components again",
    )
    estop.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="server endpoint (default tcp/127.0.0.1:7447; repeatable)",
    )
    estop.add_argument(
        "--config", metavar="FILE", help="Zenoh JSON5 configuration (replaces the safe defaults)"
    )
    estop.add_argument(
        "--namespace",
        help="the server's key-expression namespace (default: the one rig served, "
        "discovered from its liveliness token)",
    )
    estop.add_argument(
        "--timeout",
        type=float,
        default=5.0,
        help="seconds to wait for the server, then for its reply (default 5)",
    )
    return estop


def run_estop(args: argparse.Namespace) -> int:
    import anyio
    import zenoh

    from .config import DEFAULT_ENDPOINT
    from .estop import describe
    from .keys import Keys

    try:
        if args.namespace is not None:
            Keys(args.namespace)
        if not args.timeout > 0:
            raise BadParameterError("--timeout", args.timeout, "a number of seconds > 0")
    except BadParameterError as exc:
        print(f"openel-async estop: {exc}", file=sys.stderr)
        return EXIT_USAGE
    where = args.config or ", ".join(args.connect or [DEFAULT_ENDPOINT])
    try:
        reply = anyio.run(_estop, args, backend="asyncio")
    except BadParameterError as exc:  # a bad --config or endpoint
        print(f"openel-async estop: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except zenoh.ZError as exc:
        print(f"openel-async estop: no Zenoh session for {where}: {exc}", file=sys.stderr)
        return EXIT_NO_SERVER
    except (HALError, TimeoutError) as exc:
        namespace = f", namespace {args.namespace!r}" if args.namespace else ""
        print(f"openel-async estop: no rig served at {where}{namespace}: {exc}", file=sys.stderr)
        return EXIT_NO_SERVER
    for state in reply.components:
        print(describe(state, reply.release), flush=True)
    if reply.return_code != 0:
        what = "release" if reply.release else "e-stop"
        print(f"openel-async estop: {what} failed: {reply.message}", file=sys.stderr)
        return EXIT_ESTOP_FAILED
    return 0


async def _estop(args: argparse.Namespace) -> wire.EstopReply:
    from . import close_session, open_session
    from .config import DEFAULT_ENDPOINT, client_config, file_config
    from .estop import estop_rig

    config = (
        file_config(args.config)
        if args.config
        else client_config(args.connect or [DEFAULT_ENDPOINT])
    )
    session = await open_session(config)
    try:
        namespace = args.namespace
        if namespace is None:  # the one rig served
            from .shell import NoRigError, discover

            served = await discover(session, timeout=args.timeout)
            if len(served) != 1:
                raise NoRigError(
                    f"several rigs served: {', '.join(served)}; give --namespace"
                    if served
                    else f"none within {args.timeout:g} s",
                    served,
                )
            namespace = served[0]
        return await estop_rig(session, namespace, release=args.release, timeout=args.timeout)
    finally:
        await close_session(session)


ESTOP = CliCommand("estop", add_estop_parser, run_estop)
"""``openel-async estop``."""


# -- hal4rt exec --------------------------------------------------------------------------------


def add_exec_parser(actions: SubParsers) -> argparse.ArgumentParser:
    execute: argparse.ArgumentParser = actions.add_parser(
        "exec", help="send a <Device> message to a server and print the reply"
    )
    execute.add_argument("file", metavar="FILE.xml", help="the message ('-' for standard input)")
    execute.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="server endpoint (default tcp/127.0.0.1:7447)",
    )
    execute.add_argument(
        "--config", metavar="FILE", help="Zenoh JSON5 configuration (replaces the safe defaults)"
    )
    execute.add_argument(
        "--namespace",
        default="default",
        help="the server's key-expression namespace (default: default)",
    )
    execute.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for the reply")
    return execute


def run_exec(args: argparse.Namespace) -> int:
    import anyio

    from openel_async.surface import xml_psm

    if no_such_file("openel-async hal4rt exec", args.file):
        return EXIT_USAGE
    try:
        device = xml_psm.device_from_xml(load_bytes(args.file))
    except (OSError, BadParameterError) as exc:
        print(f"{args.file}: {exc}", file=sys.stderr)
        return 1
    try:
        reply = anyio.run(_send, device, args, backend="asyncio")
    except (HALError, TimeoutError) as exc:
        print(f"openel-async hal4rt exec: {exc}", file=sys.stderr)
        return 1
    sys.stdout.write(xml_psm.to_xml(reply).decode("utf-8") + "\n")
    codes = [
        c.results.value("return_code")
        for c in reply.commands
        if c.results and c.results.get("return_code")
    ]
    return 0 if all(code == 0 for code in codes) else 3


async def _send(device: Device, args: argparse.Namespace) -> Device:
    from . import RemoteSurface, close_session, open_session
    from .config import DEFAULT_ENDPOINT, client_config, file_config

    config = (
        file_config(args.config)
        if args.config
        else client_config(args.connect or [DEFAULT_ENDPOINT])
    )
    session = await open_session(config)
    try:
        async with RemoteSurface(
            session, args.namespace, timeout=args.timeout, encoding="xml"
        ) as remote:
            return await remote.execute(device)
    finally:
        await close_session(session)


HAL4RT_EXEC = CliCommand("exec", add_exec_parser, run_exec, parent="hal4rt")
"""``openel-async hal4rt exec``."""
