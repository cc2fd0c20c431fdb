"""Remote devices: an actuator or sensor of a ``openel-async serve`` server as a local
device, so that ``Actuator(RemoteActuator(remote, 0))`` behaves as a local component.

``set_value`` returns once the server accepted the command (one round trip); the
server's ``completed`` for the latest command is this device's ``target_reached``, so
COMPLETED arrives as event 1; ``get_value`` of an actual value is one round trip. The
server's errors for the component arrive as errors (a fault there is a fault here); the
server going away, and a query of the device left without reply (its timeout), is a link
fault (``ErrorId.DISCONNECTED``, ``HAL_NO_CONNECTED``), and
``re_init`` once it is back resets the remote component if it is in Error.
"""

from __future__ import annotations

import asyncio
import struct
from collections.abc import Iterator
from contextlib import contextmanager

from openel_async.device import (
    ActuatorDevice,
    ActuatorLimits,
    DeviceContext,
    DeviceInfo,
    ErrorId,
    Reading,
    SensorDevice,
)
from openel_async.errors import BadParameterError, NotConnectedError, ReturnCode, check_code
from openel_async.ids import DeviceKind
from openel_async.logs import get_logger
from openel_async.requests import EventId, Request
from openel_async.surface import compact
from openel_async.surface.messages import CommandMessage, Device, ResultList

from .client import COMMANDS_LANE, RemoteSurface

log = get_logger(__name__)

COMPLETED = EventId.COMPLETED.name
_FLOAT = struct.Struct(">d")
_FLOAT_BYTES = _FLOAT.size

_SET = {
    Request.POSITION: ("SetPosition", "position"),
    Request.VELOCITY: ("SetSpeed", "speed"),
    Request.TORQUE: ("SetTorque", "torque"),
}
_GET = {
    Request.POSITION_ACTUAL: ("GetPosition", "position"),
    Request.VELOCITY_ACTUAL: ("GetSpeed", "speed"),
    Request.TORQUE_ACTUAL: ("GetTorque", "torque"),
}


def results_of(command: CommandMessage) -> ResultList:
    """The results of an executed command, or the exception its return code names."""
    results = command.results
    if results is None or results.get("return_code") is None:
        raise NotConnectedError(f"{command.function_name}: the reply carries no return_code")
    code = results.value("return_code")
    if code != ReturnCode.HAL_OK:
        message = results.get("message")
        check_code(code, f"remote {command.function_name}: {message.value if message else ''}")
    return results


@contextmanager
def no_reply_is_a_link_fault(what: str) -> Iterator[None]:
    """A query left without reply (RemoteSurface's TimeoutError) raised as NotConnectedError:
    for a remote device, no answer from its server is a link failure, whatever the cause
    (a partition, a dead or stopped host)."""
    try:
        yield
    except TimeoutError as exc:
        raise NotConnectedError(f"{what}: no reply from the server ({exc})") from exc


class _RemoteLink:
    """What both remote device kinds share: addressing, notices, presence."""

    def __init__(self, remote: RemoteSurface, logical_id: int, device_kind: str) -> None:
        if isinstance(logical_id, bool) or not isinstance(logical_id, int) or logical_id < 0:
            raise BadParameterError("logical_id", logical_id, "an int >= 0")
        self.remote = remote
        self.logical_id = logical_id
        self.device_kind = device_kind
        self.ctx: DeviceContext | None = None
        self._subscription: int | None = None
        self._unlisten: object = None
        self._payloads: dict[str, bytes] = {}

    async def call(self, function_name: str) -> ResultList:
        """A synchronous command without arguments (GetPosition, GetState...): its results.

        Its compact message is encoded once per function name and reused."""
        payload = self._payloads.get(function_name)
        if payload is None:
            command = CommandMessage.call(function_name, "", logical_id=self.logical_id)
            payload = self._payloads[function_name] = compact.encode(
                Device(self.device_kind, (command,))
            )
        with no_reply_is_a_link_fault(f"{self.device_kind}[{self.logical_id}] {function_name}"):
            reply = await self.remote.execute_compact(payload)
        return results_of(reply.commands[0])

    async def link_open(self, ctx: DeviceContext) -> ResultList:
        self.ctx = ctx
        profile = await self.call("GetProfile")
        self.remote.attach(self)
        # COMPLETED comes through completed(): the server need not make an event of it
        self._subscription = await self.remote.subscribe(
            self.device_kind, "*", self, exclude=(COMPLETED,)
        )
        self._unlisten = self.remote.on_server(self._server_presence)
        return profile

    async def link_reset(self) -> None:
        if not self.remote.server_alive:
            raise NotConnectedError(
                f"{self.device_kind}[{self.logical_id}]: the server is not reachable"
            )
        state = await self.call("GetState")
        if state.value("state") == "Error":
            await self.call("Reset")

    async def link_close(self) -> None:
        if callable(self._unlisten):
            self._unlisten()
        self.remote.detach(self)
        if self._subscription is not None:
            sid, self._subscription = self._subscription, None
            try:
                await self.remote.unsubscribe(sid)
            except Exception as exc:  # a gone server: nothing to undo there
                log.debug("remote_unsubscribe_failed", error=str(exc))

    def _mine(self, detail: ResultList | None) -> bool:
        return (
            detail is not None
            and detail.value("logical_id") == self.logical_id
            and str(detail.value("device_kind")).lower() == self.device_kind.lower()
        )

    # ApplicationBase
    def notify_event(self, event_id: str, event_type: str, subscribe_id: int) -> None:
        detail = self.remote.cached_event_detail(event_id)
        if self.ctx is None or not self._mine(detail):
            return
        assert detail is not None
        code = int(detail.value("event_code"))
        if code != EventId.COMPLETED:  # COMPLETED comes from completed()
            self.ctx.post_event(code)

    def notify_error(self, error_id: str, error_type: str) -> None:
        detail = self.remote.cached_error_detail(error_id)
        if self.ctx is None or not self._mine(detail):
            return
        assert detail is not None
        code = int(detail.value("error_code"))
        if detail.value("faulted"):
            return_code = int(detail.value("return_code"))
            self.ctx.fault(
                code,
                f"remote: {detail.value('message')}",
                ReturnCode(return_code)
                if return_code in ReturnCode._value2member_map_
                else ReturnCode.HAL_ERROR,
            )
        else:
            self.ctx.post_error(code)

    def _server_presence(self, alive: bool) -> None:
        if not alive and self.ctx is not None:
            self.ctx.fault(
                ErrorId.DISCONNECTED,
                f"link fault: the server of namespace {self.remote.keys.namespace!r} is gone",
                ReturnCode.HAL_NO_CONNECTED,
            )


class RemoteActuator(_RemoteLink, ActuatorDevice):
    """A Motor served by a remote surface layer, addressed by its logical id."""

    reports_completion = True

    def __init__(
        self, remote: RemoteSurface, logical_id: int = 0, *, device_kind: str = "Motor"
    ) -> None:
        _RemoteLink.__init__(self, remote, logical_id, device_kind)
        self.info = DeviceInfo(
            kind=DeviceKind.MOTOR,
            vendor_name="Remote",
            product_name=f"Motor{logical_id}",
            functions=(),
        )
        self._latest = ""
        self._completed: dict[str, ReturnCode] = {}
        self._command_parts: dict[Request, tuple[bytes, bytes | None]] = {}

    async def open(self, ctx: DeviceContext) -> None:
        profile = await self.link_open(ctx)
        low, high = profile.value("position_limits")
        self.limits = ActuatorLimits(
            (low, high), profile.value("velocity_limit"), profile.value("torque_limit")
        )
        self.supported_requests = frozenset(Request(r) for r in profile.value("supported_requests"))
        self.info = DeviceInfo(
            kind=profile.value("device_kind_id"),
            vendor_id=profile.value("vendor_id"),
            product_id=profile.value("product_id"),
            vendor_name="Remote",
            product_name=f"Motor{self.logical_id}",
        )

    async def reset(self) -> None:
        await self.link_reset()

    async def close(self) -> None:
        await self.link_close()

    async def command(self, request: Request, value: float) -> None:
        name = "SetControlMode" if request is Request.NO_EXCITE else _SET[request][0]
        with no_reply_is_a_link_fault(f"{self.device_kind}[{self.logical_id}] {name}"):
            reply = await self.remote.execute_compact(
                self.command_payload(request, value),
                self,
                lane=COMMANDS_LANE if name in self.remote.asynchronous else "",
            )
        done = reply.commands[0]
        results_of(done)
        self._latest = done.command_id
        status = self._completed.pop(done.command_id, None)
        if status is not None:
            # Completed before its reply came back: the Actuator accepts this command only
            # once command() returns, so the completion is reported right after that.
            asyncio.get_running_loop().call_soon(
                self._completed_after_send, done.command_id, status
            )

    def command_payload(self, request: Request, value: float) -> bytes:
        """The compact execute of a command: the bytes before and after its value are
        encoded once per request (the value, a float, is the last argument: msgpack float
        64, ``cb`` and 8 bytes big-endian), as ``compact.encode`` would encode the message."""
        parts = self._command_parts.get(request)
        if parts is None:
            if request is Request.NO_EXCITE:
                command = CommandMessage.call(
                    "SetControlMode", "", logical_id=self.logical_id, mode=0
                )
                parts = (compact.encode(Device(self.device_kind, (command,))), None)
            else:
                name, argument = _SET[request]
                command = CommandMessage.call(
                    name, "", logical_id=self.logical_id, **{argument: 0.0}
                )
                whole = compact.encode(Device(self.device_kind, (command,)))
                marker = len(whole) - _FLOAT_BYTES - 2  # ... cb <8 bytes> c0 (no results)
                if whole[marker:] != b"\xcb" + _FLOAT.pack(0.0) + b"\xc0":
                    raise BadParameterError("encoding", whole.hex(), "a float last argument")
                parts = (whole[: marker + 1], whole[marker + 1 + _FLOAT_BYTES :])
            self._command_parts[request] = parts
        head, tail = parts
        if tail is None:
            return head
        return head + _FLOAT.pack(float(value)) + tail

    def _completed_after_send(self, command_id: str, status: ReturnCode) -> None:
        if self.ctx is not None and command_id == self._latest and status == ReturnCode.HAL_OK:
            self.ctx.target_reached()

    async def read(self, request: Request) -> float:
        name, result = _GET[request]
        value = (await self.call(name)).value(result)
        return float(value)

    # ApplicationBase: completed
    def completed(self, command_id: str, status: ReturnCode) -> None:
        if self.ctx is None:
            return
        if command_id != self._latest:
            # Possibly a command whose reply is still on its way: kept for command().
            self._completed[command_id] = status
            if len(self._completed) > 64:
                del self._completed[next(iter(self._completed))]
            return
        if status == ReturnCode.HAL_OK:
            self.ctx.target_reached()


class RemoteSensor(_RemoteLink, SensorDevice):
    """A sensor served by a remote surface layer, addressed by kind and logical id."""

    has_time = True

    def __init__(
        self, remote: RemoteSurface, logical_id: int = 0, *, device_kind: str = "Encoder"
    ) -> None:
        _RemoteLink.__init__(self, remote, logical_id, device_kind)
        self.info = DeviceInfo(
            kind=DeviceKind.ROTARY_ANGLE, vendor_name="Remote", product_name=f"Sensor{logical_id}"
        )

    async def open(self, ctx: DeviceContext) -> None:
        profile = await self.link_open(ctx)
        units = tuple(profile.value("units"))
        self.units = () if units == ("",) else units

    async def reset(self) -> None:
        await self.link_reset()

    async def close(self) -> None:
        await self.link_close()

    async def read(self) -> Reading:
        # The server's clock is another clock domain: the reading is stamped locally.
        return Reading(tuple((await self.call("GetValueOfMeasurement")).value("values")))

    def completed(self, command_id: str, status: ReturnCode) -> None:
        pass
