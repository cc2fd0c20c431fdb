"""A device's limits set after an ActuatorBank was built: the bank checks the next batch
against them, on every path (the per-value check, the inline streaming tick, a proven
position stream), as ``Actuator.set_value`` on the same component does.  A value outside a
device's current limits is never sent through a bank; one inside them is."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from typing import ClassVar

import pytest

from openel_async import (
    ActuatorBank,
    ActuatorDevice,
    ActuatorLimits,
    BadParameterError,
    Request,
)
from openel_async.device import LIMITS_CHANGES, BatchCommander
from openel_async.testing import ComponentStack

WIDE = ActuatorLimits((-2.0, 2.0), 1.0, 1.0)
NARROW = ActuatorLimits((-0.5, 0.5), 1.0, 1.0)


class StreamServo(ActuatorDevice):
    """Reports completion; its driver commands a whole bank in one call (the bank's inline
    streaming tick and position streams). Its limits are its own, set per instance."""

    supported_requests = frozenset({Request.POSITION})
    reports_completion = True
    batches: ClassVar[list[tuple[float, ...]]] = []

    def __init__(self, limits: ActuatorLimits = WIDE) -> None:
        self.limits = limits
        self.position = 0.0
        self.commands = 0

    async def command(self, request: Request, value: float) -> None:
        self.command_nowait(request, value)

    def command_nowait(self, request: Request, value: float) -> None:
        self.commands += 1
        self.position = value

    async def read(self, request: Request) -> float:
        return self.position

    def read_nowait(self, request: Request) -> float:
        return self.position

    @classmethod
    def batch_commander(cls, devices: Sequence[ActuatorDevice]) -> BatchCommander | None:
        servos = [d for d in devices if isinstance(d, StreamServo)]

        def command(request: Request, values: Sequence[float], /) -> bool:
            cls.batches.append(tuple(values))
            for servo, value in zip(servos, values, strict=True):
                servo.position = value
            return True

        return command


class PlainServo(StreamServo):
    """No batch and no completion report: the bank checks each batch in ``_check`` and
    commands the devices one by one."""

    reports_completion = False

    @classmethod
    def batch_commander(cls, devices: Sequence[ActuatorDevice]) -> BatchCommander | None:
        return None


@pytest.fixture(autouse=True)
def _batches() -> Iterator[None]:
    StreamServo.batches.clear()
    yield
    StreamServo.batches.clear()


def _sent(servos: Sequence[StreamServo]) -> tuple[int, list[int]]:
    return len(StreamServo.batches), [s.commands for s in servos]


async def _bank(hal_components: ComponentStack, servos: Sequence[StreamServo]) -> ActuatorBank:
    actuators = [
        await hal_components.actuator(s, device_name=f"servo{i}") for i, s in enumerate(servos)
    ]
    return ActuatorBank(actuators)


# -- the device's limits attribute ------------------------------------------------------------


def test_every_assignment_of_limits_is_counted_and_checked() -> None:
    servo = StreamServo()
    assert "limits" not in vars(servo)  # set through the property, not shadowing it
    before = LIMITS_CHANGES.value
    servo.limits = NARROW
    assert servo.limits is NARROW and LIMITS_CHANGES.value == before + 1
    with pytest.raises(BadParameterError) as info:
        servo.limits = (-1.0, 1.0)  # type: ignore[assignment]
    assert info.value.parameter == "limits" and "ActuatorLimits" in info.value.allowed
    assert servo.limits is NARROW and LIMITS_CHANGES.value == before + 1


def test_a_class_attribute_default_does_not_shadow_the_property() -> None:
    class Declared(PlainServo):
        limits = NARROW  # the usual way to declare a device's fixed limits

        def __init__(self) -> None:
            self.position = 0.0
            self.commands = 0

    class Inherited(Declared):
        pass

    assert isinstance(vars(ActuatorDevice)["limits"], property)
    assert "limits" not in vars(Declared)
    assert Declared().limits is NARROW and Inherited().limits is NARROW
    assert Declared.limits is NARROW and Inherited.limits is NARROW  # read on the class too
    device = Inherited()
    before = LIMITS_CHANGES.value
    device.limits = WIDE
    assert device.limits is WIDE and Declared().limits is NARROW
    assert LIMITS_CHANGES.value == before + 1
    # Set on the class: the default of its instances that set none (also counted).
    plain = Inherited()
    Inherited.limits = WIDE
    assert plain.limits is WIDE and Declared().limits is NARROW
    assert LIMITS_CHANGES.value == before + 2
    with pytest.raises(BadParameterError, match=r"Inherited\.limits"):
        Inherited.limits = None  # type: ignore[assignment]

    with pytest.raises(BadParameterError, match=r"Broken\.limits"):

        class Broken(PlainServo):
            limits = (-1.0, 1.0)  # type: ignore[assignment]


def test_limits_none_in_a_class_body_is_refused_not_left_shadowing_the_property() -> None:
    # None would hide the property from the instances: device.limits None, and assignments
    # stored in the instance's dict, never counted (a bank would not see them).
    with pytest.raises(BadParameterError, match=r"Unlimited\.limits"):

        class Unlimited(PlainServo):
            limits = None  # type: ignore[assignment]


# -- ActuatorBank.set_values(_nowait) -----------------------------------------------------------


@pytest.mark.parametrize("kind", [StreamServo, PlainServo])
@pytest.mark.parametrize("narrowed", ["all", "one"])  # one shared range, or per-device ranges
async def test_limits_narrowed_after_the_bank_was_built_refuse_the_next_batch(
    hal_components: ComponentStack, kind: type[StreamServo], narrowed: str
) -> None:
    servos = [kind() for _ in range(3)]
    bank = await _bank(hal_components, servos)
    bank.set_values_nowait([1.5, 1.5, 1.5])  # within the limits the bank was built with
    sent = _sent(servos)
    for servo in servos if narrowed == "all" else servos[1:2]:
        servo.limits = NARROW
    # The actuator refuses it; so does the bank, whatever its path, and sends nothing.
    with pytest.raises(BadParameterError):
        bank.actuators[1].set_value_nowait(1.0)
    for values in ([0.0, 1.0, 0.0], [0.2, 0.6, 0.3], [0.4, -0.51, 0.4], [0.0, -1.9, 0.0]):
        with pytest.raises(BadParameterError) as info:
            bank.set_values_nowait(values)
        assert info.value.parameter == "values[1]" and "[-0.5, 0.5]" in info.value.allowed
        with pytest.raises(BadParameterError):
            await bank.set_values(values)
        assert _sent(servos) == sent
    assert [s.position for s in servos] == [1.5, 1.5, 1.5]
    assert [a.get_value_nowait(Request.POSITION) for a in bank.actuators] == [1.5, 1.5, 1.5]
    # Within the new limits: sent.
    bank.set_values_nowait([0.1, 0.5, -0.5] if narrowed == "all" else [1.9, 0.5, -1.9])
    assert _sent(servos) != sent
    # Widened again (beyond those the bank was built with): the wider values go through.
    for servo in servos:
        servo.limits = ActuatorLimits((-3.0, 3.0), 1.0, 1.0)
    bank.set_values_nowait([2.5, -2.5, 1.0])
    await bank.set_values([-2.9, 2.9, 0.0])
    assert [s.position for s in servos] == [-2.9, 2.9, 0.0]


async def test_the_inline_tick_rechecks_after_narrowing_between_two_equal_batches(
    hal_components: ComponentStack,
) -> None:
    """The same batch, streamed twice: accepted, then refused once a device's limits no
    longer hold it (the bank does not remember the batch as checked)."""
    servos = [StreamServo() for _ in range(2)]
    bank = await _bank(hal_components, servos)
    batch = [0.7, -0.7]
    bank.set_values_nowait(batch)
    assert StreamServo.batches == [(0.7, -0.7)]
    servos[0].limits = ActuatorLimits((-2.0, 0.6), 1.0, 1.0)
    with pytest.raises(BadParameterError) as info:
        bank.set_values_nowait(batch)
    assert info.value.parameter == "values[0]"
    assert StreamServo.batches == [(0.7, -0.7)]
    servos[0].limits = ActuatorLimits((0.7, 0.8), 1.0, 1.0)  # the lower limit: inclusive
    bank.set_values_nowait(batch)
    assert StreamServo.batches == [(0.7, -0.7), (0.7, -0.7)]


# -- ActuatorBank.position_stream ---------------------------------------------------------------


async def test_a_proven_stream_rechecks_its_proof_when_limits_are_set(
    hal_components: ComponentStack,
) -> None:
    servos = [StreamServo() for _ in range(2)]
    bank = await _bank(hal_components, servos)
    send = bank.position_stream([-1.0, -1.0], [1.0, 1.0])
    assert send is not None
    send([0.9, -0.9])
    assert StreamServo.batches == [(0.9, -0.9)]
    # Narrowed below the proven bounds: a value outside the new limits is refused as the
    # per-value path refuses it, nothing sent; one inside them still goes through.
    servos[1].limits = NARROW
    with pytest.raises(BadParameterError) as info:
        send([0.9, -0.9])
    assert info.value.parameter == "values[1]" and "[-0.5, 0.5]" in info.value.allowed
    assert StreamServo.batches == [(0.9, -0.9)] and [s.commands for s in servos] == [0, 0]
    assert [a.get_value_nowait(Request.POSITION) for a in bank.actuators] == [0.9, -0.9]
    send([0.9, -0.4])
    assert StreamServo.batches[-1] == (0.9, -0.4)
    with pytest.raises(BadParameterError):
        send([0.9, 0.6])
    assert StreamServo.batches[-1] == (0.9, -0.4)
    # Narrowed but still around the bounds: proven again.
    servos[1].limits = ActuatorLimits((-1.0, 1.0), 1.0, 1.0)
    send([0.9, 1.0])
    assert StreamServo.batches[-1] == (0.9, 1.0)
    # A new stream is refused bounds outside the current limits and proven within them,
    # also beyond those the bank was built with.
    servos[0].limits = NARROW
    assert bank.position_stream([-1.0, -1.0], [1.0, 1.0]) is None
    for servo in servos:
        servo.limits = ActuatorLimits((-5.0, 5.0), 1.0, 1.0)
    wide = bank.position_stream([-4.0, -4.0], [4.0, 4.0])
    assert wide is not None
    wide([4.0, -4.0])
    assert StreamServo.batches[-1] == (4.0, -4.0)


async def test_a_proven_stream_refuses_a_value_outside_infinite_turned_finite_limits(
    hal_components: ComponentStack,
) -> None:
    servos = [StreamServo(ActuatorLimits((-math.inf, math.inf), 1.0, 1.0)) for _ in range(2)]
    bank = await _bank(hal_components, servos)
    send = bank.position_stream([-100.0, -100.0], [100.0, 100.0])
    assert send is not None
    send([100.0, -100.0])
    servos[0].limits = WIDE
    with pytest.raises(BadParameterError) as info:
        send([100.0, 0.0])
    assert info.value.parameter == "values[0]"
    assert StreamServo.batches == [(100.0, -100.0)]
