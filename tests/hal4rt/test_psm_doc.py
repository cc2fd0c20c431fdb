"""docs/psm.md §2 says what ``check_code`` raises for each return code, as the code does
(it said HAL_BAD_PARAMETER became a plain HALError; issue 21 point 20)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import openel_async.errors as errors
from openel_async.errors import BadParameterError, HALError, ReturnCode, check_code

PSM = Path(__file__).resolve().parents[2] / "docs" / "psm.md"


def _section_2() -> str:
    text = PSM.read_text(encoding="utf-8")
    return text[text.index("## 2. Return codes") : text.index("## 3. HALComponent")]


def _check_code_part() -> str:
    section = _section_2()
    return section[section.index("check_code(code") :]


def _documented() -> dict[str, str]:
    """The ``| `HAL_X` | `ExceptionClass` ...`` rows of the check_code table."""
    return dict(re.findall(r"^\| `(HAL_[A-Z_]+)` \| `(\w+)`", _check_code_part(), flags=re.M))


def test_the_doc_names_the_exception_of_every_code() -> None:
    documented = _documented()
    assert set(documented) == {c.name for c in ReturnCode if c is not ReturnCode.HAL_OK}
    for name, class_name in documented.items():
        code = ReturnCode[name]
        with pytest.raises(HALError) as raised:
            check_code(code, "from a C API")
        assert type(raised.value) is getattr(errors, class_name), name
        assert raised.value.code is code and "from a C API" in str(raised.value)
    check_code(ReturnCode.HAL_OK)


def test_bad_parameter_is_a_bad_parameter_error_as_the_doc_says() -> None:
    with pytest.raises(BadParameterError) as raised:
        check_code(ReturnCode.HAL_BAD_PARAMETER, "speed out of range")
    exc = raised.value
    assert (exc.parameter, exc.value, exc.allowed) == ("parameter", None, "speed out of range")
    assert isinstance(exc, ValueError)
    lines = _check_code_part().splitlines()
    row = next(line for line in lines if line.startswith("| `HAL_BAD_PARAMETER`"))
    assert '`.parameter` is `"parameter"`' in row and "`.value` `None`" in row
