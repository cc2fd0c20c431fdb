"""RemoteSurface and the remote devices against a server in the same process (loopback)."""

from __future__ import annotations

import anyio
import pytest
from hypothesis import given, settings

from openel_async import (
    Actuator,
    BadParameterError,
    ComponentState,
    EventId,
    ObserverQueue,
    Request,
    ReturnCode,
    Sensor,
)
from openel_async.surface import (
    ApplicationQueue,
    CommandMessage,
    Completed,
    Device,
    EventNotification,
    compact,
    xml_psm,
)
from openel_zenoh import RemoteActuator, RemoteSensor, RemoteSurface, wire
from openel_zenoh.server import is_xml

from ..surface.test_messages import devices
from .conftest import client_cfg, free_port, session, sim_server


async def test_remote_actuator_behaves_as_a_local_one() -> None:
    port = free_port()
    async with (
        sim_server(port) as (_, motors, components),
        session(client_cfg(port)) as zs,
        RemoteSurface(zs, "test") as remote,
    ):
        await remote.wait_server(5)
        async with (
            Actuator(RemoteActuator(remote, 1)) as axis,
            Sensor(RemoteSensor(remote, 0)) as enc,
        ):
            events = ObserverQueue()
            axis.add_observer(events)
            with anyio.fail_after(10):
                motion = await axis.set_value(0.5, Request.POSITION)
                assert not motion.done()  # returned at once
                notice = await events.get()
            assert notice.event_id == EventId.COMPLETED
            await motion
            assert await axis.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.5)
            assert await components[1].get_value() == pytest.approx(0.5)  # type: ignore[attr-defined]
            assert enc.units == components[2].units  # type: ignore[attr-defined]
            assert (await enc.get_value())[0] == pytest.approx(await components[0].get_value())  # type: ignore[attr-defined]
            with pytest.raises(BadParameterError):
                await axis.set_value(100.0)  # the server's limits, checked locally
            # A fault on the server arrives as a fault here.
            motors[1].inject_fault(error_id=7, reason="over-temperature")
            with anyio.fail_after(5):
                error = await events.get()
            assert error.error_id == 7  # type: ignore[union-attr]
            assert axis.state is ComponentState.ERROR
            await axis.re_init()
            assert axis.state is ComponentState.ACTIVE
            assert components[1].state is ComponentState.ACTIVE


async def test_bad_messages_get_return_codes_and_others_keep_being_served() -> None:
    port = free_port()
    async with (
        sim_server(port) as (server, _, _),
        session(client_cfg(port)) as zs,
        RemoteSurface(zs, "test") as remote,
    ):
        reply = await remote.query(remote.keys.execute, b"<Device><oops/></Device>")
        assert b"return_code" in reply and b"valid against the HAL4RT schema" in reply
        reply = await remote.query(remote.keys.execute, b"\x93garbage")
        assert b"compact Device" in reply
        bad = await remote.execute_command("Motor", CommandMessage.call("Fly", "", logical_id=0))
        assert (
            bad.results is not None
            and bad.results.value("return_code") == ReturnCode.HAL_NOT_IMPLEMENTED
        )
        ok = await remote.execute(
            Device("Motor", (CommandMessage.call("GetPosition", "", logical_id=0),)),
            encoding="xml",
        )
        assert ok.commands[0].results is not None
        assert ok.commands[0].results.value("return_code") == 0
        assert server.refused_bad == 2


async def test_events_and_completions_reach_the_right_applications() -> None:
    port = free_port()
    async with (
        sim_server(port) as (_, _, _),
        session(client_cfg(port)) as za,
        session(client_cfg(port)) as zb,
        RemoteSurface(za, "test") as commander,
        RemoteSurface(zb, "test") as listener,
    ):
        await commander.wait_server(5)
        await listener.wait_server(5)
        cmd_app, listen_app = ApplicationQueue(), ApplicationQueue()
        sid = await listener.subscribe("Motor", "COMPLETED", listen_app)
        reply = await commander.execute_command(
            "Motor", CommandMessage.call("SetPosition", "", logical_id=0, position=0.2), cmd_app
        )
        with anyio.fail_after(5):
            done = await cmd_app.get()
            event = await listen_app.get()
        assert done == Completed(reply.command_id, ReturnCode.HAL_OK)
        assert isinstance(event, EventNotification) and event.subscribe_id == sid
        detail = await listener.get_event_detail(event.event_id)
        assert detail.value("logical_id") == 0
        assert len(cmd_app) == 0  # the commander did not subscribe


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-16-be", "utf-8-sig"])
async def test_xml_in_any_encoding_an_xml_parser_reads_is_executed(encoding: str) -> None:
    """Issue 26 defect 3: a spec-valid document in UTF-16 was taken for the compact form and
    refused, while the XML PSM reads the same bytes."""
    port = free_port()
    name = encoding.upper().removesuffix("-SIG").replace("-LE", "").replace("-BE", "")
    text = (
        f'<?xml version="1.0" encoding="{name}"?>\n'
        "<Device><device_kind>Motor</device_kind><CommandMessage>"
        "<function_name>GetPosition</function_name><command_id/><arguments><parameters>"
        "<data_type_id>1</data_type_id><name>logical_id</name><value>0</value></parameters>"
        "</arguments></CommandMessage></Device>"
    )
    payload = text.encode(encoding)
    assert xml_psm.device_from_xml(payload).commands[0].function_name == "GetPosition"
    async with (
        sim_server(port) as (server, _, _),
        session(client_cfg(port)) as zs,
        RemoteSurface(zs, "test") as remote,
    ):
        reply = await remote.query(remote.keys.execute, payload)
        done = xml_psm.device_from_xml(reply)  # answered in XML, as the request was
        assert done.commands[0].results is not None
        assert done.commands[0].results.value("return_code") == 0
        assert server.refused_bad == 0


@pytest.mark.parametrize("encoding", ["utf-32", "utf-32-le", "utf-32-be", "utf-16-le"])
def test_xml_is_told_from_the_compact_form_by_its_first_character(encoding: str) -> None:
    # (expat reads no UTF-32: such a document is answered as XML the PSM refuses)
    assert is_xml(" \n<Device/>".encode(encoding))


@settings(max_examples=100)
@given(devices)
def test_no_compact_device_is_taken_for_xml(device: Device) -> None:
    assert not is_xml(compact.encode(device))


async def test_the_protocol_version_is_in_the_components_reply_and_a_mismatch_is_refused() -> None:
    port = free_port()
    async with (
        sim_server(port) as (_, _, _),
        session(client_cfg(port)) as zs,
        RemoteSurface(zs, "test") as remote,
    ):
        assert [c.device_kind for c in await remote.components()] == ["Motor", "Motor", "Encoder"]
        reply = wire.components_decoder.decode(await remote.query(remote.keys.components, b""))
        assert reply.protocol == wire.PROTOCOL_VERSION == 1
        refused = wire.answer_decoder.decode(
            await remote.query(remote.keys.components, wire.encoder.encode(2))
        )
        assert refused.return_code == ReturnCode.HAL_BAD_PARAMETER
        assert refused.message == (
            "protocol=2 is not allowed: expected protocol version 1 (this server's)"
        )
