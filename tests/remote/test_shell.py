"""The served rig from the shell (openel_zenoh.shell_commands: ls, get, set, watch, reset),
each command's async main against the shipped two-axis rig served in this process on
loopback; the options refused before anything is opened. The commands as processes:
tests/tools/test_shell_processes.py."""

from __future__ import annotations

import argparse
import json
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from pathlib import Path

import anyio
import pytest

from openel_async.component import ComponentState
from openel_async.errors import BadParameterError, HALError
from openel_async.rig import Rig, load_rig, open_rig
from openel_async.surface import Surface
from openel_zenoh import SurfaceServer
from openel_zenoh import shell_commands as sc
from openel_zenoh.config import endpoint, server_config
from openel_zenoh.estop import RigEstopServer
from openel_zenoh.shell import NoRigError, RigShell, discover

from .conftest import client_cfg, free_port, session

RIG = Path(__file__).resolve().parents[2] / "apps" / "openel_apps" / "rigs" / "twoaxis-sim.yaml"
PARSERS: dict[str, Callable[..., argparse.ArgumentParser]] = {
    "ls": sc.add_ls_parser,
    "get": sc.add_get_parser,
    "set": sc.add_set_parser,
    "watch": sc.add_watch_parser,
    "reset": sc.add_reset_parser,
}


def parse(*argv: str) -> argparse.Namespace:
    """The arguments of one shell command, as openel-async parses them."""
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    for add in PARSERS.values():
        add(sub)
    return parser.parse_args(list(argv))


@asynccontextmanager
async def served(port: int, namespaces: tuple[str, ...] = ("twoaxis",)) -> AsyncIterator[list[Rig]]:
    """The two-axis rig served in this process once per namespace (as openel-async serve
    serves it: its e-stop, then the surface)."""
    async with session(server_config([endpoint(port)])) as zs, AsyncExitStack() as stack:
        rigs: list[Rig] = []
        for namespace in namespaces:
            rig = await stack.enter_async_context(open_rig(load_rig(RIG), sim=True))
            await stack.enter_async_context(RigEstopServer(rig, zs, namespace))
            surface = await stack.enter_async_context(Surface(list(rig.components.values())))
            await stack.enter_async_context(SurfaceServer(surface, zs, namespace))
            rigs.append(rig)
        yield rigs


@asynccontextmanager
async def shell(port: int, namespace: str | None = None) -> AsyncIterator[RigShell]:
    async with RigShell(client_cfg(port), namespace=namespace, timeout=5.0) as opened:
        yield opened


async def test_ls_lists_every_component_with_state_address_and_hal_id(
    capsys: pytest.CaptureFixture[str],
) -> None:
    port = free_port()
    async with served(port), shell(port) as rig_shell:
        assert await sc.ls_main(rig_shell, parse("ls")) == 0
        lines = capsys.readouterr().out.splitlines()  # no lifecycle served here: "-"
        assert lines[0] == "twoaxis: 4 components"
        assert lines[1].split() == [
            "NAME",
            "ADDRESS",
            "STATE",
            "LIFECYCLE",
            "HALID",
            "(kind:vendor:product:instance)",
        ]
        assert lines[2].split() == ["MOTOR_1", "Motor[0]", "Active", "-", "0x1:0xE1:0x100:1"]
        assert lines[5].split() == [
            "TEMP_2", "TemperatureSensor[0]", "Active", "-", "0x8:0xE1:0x400:1"
        ]  # fmt: skip

        assert await sc.ls_main(rig_shell, parse("ls", "--json")) == 0
        listing = json.loads(capsys.readouterr().out)
        assert [c["name"] for c in listing["twoaxis"]] == [
            "MOTOR_1",
            "MOTOR_2",
            "ENCODER_1",
            "TEMP_2",
        ]
        assert listing["twoaxis"][1]["hal_id"] == {
            "device_kind_id": 1, "vendor_id": 0xE1, "product_id": 0x100, "instance_id": 2,
        }  # fmt: skip


async def test_namespaces_are_discovered_and_a_wrong_one_names_those_served() -> None:
    port = free_port()
    async with served(port, ("lab", "bench")), session(client_cfg(port)) as zc:
        assert await discover(zc, timeout=5.0) == ["bench", "lab"]
        assert "lab" in await discover(zc, timeout=5.0, wanted="lab")
        async with shell(port, "lba") as wrong:
            with pytest.raises(NoRigError, match=r"namespace 'lba'; served: bench, lab"):
                await wrong.listing()
        async with shell(port) as both:
            with pytest.raises(BadParameterError, match="one of bench/MOTOR_1, lab/MOTOR_1"):
                await both.target("MOTOR_1")
            target = await both.target("lab/Motor[1]")
            assert (target.namespace, target.name) == ("lab", "MOTOR_2")
            with pytest.raises(BadParameterError, match="a served component: bench/MOTOR_1"):
                await both.target("MOTOR_9")


async def test_no_server_is_told_within_the_timeout() -> None:
    async with RigShell(client_cfg(free_port()), timeout=0.3) as alone:
        with (
            anyio.fail_after(5),
            pytest.raises(NoRigError, match=r"no rig served \(waited 0.3 s\)"),
        ):
            await alone.namespaces()


async def test_get_reads_by_short_name_or_function(capsys: pytest.CaptureFixture[str]) -> None:
    port = free_port()
    async with served(port), shell(port) as rig_shell:
        assert await sc.get_main(rig_shell, parse("get", "MOTOR_1")) == 0
        assert capsys.readouterr().out == "MOTOR_1 position 0\n"
        assert await sc.get_main(rig_shell, parse("get", "motor_2", "state")) == 0
        assert capsys.readouterr().out.splitlines()[0] == "MOTOR_2 state Active"
        assert await sc.get_main(rig_shell, parse("get", "TemperatureSensor[0]", "--json")) == 0
        reading = json.loads(capsys.readouterr().out)
        assert reading["name"] == "TEMP_2" and reading["function"] == "GetValueOfMeasurement"
        assert 270 < reading["results"]["values"][0] < 320  # kelvin
        assert await sc.get_main(rig_shell, parse("get", "ENCODER_1", "GetUnitOfMeasurement")) == 0
        assert capsys.readouterr().out.startswith("ENCODER_1 units ")
        with pytest.raises(BadParameterError, match="for a Encoder: "):
            await sc.get_main(rig_shell, parse("get", "ENCODER_1", "torque"))


async def test_set_waits_for_completed_or_tells_the_error(
    capsys: pytest.CaptureFixture[str],
) -> None:
    port = free_port()
    async with served(port) as rigs, shell(port) as rig_shell:
        args = parse("set", "MOTOR_1", "0.2", "--wait")
        args.arguments = sc.set_arguments(args)
        assert await sc.set_main(rig_shell, args) == 0
        assert capsys.readouterr().out == "COMPLETED\n"
        assert await rigs[0].component("MOTOR_1").get_value() == pytest.approx(0.2, abs=1e-6)

        args = parse("set", "MOTOR_2", "9", "--json", "--wait")
        args.arguments = sc.set_arguments(args)
        assert await sc.set_main(rig_shell, args) == sc.EXIT_FAILED
        refused = json.loads(capsys.readouterr().out)
        assert refused["status"] == "HAL_BAD_PARAMETER" and "position=9.0" in refused["message"]

        args = parse("set", "MOTOR_2", "1.0", "--request", "speed")  # no --wait: once accepted
        args.arguments = sc.set_arguments(args)
        assert await sc.set_main(rig_shell, args) == 0
        assert capsys.readouterr().out == "ACCEPTED\n"

        args = parse("set", "MOTOR_2", "2.0", "--wait", "--wait-timeout", "0.05")
        args.arguments = sc.set_arguments(args)  # 2 rad at 3 rad/s: not within 50 ms
        assert await sc.set_main(rig_shell, args) == sc.EXIT_FAILED
        assert (
            "TIMEOUT: MOTOR_2: SetPosition not completed within 0.05 s" in capsys.readouterr().err
        )


async def test_watch_prints_values_events_and_errors_as_they_come(
    capsys: pytest.CaptureFixture[str],
) -> None:
    port = free_port()
    async with served(port) as rigs, shell(port) as rig_shell:
        motor = rigs[0].component("MOTOR_1")

        async def act() -> None:
            await anyio.sleep(0.1)
            await (await motor.set_value(0.05))  # COMPLETED
            await rigs[0].estop()  # an error: ESTOP

        async with anyio.create_task_group() as tg:
            tg.start_soon(act)
            assert (
                await sc.watch_main(
                    rig_shell,
                    parse("watch", "MOTOR_1", "--json", "--rate", "20", "--duration", "0.5"),
                )
                == 0
            )
        rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
        kinds = {(r["type"], r["what"]) for r in rows}
        assert ("value", "position") in kinds
        assert ("event", "COMPLETED") in kinds
        assert ("error", "ESTOP") in kinds
        assert {r["name"] for r in rows} == {"MOTOR_1"}
        assert rows == sorted(rows, key=lambda r: r["t"])


async def test_watch_csv_has_a_header_and_reads_the_request(
    capsys: pytest.CaptureFixture[str],
) -> None:
    port = free_port()
    async with served(port), shell(port) as rig_shell:
        args = parse(
            "watch", "TEMP_2", "MOTOR_2", "--csv", "--request", "state", "--duration", "0.3"
        )
        assert await sc.watch_main(rig_shell, args) == 0
        lines = capsys.readouterr().out.splitlines()
        assert lines[0] == "t,namespace,name,type,what,value"
        assert any(line.endswith(",TEMP_2,value,state,Active") for line in lines[1:])
        assert any(line.endswith(",MOTOR_2,value,state,Active") for line in lines[1:])


async def test_reset_recovers_a_component_once_the_estop_is_released(
    capsys: pytest.CaptureFixture[str],
) -> None:
    port = free_port()
    async with served(port) as rigs, shell(port) as rig_shell:
        assert await sc.reset_main(rig_shell, parse("reset", "MOTOR_1")) == 0
        assert capsys.readouterr().out == "MOTOR_1 Active (not in Error: nothing to reset)\n"
        await rigs[0].estop()
        assert await sc.reset_main(rig_shell, parse("reset", "MOTOR_1")) == sc.EXIT_FAILED
        captured = capsys.readouterr()
        assert captured.out == "MOTOR_1 Error\n" and "e-stop is not released" in captured.err
        rigs[0].release_estop()
        assert await sc.reset_main(rig_shell, parse("reset", "MOTOR_1", "--json")) == 0
        reply = json.loads(capsys.readouterr().out)
        assert reply["state"] == "Active" and reply["reset"] is True
        assert rigs[0].component("MOTOR_1").state is ComponentState.ACTIVE


@pytest.mark.parametrize(
    ("argv", "complaint"),
    [
        (("set", "MOTOR_1", "abc"), "VALUE='abc' is not allowed: expected a number"),
        (("set", "MOTOR_1", "nan"), "expected a finite number"),
        (("set", "MOTOR_1", "7", "--request", "mode"), "expected a control mode"),
        (("set", "MOTOR_1", "1", "--tm-acc", "0.5"), "only with --request speed"),
        (("set", "MOTOR_1", "1", "--wait-timeout", "0"), "--wait-timeout"),
        (("get", "MOTOR_1", "speeed"), "REQUEST='speeed' is not allowed"),
        (("ls", "--namespace", "a/b"), "--namespace='a/b' is not allowed"),
        (("ls", "--timeout", "0"), "--timeout=0.0 is not allowed"),
        (("ls", "--connect", "localhost"), "a Zenoh endpoint"),
        (("ls", "--config", "no-such.json5"), "no-such.json5: no such file"),
        (("watch", "MOTOR_1", "--rate", "-1"), "--rate=-1.0 is not allowed"),
        (("watch", "MOTOR_1", "--duration", "0"), "--duration=0.0 is not allowed"),
        (("reset", "MOTOR_1", "--timeout", "inf"), "--timeout=inf is not allowed"),
    ],
)
def test_options_are_checked_before_anything_is_opened(
    argv: tuple[str, ...], complaint: str, capsys: pytest.CaptureFixture[str]
) -> None:
    run = {
        "ls": sc.run_ls,
        "get": sc.run_get,
        "set": sc.run_set,
        "watch": sc.run_watch,
        "reset": sc.run_reset,
    }
    assert run[argv[0]](parse(*argv)) == 2
    assert complaint in capsys.readouterr().err


def test_a_mode_is_taken_by_name_or_number() -> None:
    for text, mode in (("position", 1), ("READY_TO_CONTROL", 0), ("3", 3)):
        args = parse("set", "MOTOR_1", text, "--request", "mode")
        assert sc.set_arguments(args) == {"mode": mode}
    args = parse("set", "MOTOR_1", "2", "--request", "speed", "--tm-acc", "0.5")
    assert sc.set_arguments(args) == {"speed": 2.0, "tmAcc": 0.5}


def test_check_code_of_a_refusal_keeps_the_components_message() -> None:
    from openel_async.surface.messages import CommandMessage, DataType, Parameter, ResultList
    from openel_zenoh.shell import checked

    refused = CommandMessage(
        "SetPosition", "c1", None,
        ResultList((Parameter(DataType.INT, "return_code", 6), Parameter(DataType.STRING, "message", "too far"))),
    )  # fmt: skip
    with pytest.raises(HALError, match=r"^too far$") as caught:
        checked(refused)
    assert caught.value.code == 6
