"""The HAL4RT message data structures (spec §7.4.4, Tables 7.8-7.12).

``Device`` holds the device kind and one or more ``CommandMessage``; a command message
names the API (``function_name``), carries a ``command_id`` and optional ``ArgumentList``
and ``ResultList``, each a non-empty sequence of ``Parameter``. The spec leaves the
``data_type_id`` values open; this module fixes them (:class:`DataType`):

| data_type_id | name        | Python value      | XML text of ``<value>``               |
|--------------|-------------|-------------------|---------------------------------------|
| 1            | INT         | int (64-bit)      | decimal, e.g. ``-42``                 |
| 2            | FLOAT       | float             | xs:double: ``repr``, ``INF``, ``-INF``, ``NaN`` |
| 3            | STRING      | str               | the text itself                       |
| 4            | BOOL        | bool              | ``true`` / ``false``                  |
| 5            | BYTES       | bytes             | base64                                |
| 11           | INT_LIST    | tuple[int, ...]   | space-separated decimals              |
| 12           | FLOAT_LIST  | tuple[float, ...] | space-separated xs:double             |
| 13           | STRING_LIST | tuple[str, ...]   | a JSON array of strings               |
| 14           | BOOL_LIST   | tuple[bool, ...]  | space-separated ``true``/``false``    |

Every string (names, ids, values) must consist of characters XML 1.0 can carry, so that
any message has a representation in the standard (XML) PSM.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from enum import IntEnum
from typing import Any, cast

import msgspec

from ..errors import BadParameterError

INT64_MIN = -(2**63)
INT64_MAX = 2**63 - 1


class DataType(IntEnum):
    """``Parameter.data_type_id`` values (see the module's table)."""

    INT = 1
    FLOAT = 2
    STRING = 3
    BOOL = 4
    BYTES = 5
    INT_LIST = 11
    FLOAT_LIST = 12
    STRING_LIST = 13
    BOOL_LIST = 14


_SCALAR: dict[int, type] = {
    DataType.INT: int,
    DataType.FLOAT: float,
    DataType.STRING: str,
    DataType.BOOL: bool,
    DataType.BYTES: bytes,
}
_ARTICLE = {int: "an int", float: "a float", str: "a str", bool: "a bool", bytes: "bytes"}
_ITEM: dict[int, type] = {
    DataType.INT_LIST: int,
    DataType.FLOAT_LIST: float,
    DataType.STRING_LIST: str,
    DataType.BOOL_LIST: bool,
}
PYTHON_TYPES: dict[DataType, str] = {
    DataType.INT: "int",
    DataType.FLOAT: "float",
    DataType.STRING: "str",
    DataType.BOOL: "bool",
    DataType.BYTES: "bytes",
    DataType.INT_LIST: "tuple[int, ...]",
    DataType.FLOAT_LIST: "tuple[float, ...]",
    DataType.STRING_LIST: "tuple[str, ...]",
    DataType.BOOL_LIST: "tuple[bool, ...]",
}

# Characters outside XML 1.0's Char production.
_NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")

ParameterValue = (
    int | float | str | bool | bytes | tuple[int, ...] | tuple[float, ...] | tuple[str, ...]
)


def check_text(parameter: str, value: object) -> str:
    """``value`` as a str that XML 1.0 can carry, or BAD_PARAMETER."""
    if not isinstance(value, str):
        raise BadParameterError(parameter, value, "a string")
    bad = _NOT_XML.search(value)
    if bad is not None:
        raise BadParameterError(
            parameter, value, f"characters XML 1.0 can carry (found U+{ord(bad.group()):04X})"
        )
    return value


def _check_item(name: str, kind: type, item: object) -> None:
    if type(item) is not kind:
        raise BadParameterError(name, item, _ARTICLE[kind])
    if kind is int and not INT64_MIN <= item <= INT64_MAX:  # type: ignore[operator]
        raise BadParameterError(name, item, "a 64-bit signed integer")
    if kind is str:
        check_text(name, item)


def check_value(data_type_id: int, value: object, name: str = "value") -> ParameterValue:
    """``value`` checked against ``data_type_id`` (lists become tuples), or BAD_PARAMETER."""
    if type(data_type_id) is not int and not isinstance(data_type_id, DataType):
        raise BadParameterError("data_type_id", data_type_id, "an int")
    scalar = _SCALAR.get(data_type_id)
    if scalar is not None:
        _check_item(name, scalar, value)
        return value  # type: ignore[return-value]
    item = _ITEM.get(data_type_id)
    if item is None:
        allowed = ", ".join(f"{d.value} ({d.name})" for d in DataType)
        raise BadParameterError("data_type_id", data_type_id, f"one of {allowed}")
    if not isinstance(value, tuple | list):
        raise BadParameterError(name, value, f"a sequence of {item.__name__}")
    for entry in value:
        _check_item(name, item, entry)
    return tuple(value)


def infer_type(value: object) -> DataType:
    """The data type of a Python value (lists by their first item; empty lists are FLOAT_LIST)."""
    kind = type(value)
    for data_type, scalar in _SCALAR.items():
        if kind is scalar:
            return DataType(data_type)
    if isinstance(value, tuple | list):
        first = type(value[0]) if value else float
        for data_type, item in _ITEM.items():
            if first is item:
                return DataType(data_type)
    raise BadParameterError("value", value, "an int, float, str, bool, bytes or a list of those")


class Parameter(msgspec.Struct, frozen=True, array_like=True):
    """Table 7.12: one argument or result."""

    data_type_id: int
    name: str
    value: Any

    def __post_init__(self) -> None:
        check_text("name", self.name)
        checked = check_value(self.data_type_id, self.value, self.name or "value")
        if checked is not self.value:
            msgspec.structs.force_setattr(self, "value", checked)

    @classmethod
    def of(cls, name: str, value: object, data_type: DataType | None = None) -> Parameter:
        """A parameter whose data type is inferred from ``value`` unless given."""
        return cls(int(data_type or infer_type(value)), name, value)


def _parameters(owner: str, parameters: object) -> tuple[Parameter, ...]:
    if not isinstance(parameters, tuple | list) or not parameters:
        raise BadParameterError(f"{owner}.parameters", parameters, "one or more Parameters")
    for parameter in parameters:
        if not isinstance(parameter, Parameter):
            raise BadParameterError(f"{owner}.parameters", parameter, "a Parameter")
    return tuple(parameters)


class ArgumentList(msgspec.Struct, frozen=True, array_like=True):
    """Table 7.10: the parameters of a command (one or more)."""

    parameters: tuple[Parameter, ...]

    def __post_init__(self) -> None:
        msgspec.structs.force_setattr(
            self, "parameters", _parameters("ArgumentList", self.parameters)
        )

    def get(self, name: str) -> Parameter | None:
        return next((p for p in self.parameters if p.name == name), None)


class ResultList(msgspec.Struct, frozen=True, array_like=True):
    """Table 7.11: the results of a command, an event or an error (one or more)."""

    parameters: tuple[Parameter, ...]

    def __post_init__(self) -> None:
        msgspec.structs.force_setattr(
            self, "parameters", _parameters("ResultList", self.parameters)
        )

    def get(self, name: str) -> Parameter | None:
        return next((p for p in self.parameters if p.name == name), None)

    def value(self, name: str) -> Any:
        """The value of the result ``name``; BAD_PARAMETER when there is none."""
        found = self.get(name)
        if found is None:
            names = [p.name for p in self.parameters]
            raise BadParameterError("name", name, f"one of the results {names}")
        return found.value

    def as_dict(self) -> dict[str, Any]:
        return {p.name: p.value for p in self.parameters}

    @classmethod
    def of(cls, **values: object) -> ResultList:
        return cls(tuple(Parameter.of(name, value) for name, value in values.items()))


class CommandMessage(msgspec.Struct, frozen=True, array_like=True):
    """Table 7.9: the API to call, its id, arguments and results."""

    function_name: str
    command_id: str = ""
    arguments: ArgumentList | None = None
    results: ResultList | None = None

    def __post_init__(self) -> None:
        check_text("function_name", self.function_name)
        check_text("command_id", self.command_id)
        if self.arguments is not None and not isinstance(self.arguments, ArgumentList):
            raise BadParameterError("arguments", self.arguments, "an ArgumentList or None")
        if self.results is not None and not isinstance(self.results, ResultList):
            raise BadParameterError("results", self.results, "a ResultList or None")

    def argument(self, name: str) -> Parameter | None:
        return None if self.arguments is None else self.arguments.get(name)

    @classmethod
    def call(
        cls, function_name: str, command_id: str = "", /, **arguments: object
    ) -> CommandMessage:
        """A command with arguments inferred from Python values."""
        args = (
            ArgumentList(tuple(Parameter.of(k, v) for k, v in arguments.items()))
            if arguments
            else None
        )
        return cls(function_name, command_id, args)


class Device(msgspec.Struct, frozen=True, array_like=True):
    """Table 7.8 with Figure 7.7: the kind of the target device and its command messages."""

    device_kind: str
    commands: tuple[CommandMessage, ...]

    def __post_init__(self) -> None:
        check_text("device_kind", self.device_kind)
        if not isinstance(self.commands, tuple | list) or not self.commands:
            raise BadParameterError("commands", self.commands, "one or more CommandMessages")
        for command in self.commands:
            if not isinstance(command, CommandMessage):
                raise BadParameterError("commands", command, "a CommandMessage")
        msgspec.structs.force_setattr(self, "commands", tuple(self.commands))


Message = Device | CommandMessage | ArgumentList | ResultList | Parameter
"""Any of the schema's global elements."""


# -- Messages from values already checked ------------------------------------------------
# The surface layer builds every reply from parts that passed the checks above (a
# request's names, arguments and kind; results built by the constructors; command ids
# it numbers itself), so it builds them without running the checks again: a copy of a
# prototype (msgspec's __copy__ does not call __post_init__) with its fields set. The
# result is the same message, equal to and encoded as one built by the constructor.
_set_field = msgspec.structs.force_setattr
_copy: Callable[[Any], Any] = cast(Any, msgspec.Struct).__copy__
_PARAMETER = Parameter(DataType.INT, "p", 0)
_RESULTS = ResultList((_PARAMETER,))
_COMMAND = CommandMessage("c")
_DEVICE = Device("d", (_COMMAND,))


def parameter_unchecked(data_type_id: int, name: str, value: Any) -> Parameter:
    """``Parameter(data_type_id, name, value)`` without its checks: only for a name and a
    value known to pass them (a name of the code, a float for FLOAT...)."""
    parameter: Parameter = _copy(_PARAMETER)
    _set_field(parameter, "data_type_id", data_type_id)
    _set_field(parameter, "name", name)
    _set_field(parameter, "value", value)
    return parameter


def with_value(parameter: Parameter, value: Any) -> Parameter:
    """``parameter`` with another value, without the checks: only for a value known to pass
    them for its data type (a float for FLOAT)."""
    copy: Parameter = _copy(parameter)
    _set_field(copy, "value", value)
    return copy


def results_unchecked(parameters: tuple[Parameter, ...]) -> ResultList:
    """``ResultList(parameters)`` without its checks: a non-empty tuple of Parameters."""
    results: ResultList = _copy(_RESULTS)
    _set_field(results, "parameters", parameters)
    return results


def command_unchecked(
    function_name: str,
    command_id: str,
    arguments: ArgumentList | None,
    results: ResultList | None,
) -> CommandMessage:
    """``CommandMessage(...)`` without its checks: the fields of a checked message (or a
    command id of characters XML carries)."""
    command: CommandMessage = _copy(_COMMAND)
    _set_field(command, "function_name", function_name)
    _set_field(command, "command_id", command_id)
    _set_field(command, "arguments", arguments)
    _set_field(command, "results", results)
    return command


def device_unchecked(device_kind: str, commands: tuple[CommandMessage, ...]) -> Device:
    """``Device(device_kind, commands)`` without its checks: a checked kind and a non-empty
    tuple of CommandMessages."""
    device: Device = _copy(_DEVICE)
    _set_field(device, "device_kind", device_kind)
    _set_field(device, "commands", commands)
    return device
