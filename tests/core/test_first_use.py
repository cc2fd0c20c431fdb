"""``lazy.first_use``: a module global that imports its module at the first call, then is
that module's function itself."""

from __future__ import annotations

import json
import sys
from typing import Any

import pytest

from openel_async.lazy import first_use


def test_the_first_call_imports_rebinds_and_returns_the_functions_result() -> None:
    namespace: dict[str, Any] = {}
    namespace["dumps"] = first_use(namespace, "dumps", "json", "dumps")
    assert namespace["dumps"] is not json.dumps
    assert namespace["dumps"]([1, 2]) == "[1, 2]"
    assert namespace["dumps"] is json.dumps  # later calls: no stand-in frame


def test_the_module_is_not_imported_until_the_first_call(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delitem(sys.modules, "colorsys", raising=False)
    namespace: dict[str, Any] = {}
    namespace["f"] = first_use(namespace, "f", "colorsys", "rgb_to_hsv")
    assert "colorsys" not in sys.modules
    assert namespace["f"](1.0, 0.0, 0.0) == (0.0, 1.0, 1.0)
    assert "colorsys" in sys.modules
