"""Issue 26: the wire protocol as docs/wire.md specifies it, exercised by a client written from
the specification with nothing but eclipse-zenoh and msgspec (examples/raw_client.py)."""

from __future__ import annotations

import ast
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import anyio
import pytest

from .conftest import free_port, sim_server

CLIENT = Path(__file__).resolve().parents[2] / "examples" / "raw_client.py"


def _load() -> ModuleType:
    spec = importlib.util.spec_from_file_location("raw_client", CLIENT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["raw_client"] = module  # msgspec resolves its annotations there
    spec.loader.exec_module(module)
    return module


def test_the_reference_client_uses_nothing_of_openel_async() -> None:
    imported = set()
    for node in ast.walk(ast.parse(CLIENT.read_text())):
        if isinstance(node, ast.Import):
            imported |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            imported.add(node.module.split(".")[0])
    assert imported <= {
        "__future__",
        "json",
        "sys",
        "threading",
        "uuid",
        "typing",
        "msgspec",
        "zenoh",
    }


async def test_the_reference_client_drives_a_served_rig(capsys: pytest.CaptureFixture[str]) -> None:
    raw = _load()
    port = free_port()
    async with sim_server(port) as (server, _, _):
        code = await anyio.to_thread.run_sync(raw.main, f"tcp/127.0.0.1:{port}", "test")
        assert code == 0
        out = capsys.readouterr().out.splitlines()
        assert out[0] == "protocol 1"
        assert out[1:4] == [
            "component Motor[0] " + server.surface.entries[0].component.device_name + " Active",
            "component Motor[1] " + server.surface.entries[1].component.device_name + " Active",
            "component Encoder[0] " + server.surface.entries[2].component.device_name + " Active",
        ]
        assert out[4] == "SetPosition return_code 0 command_id c1"
        assert out[5] == "completed c1 status 0"
        assert out[6] == "GetPosition position 0.500"
        assert out[7] == "notices missed 0"
