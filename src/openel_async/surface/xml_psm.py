"""The XML PSM (spec §7.5.3): HAL4RT messages as XML valid against the spec's schema.

Reading is safe by construction: the input's size is checked first, the parser refuses
DTDs, entities and external references (defusedxml), nesting deeper than the schema allows
is refused while parsing, the document is validated against the shipped XSD by
``xmlschema``, and only then converted to the message model, which checks every value
against its ``data_type_id``. Every refusal is a :class:`BadParameterError` naming what
was wrong. Writing produces text that reads back to an equal message (floats by
``repr``, ``\\r`` as a character reference so parsers do not normalize it).
"""

from __future__ import annotations

import base64
import binascii
import io
import json
import math
import re
import xml.etree.ElementTree as ET
from functools import cache
from importlib.resources import files
from typing import TYPE_CHECKING, Any

import defusedxml.ElementTree as DET
from defusedxml import DefusedXmlException

from ..errors import BadParameterError
from .messages import (
    ArgumentList,
    CommandMessage,
    DataType,
    Device,
    Message,
    Parameter,
    ResultList,
)

if TYPE_CHECKING:
    import xmlschema

SCHEMA_FILE = "hal4rt_message.xsd"
MAX_XML_BYTES = 1 << 20
"""Largest XML message accepted (1 MiB)."""
MAX_DEPTH = 8
"""Deepest element nesting accepted; the schema's own maximum is 5 (Device ... value)."""

_ROOTS: dict[str, type] = {
    "Device": Device,
    "CommandMessage": CommandMessage,
    "ArgumentList": ArgumentList,
    "ResultList": ResultList,
    "Parameter": Parameter,
}
_INT = re.compile(r"[+-]?[0-9]+")
_DOUBLE = re.compile(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([Ee][+-]?[0-9]+)?|[+-]?INF|NaN")
_BOOL = {"true": True, "false": False, "1": True, "0": False}


@cache
def schema() -> xmlschema.XMLSchema:
    """The spec's schema (typos fixed), loaded once, on first use: importing xmlschema
    costs ~0.3 s, which every ``openel-async`` start would otherwise pay."""
    import xmlschema

    path = files(__package__).joinpath(SCHEMA_FILE)
    return xmlschema.XMLSchema(str(path))


def schema_text() -> str:
    return files(__package__).joinpath(SCHEMA_FILE).read_text(encoding="utf-8")


# -- values ----------------------------------------------------------------------------
def _format_double(value: float) -> str:
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "INF" if value > 0 else "-INF"
    return repr(value)


def _parse_double(name: str, text: str) -> float:
    if not _DOUBLE.fullmatch(text):
        raise BadParameterError(name, text, "an xs:double (e.g. 1.5, -2e-3, INF, -INF, NaN)")
    return float(text.replace("INF", "inf"))


def _parse_int(name: str, text: str) -> int:
    if not _INT.fullmatch(text):
        raise BadParameterError(name, text, "a decimal integer")
    return int(text)


def _parse_bool(name: str, text: str) -> bool:
    try:
        return _BOOL[text]
    except KeyError:
        raise BadParameterError(name, text, "true or false") from None


def format_value(data_type_id: int, value: Any) -> str:
    """The text of ``<value>`` for a checked parameter value."""
    if data_type_id == DataType.INT:
        return str(value)
    if data_type_id == DataType.FLOAT:
        return _format_double(value)
    if data_type_id == DataType.STRING:
        return str(value)
    if data_type_id == DataType.BOOL:
        return "true" if value else "false"
    if data_type_id == DataType.BYTES:
        return base64.b64encode(value).decode("ascii")
    if data_type_id == DataType.INT_LIST:
        return " ".join(str(v) for v in value)
    if data_type_id == DataType.FLOAT_LIST:
        return " ".join(_format_double(v) for v in value)
    if data_type_id == DataType.STRING_LIST:
        return json.dumps(list(value), ensure_ascii=False)
    if data_type_id == DataType.BOOL_LIST:
        return " ".join("true" if v else "false" for v in value)
    raise BadParameterError("data_type_id", data_type_id, "a DataType")


def parse_value(data_type_id: int, text: str, name: str = "value") -> Any:
    """The Python value of the text of ``<value>`` for ``data_type_id``."""
    if data_type_id == DataType.INT:
        return _parse_int(name, text)
    if data_type_id == DataType.FLOAT:
        return _parse_double(name, text)
    if data_type_id == DataType.STRING:
        return text
    if data_type_id == DataType.BOOL:
        return _parse_bool(name, text)
    if data_type_id == DataType.BYTES:
        try:
            return base64.b64decode(text.encode("ascii"), validate=True)
        except (binascii.Error, UnicodeEncodeError):
            raise BadParameterError(name, text, "base64 text") from None
    if data_type_id == DataType.INT_LIST:
        return tuple(_parse_int(name, t) for t in text.split())
    if data_type_id == DataType.FLOAT_LIST:
        return tuple(_parse_double(name, t) for t in text.split())
    if data_type_id == DataType.BOOL_LIST:
        return tuple(_parse_bool(name, t) for t in text.split())
    if data_type_id == DataType.STRING_LIST:
        try:
            items = json.loads(text)
        except ValueError:
            raise BadParameterError(name, text, "a JSON array of strings") from None
        if not isinstance(items, list) or not all(isinstance(i, str) for i in items):
            raise BadParameterError(name, text, "a JSON array of strings")
        return tuple(items)
    allowed = ", ".join(f"{d.value} ({d.name})" for d in DataType)
    raise BadParameterError("data_type_id", data_type_id, f"one of {allowed}")


# -- writing ---------------------------------------------------------------------------
def _escape(text: str) -> str:
    return (
        text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace("\r", "&#13;")
    )


def _write_parameter(out: list[str], tag: str, p: Parameter) -> None:
    out.append(
        f"<{tag}><data_type_id>{p.data_type_id}</data_type_id><name>{_escape(p.name)}</name>"
        f"<value>{_escape(format_value(p.data_type_id, p.value))}</value></{tag}>"
    )


def _write_list(out: list[str], tag: str, parameters: tuple[Parameter, ...]) -> None:
    out.append(f"<{tag}>")
    for p in parameters:
        _write_parameter(out, "parameters", p)
    out.append(f"</{tag}>")


def _write_command(out: list[str], tag: str, c: CommandMessage) -> None:
    out.append(
        f"<{tag}><function_name>{_escape(c.function_name)}</function_name>"
        f"<command_id>{_escape(c.command_id)}</command_id>"
    )
    if c.arguments is not None:
        _write_list(out, "arguments", c.arguments.parameters)
    if c.results is not None:
        _write_list(out, "results", c.results.parameters)
    out.append(f"</{tag}>")


def to_xml(message: Message, *, declaration: bool = True) -> bytes:
    """UTF-8 XML of a message, its root element named after its type."""
    out: list[str] = ['<?xml version="1.0" encoding="utf-8"?>\n'] if declaration else []
    if isinstance(message, Device):
        out.append(f"<Device><device_kind>{_escape(message.device_kind)}</device_kind>")
        for command in message.commands:
            _write_command(out, "CommandMessage", command)
        out.append("</Device>")
    elif isinstance(message, CommandMessage):
        _write_command(out, "CommandMessage", message)
    elif isinstance(message, ArgumentList | ResultList):
        _write_list(out, type(message).__name__, message.parameters)
    elif isinstance(message, Parameter):
        _write_parameter(out, "Parameter", message)
    else:
        raise BadParameterError(
            "message", message, "a Device, CommandMessage, ArgumentList, ResultList or Parameter"
        )
    return "".join(out).encode("utf-8")


# -- reading ---------------------------------------------------------------------------
def _parse_tree(data: bytes | str, max_bytes: int) -> ET.Element:
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    if len(raw) > max_bytes:
        raise BadParameterError(
            "message", f"<{len(raw)} bytes>", f"at most {max_bytes} bytes of XML"
        )
    depth = 0
    root: ET.Element | None = None
    try:
        for event, element in DET.iterparse(
            io.BytesIO(raw), events=("start", "end"), forbid_dtd=True
        ):
            if event == "start":
                depth += 1
                if depth > MAX_DEPTH:
                    raise BadParameterError(
                        "message", "<nesting>", f"at most {MAX_DEPTH} levels of elements"
                    )
                if root is None:
                    root = element
            else:
                depth -= 1
    except (ET.ParseError, DefusedXmlException) as exc:
        raise BadParameterError(
            "message", "<xml>", f"well-formed XML without DTD or entities ({exc})"
        ) from None
    assert root is not None
    return root


def validate(data: bytes | str, *, max_bytes: int = MAX_XML_BYTES) -> ET.Element:
    """Parse safely and validate against the schema; the root element, or BAD_PARAMETER."""
    root = _parse_tree(data, max_bytes)
    if root.tag not in _ROOTS:
        raise BadParameterError("message", root.tag, f"a root element among {sorted(_ROOTS)}")
    error = next(schema().iter_errors(root), None)
    if error is not None:
        reason = error.reason or str(error.message)
        raise BadParameterError(
            "message", root.tag, f"XML valid against the HAL4RT schema: {reason} at {error.path}"
        )
    return root


def _text(element: ET.Element, tag: str) -> str:
    child = element.find(tag)
    assert child is not None  # validated
    return child.text or ""


def _read_parameter(element: ET.Element) -> Parameter:
    data_type_id = int(_text(element, "data_type_id"))
    name = _text(element, "name")
    value = parse_value(data_type_id, _text(element, "value"), name or "value")
    return Parameter(data_type_id, name, value)


def _read_list(element: ET.Element) -> tuple[Parameter, ...]:
    return tuple(_read_parameter(p) for p in element.findall("parameters"))


def _read_command(element: ET.Element) -> CommandMessage:
    arguments = element.find("arguments")
    results = element.find("results")
    return CommandMessage(
        _text(element, "function_name"),
        _text(element, "command_id"),
        None if arguments is None else ArgumentList(_read_list(arguments)),
        None if results is None else ResultList(_read_list(results)),
    )


def from_xml(data: bytes | str, *, max_bytes: int = MAX_XML_BYTES) -> Message:
    """Read any of the schema's global elements; BAD_PARAMETER for anything invalid."""
    root = validate(data, max_bytes=max_bytes)
    tag = root.tag
    try:
        if tag == "Device":
            return Device(
                _text(root, "device_kind"),
                tuple(_read_command(c) for c in root.findall("CommandMessage")),
            )
        if tag == "CommandMessage":
            return _read_command(root)
        if tag == "ArgumentList":
            return ArgumentList(_read_list(root))
        if tag == "ResultList":
            return ResultList(_read_list(root))
        return _read_parameter(root)
    except ValueError as exc:  # data_type_id beyond any int range, etc.
        if isinstance(exc, BadParameterError):
            raise
        raise BadParameterError("message", tag, str(exc)) from None


def device_from_xml(data: bytes | str, *, max_bytes: int = MAX_XML_BYTES) -> Device:
    """Read a ``<Device>`` message (what ``execute`` takes)."""
    message = from_xml(data, max_bytes=max_bytes)
    if not isinstance(message, Device):
        raise BadParameterError("message", type(message).__name__, "a <Device> root element")
    return message
