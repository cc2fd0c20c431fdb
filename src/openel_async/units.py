"""Units of measurement: pint resolves a unit once, the read path applies an affine map.

``affine(si_unit, unit)`` asks pint (loaded on first use) for the map from a device's SI
unit to ``unit`` and returns it as ``(gain, offset)``: ``value_in_unit = gain * si + offset``
(offset is non-zero only for offset units such as degC or degF). Reading a sensor then
costs one multiply-add per value, never a pint call.
"""

from __future__ import annotations

import functools
from typing import Any

from .errors import BadParameterError

ALIASES_BY_DIMENSION = {
    "[length] / [time] ** 2": {"g": "standard_gravity", "G": "standard_gravity"}
}
"""Unit names read differently for one dimension: 'g' is gram in pint, but an acceleration
in g means standard gravity (9.80665 m/s^2)."""


@functools.cache
def registry() -> Any:
    """pint's UnitRegistry, created once on first use (about 0.1 s)."""
    import pint

    return pint.UnitRegistry()


def _unit(name: str, parameter: str) -> Any:
    import pint

    if not isinstance(name, str) or not name.strip():
        raise BadParameterError(parameter, name, "a unit name such as 'deg', 'degC', 'hPa'")
    try:
        return registry().Unit(name)
    except (pint.errors.PintError, AttributeError, TypeError, ValueError, SyntaxError) as exc:
        raise BadParameterError(parameter, name, f"a unit pint knows ({exc})") from None


@functools.cache
def _affine(si_unit: str, unit: str) -> tuple[float, float] | str:
    import pint

    ureg = registry()
    source = _unit(si_unit, "si_unit")
    alias = ALIASES_BY_DIMENSION.get(str(source.dimensionality), {}).get(unit)
    target = _unit(alias or unit, "unit")
    if source.dimensionality != target.dimensionality:
        return f"a unit of the dimension of {si_unit!r} ({source.dimensionality})"
    try:
        at0 = float(ureg.Quantity(0.0, source).to(target).magnitude)
        at1 = float(ureg.Quantity(1.0, source).to(target).magnitude)
    except pint.errors.PintError as exc:  # pragma: no cover - same dimension converts
        return f"a unit convertible from {si_unit!r} ({exc})"
    # 15 significant digits drop pint's rounding noise (T -> nT: 999999999.9999999 -> 1e9).
    return float(f"{at1 - at0:.15g}"), float(f"{at0:.15g}")


def affine(si_unit: str, unit: str, parameter: str = "unit") -> tuple[float, float]:
    """``(gain, offset)`` with ``value_in_unit = gain * value_in_si_unit + offset``.

    BadParameterError naming ``parameter`` for a unit pint does not know or one of another
    dimension (metres for an angle).
    """
    if unit == si_unit:
        return 1.0, 0.0
    _unit(unit, parameter)  # an unknown name is told under the caller's parameter name
    result = _affine(si_unit, unit)
    if isinstance(result, str):
        raise BadParameterError(parameter, unit, result)
    return result
