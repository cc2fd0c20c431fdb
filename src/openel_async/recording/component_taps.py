"""The listeners a :class:`~.tap.Tap` sets on components (:class:`ComponentTap`, and
:class:`ActuatorTap` for actuators) and on banks (:class:`BankTap`, a batch listener): each
turns its commands, readings and state changes into records of the tap's pipeline (column
buffers of :mod:`.columns`, or tuples in its queue), and the actuators keep what the
joint-state sample needs (the commanded position, the device's own read).

Used by :mod:`.tap`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from ..actuator import Actuator
from ..component import ComponentState, HALComponent
from ..device import ValueSource
from ..errors import HALError
from ..listeners import BatchListener
from ..requests import Request
from .columns import Columns
from .records import BATCH, COMMAND, READING, STATE

if TYPE_CHECKING:
    from .tap import Tap

__all__ = ["ActuatorTap", "BankTap", "ComponentTap"]

_ACTIVE = ComponentState.ACTIVE
_POSITION = Request.POSITION
_POSITION_ACTUAL = Request.POSITION_ACTUAL
_POSITION_CODE = int(Request.POSITION)


class ComponentTap:
    """The listener the tap sets on one component: its records go straight into the
    pipeline (one call from the component; no lookup of the channel).

    Readings go to column buffers (:mod:`.columns`): one per request code, made at the
    first reading of that code (its width: that reading's number of values); the common one
    -- the first code read -- is kept at hand. A reading of another width, and state
    changes, go to the queue as tuples of ints, floats, None and strings (a Request as its
    int: the garbage collector then untracks them at its first passes)."""

    __slots__ = (
        "actuals",
        "capacity",
        "channel",
        "component",
        "muted",
        "now",
        "pipeline",
        "queue",
        "read_code",
        "read_times",
        "read_values",
        "read_width",
        "readings",
        "tap",
    )

    def __init__(self, tap: Tap, component: HALComponent, channel: int) -> None:
        self.tap = tap
        self.component = component
        self.channel = channel
        self.now = component.clock.now_ns
        self.pipeline = tap.pipeline
        self.queue = tap.pipeline.queue
        self.capacity = tap.pipeline.capacity
        self.muted = False
        """True while the tap reads the component itself (that read is not recorded)."""
        self.actuals: list[tuple[Columns, int, int]] = []
        """The column buffers of its POSITION_ACTUAL readings (its own, its banks' reads):
        each with its value's index in a record and the record's width."""
        self.readings: dict[Request | None, Columns | None] = {}
        """Request -> the column buffer of its readings (None: they do not fit one)."""
        self.read_code: Request | bool | None = False  # the request of the buffer at hand
        # (False: none yet; True: none, its reads take the other path, ActuatorTap._reading)
        self.read_times: list[int] = []
        self.read_values: list[float] = []
        self.read_width = 0

    def on_command(
        self, component: HALComponent, request: Request, value: float, time_ns: int
    ) -> None:
        self.hand_over()
        queue = self.queue
        if len(queue) < self.capacity:
            queue.append((self.channel, time_ns, COMMAND, int(request), value))
        else:
            self.pipeline.dropped += 1

    def hand_over(self) -> None:
        """Queue what this component's column buffers hold: before a record of its channel
        goes to the queue (the writer gets a channel's records in order)."""
        pipeline = self.pipeline
        for columns in self.readings.values():
            if columns is not None and columns.times:
                pipeline.hand_over(columns)

    def on_reading(
        self, component: HALComponent, request: Request | None, values: tuple[float, ...]
    ) -> None:
        if request is self.read_code and len(values) == self.read_width and not self.muted:
            times = self.read_times  # Columns.append, inline (the per-tick path)
            if len(times) < self.capacity:
                times.append(self.now())
                self.read_values.extend(values)
            else:
                self.pipeline.dropped += 1
            return
        if self.muted:  # the tap's own read
            return
        self._reading(request, values)

    def _reading(self, request: Request | None, values: tuple[float, ...]) -> None:
        """A reading off the path at hand: into its request's column buffer, else queued."""
        if request in self.readings:
            columns = self.readings[request]
        else:  # the first reading of this request: its buffer
            code = None if request is None else int(request)
            columns = None
            if values and all(type(v) is float for v in values):  # as readings are
                columns = self.pipeline.add_columns(READING, code, (self.channel,), len(values))
            self.readings[request] = columns
            if columns is not None and request is _POSITION_ACTUAL:
                self.actuals.append((columns, 0, columns.width))  # the sample looks at it
            if columns is not None and self.read_code is False:
                self.read_code = request
                self.read_times, self.read_values = columns.times, columns.values
                self.read_width = columns.width
        if columns is not None and len(values) == columns.width:
            if not columns.append(self.now(), values):
                self.pipeline.dropped += 1
            return
        self.hand_over()
        code = None if request is None else int(request)
        self.pipeline.put((self.channel, self.now(), READING, code, values))

    def on_state(self, component: HALComponent, old: ComponentState, new: ComponentState) -> None:
        self.hand_over()
        self.pipeline.put((self.channel, self.now(), STATE, str(old), str(new)))
        if new is _ACTIVE:
            self.tap.observe_events(component)


class ActuatorTap(ComponentTap):
    """An actuator's listener: its position commands go to a column buffer; it also keeps
    what the joint-state sample needs without reading through the framework: the commanded
    position (the last POSITION command it heard, or the latest of its banks' batches
    (:class:`BankTap`) when one came after it: each bank's batch count is noted at each
    of its own commands; read once through the framework after each activation, which
    resets it) and the device's own actual-position read (``None``: the framework answers
    the commanded value for it, or the device has no synchronous read).

    Its POSITION commands go to a column buffer while it is in no bank; a bank member's
    own commands (rare: the bank streams) go to the queue after the bank's earlier
    batches, so that the file keeps their order."""

    __slots__ = (
        "actuator",
        "banks",
        "command_times",
        "command_values",
        "commanded",
        "commands",
        "marks",
        "name",
        "read",
    )

    def __init__(self, tap: Tap, component: Actuator, channel: int) -> None:
        super().__init__(tap, component, channel)
        self.actuator = component
        self.name = component.device_name
        self.commanded: float | None = None
        """The last POSITION command heard since the last state change (None: unknown)."""
        self.banks: list[tuple[BankTap, int]] = []
        """The batch listeners of the banks it is in, and its index in each."""
        self.marks: list[int] = []
        """Each bank's batch count at its last own command or state change (a bank
        joined since: 0), in the order of :attr:`banks`."""
        self.commands: Columns | None = None  # its POSITION commands (made at the first)
        self.command_times: list[int] = []
        self.command_values: list[float] = []
        measured = component.value_source(_POSITION_ACTUAL) is not ValueSource.COMMANDED
        self.read: Callable[[Request], float] | None = (
            component.device.read_nowait if measured else None
        )

    def on_command(
        self, component: HALComponent, request: Request, value: float, time_ns: int
    ) -> None:
        if request is _POSITION:
            self.commanded = value
            if self.banks:
                self.mark()
        if request is _POSITION and not self.banks:
            times = self.command_times  # Columns.append, inline
            if len(times) < self.capacity:
                if self.commands is None:
                    self._command_columns()
                    times = self.command_times
                times.append(time_ns)
                self.command_values.append(value)
            else:
                self.pipeline.dropped += 1
            return
        self.hand_over()
        queue = self.queue
        if len(queue) < self.capacity:
            queue.append((self.channel, time_ns, COMMAND, int(request), value))
        else:
            self.pipeline.dropped += 1

    def hand_over(self) -> None:
        super().hand_over()
        pipeline = self.pipeline
        commands = self.commands
        if commands is not None and commands.times:
            pipeline.hand_over(commands)
        for bank, _ in self.banks:
            bank.hand_over()

    def _reading(self, request: Request | None, values: tuple[float, ...]) -> None:
        """Its own read of a code that one of its banks reads too: the banks' reads held
        first, and its later own reads of it stay off the path at hand (and the bank's too,
        :meth:`BankTap._read`): the two sources of one channel keep their order."""
        shared = False
        for bank, _ in self.banks:
            if request in bank.reads:
                shared = True
                bank.hand_over()
                if bank.read_code is request:
                    bank.read_code = None
        super()._reading(request, values)
        if shared and self.read_code is request:
            self.read_code = True

    def _command_columns(self) -> None:
        columns = self.pipeline.add_columns(COMMAND, _POSITION_CODE, (self.channel,), 1)
        self.commands = columns
        self.command_times, self.command_values = columns.times, columns.values

    def on_state(self, component: HALComponent, old: ComponentState, new: ComponentState) -> None:
        self.commanded = None  # an activation sets it to the actual position
        self.mark()  # and the banks' earlier batches are older
        super().on_state(component, old, new)

    def batch_listener(self, components: Sequence[HALComponent]) -> BatchListener | None:
        """The batch listener of a bank of ``components`` (every one observed by this tap):
        its :meth:`BankTap.on_batch` (a bound method: the cheapest call, not an instance's
        ``__call__``), else None (each member's listener hears its command)."""
        bank = self.tap.bank_tap(components)
        return None if bank is None else bank.on_batch

    def latest_commanded(self) -> float | None:
        """The commanded position: the last POSITION command heard, its own or in a bank's
        batch, whichever came last (read through the framework after an activation)."""
        commanded = self.commanded
        banks = self.banks
        if len(banks) == 1 and not banks[0][0].drops:  # the usual case: one bank, no drop
            bank, index = banks[0]
            columns = bank.columns
            times = columns.times
            n = len(times)
            if columns.taken + n > self.marks[0]:  # a batch since its own command
                if n:
                    return columns.values[(n - 1) * columns.width + index]
                if columns.last_values is not None:
                    return columns.last_values[index]
        elif banks:  # BankTap.batches and latest, inline (every sample)
            at = -1
            for (bank, index), mark in zip(banks, self.marks, strict=True):
                columns = bank.columns
                times = columns.times
                n = len(times)
                count = columns.taken + n + bank.drops
                if count <= mark:  # none since its own command
                    continue
                if bank.lost_at == count and bank.lost is not None:  # the latest was dropped
                    t, value = bank.lost[0], bank.lost[1][index]
                elif n:
                    t, value = times[n - 1], columns.values[(n - 1) * columns.width + index]
                elif columns.last_values is not None:
                    t, value = columns.last_time, columns.last_values[index]
                else:
                    continue
                if t > at:  # the newest bank's
                    at, commanded = t, value
        if commanded is None:
            commanded = self.read_commanded()
        return commanded

    def mark(self) -> None:
        """Note each bank's batch count (its own command or a state change came now)."""
        self.marks = [bank.batches() for bank, _ in self.banks]

    def read_commanded(self) -> float | None:
        """The commanded position read through the framework (after an activation; that
        read is not recorded)."""
        self.muted = True
        try:
            self.commanded = self.actuator.get_value_nowait(_POSITION)
        except HALError:
            return None
        finally:
            self.muted = False
        return self.commanded


class BankTap:
    """The batch listener of a bank (:func:`openel_async.listeners.batch_listener`): a
    POSITION batch is a record of a column buffer (:mod:`.columns`; the writer process makes
    a COMMAND message of each value on its component's channel), another command's a BATCH
    record in the queue; the latest POSITION batch is what the joint-state sample takes
    (:meth:`ActuatorTap.latest_commanded`). A read of the members (an actual-value code) is
    a record of that code's column buffer (a READING message of each value on its
    component's channel); the first code read is kept at hand."""

    __slots__ = (
        "capacity",
        "channels",
        "columns",
        "count",
        "drops",
        "lost",
        "lost_at",
        "members",
        "pipeline",
        "queue",
        "read_code",
        "read_times",
        "read_values",
        "reads",
        "size",
        "times",
        "values",
    )

    def __init__(self, tap: Tap, members: Sequence[ComponentTap]) -> None:
        self.members = tuple(members)
        self.channels = tuple(m.channel for m in members)
        self.size = len(members)
        self.pipeline = tap.pipeline
        self.queue = tap.pipeline.queue
        self.capacity = tap.pipeline.capacity
        self.columns = tap.pipeline.add_columns(COMMAND, _POSITION_CODE, self.channels, self.size)
        self.times = self.columns.times
        self.values = self.columns.values
        self.count = 0
        """BATCH records queued (the pipeline counts ``size`` messages for each)."""
        self.lost: tuple[int, tuple[float, ...]] | None = None
        """The latest POSITION batch that was dropped (its time and values)."""
        self.drops = 0
        """POSITION batches dropped so far."""
        self.lost_at = 0
        """:meth:`batches` when :attr:`lost` was dropped."""
        self.reads: dict[Request, Columns | None] = {}
        """Actual-value code -> the column buffer of the reads (None: they do not fit one)."""
        self.read_code: Request | None = None  # the code of the buffer at hand
        self.read_times: list[int] = []
        self.read_values: list[float] = []

    def on_batch(self, request: Request, values: Sequence[float], time_ns: int) -> None:
        """The :data:`~openel_async.listeners.BatchListener`."""
        if request is _POSITION:  # Columns.append, inline (the per-tick path)
            times = self.times
            if len(times) < self.capacity:
                times.append(time_ns)
                self.values.extend(values)
            else:
                self.pipeline.dropped += self.size
                self.lost = (time_ns, tuple(values))  # not recorded, but the latest command
                self.drops += 1
                self.lost_at = self.batches()
            return
        if request is self.read_code:  # the members' actual positions read (per tick)
            times = self.read_times
            if len(times) < self.capacity:
                times.append(time_ns)
                self.read_values.extend(values)
            else:
                self.pipeline.dropped += self.size
            return
        if not request.is_command:
            self._read(request, values, time_ns)
            return
        for member in self.members:  # their channels' earlier records first
            member.hand_over()
        self.hand_over()
        queue = self.queue
        if len(queue) < self.capacity:
            queue.append((BATCH, time_ns, COMMAND, int(request), self.channels, tuple(values)))
            self.count += 1
        else:
            self.pipeline.dropped += self.size

    def _read(self, request: Request, values: Sequence[float], time_ns: int) -> None:
        """A read off the path at hand: into its code's column buffer (made at its first
        read), else each value to its member's listener."""
        if request in self.reads:
            columns = self.reads[request]
        else:
            columns = None
            if all(type(v) is float for v in values):  # as the actual values are
                code = int(request)
                columns = self.pipeline.add_columns(READING, code, self.channels, self.size)
                if request is _POSITION_ACTUAL:  # the joint-state sample looks at it
                    for index, member in enumerate(self.members):
                        member.actuals.append((columns, index, self.size))
            self.reads[request] = columns
            own = [m for m in self.members if request in m.readings]
            for member in own:  # its own reads of it leave the path at hand (see _reading)
                if member.read_code is request:
                    member.read_code = True
            if columns is not None and self.read_code is None and not own:
                self.read_code = request
                self.read_times, self.read_values = columns.times, columns.values
        if columns is not None and all(type(v) is float for v in values):
            for member in self.members:  # a member's own reads held: they came first
                if request in member.readings:
                    member.hand_over()
            if not columns.append(time_ns, values):
                self.pipeline.dropped += self.size
            return
        for member, value in zip(self.members, values, strict=True):
            member.on_reading(member.component, request, (value,))

    def hand_over(self) -> None:
        """Queue what its column buffers hold (before another record of its members)."""
        pipeline = self.pipeline
        if self.times:
            pipeline.hand_over(self.columns)
        for columns in self.reads.values():
            if columns is not None and columns.times:
                pipeline.hand_over(columns)

    def batches(self) -> int:
        """POSITION batches heard so far (held, handed over or dropped)."""
        columns = self.columns
        return columns.taken + len(self.times) + self.drops
