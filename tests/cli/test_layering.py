"""The framework imports no driver (issue 15): ``openel_async`` and its command line work
with every driver package made unimportable, and no module under src/openel_async imports
one."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "src" / "openel_async"
DRIVERS = ("openel_sim", "openel_mujoco", "openel_can", "openel_serial", "openel_zenoh")

BLOCKED = f"""
import sys

DRIVERS = {DRIVERS!r}


class Blocker:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in DRIVERS:
            raise ModuleNotFoundError(f"blocked driver: {{name}}", name=name)
        return None


sys.meta_path.insert(0, Blocker())
import openel_async
import openel_async.testing
from openel_async.cli import main

try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
loaded = sorted(m for m in sys.modules if m.split(".")[0] in DRIVERS)
print("DRIVER MODULES:", loaded)
sys.exit(code)
"""


def _blocked(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", BLOCKED, "--log-level", "warning", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )


def test_help_without_any_driver() -> None:
    result = _blocked("--help")
    assert result.returncode == 0, result.stderr
    listed = result.stdout.split("\ncommands:\n", 1)[1].split("\n\n", 1)[0]
    commands = [
        line.split()[0] for line in listed.splitlines() if line[:4] == "    " and line[4:5] != " "
    ]
    assert commands == [
        "demo", "run", "devices", "profile", "record", "replay", "rig", "param", "jog", "hal4rt",
        "scan", "bus", "completion",
    ]  # no serve: Zenoh's command  # fmt: skip
    assert result.stderr == ""
    assert "DRIVER MODULES: []" in result.stdout


def test_demo_list_without_any_driver() -> None:
    result = _blocked("demo", "--list")
    assert result.returncode == 0, result.stderr
    names = [line.split()[0] for line in result.stdout.splitlines()[:-1]]
    assert names == ["arm2", "arm6", "csp4", "pantilt", "so101", "twoaxis"]
    assert "unavailable" not in result.stdout
    assert "DRIVER MODULES: []" in result.stdout


def test_an_app_says_which_driver_it_misses() -> None:
    result = _blocked("run", "twoaxis", "--virtual", "--duration", "1", "--no-live")
    assert result.returncode == 2
    assert "the sim rig is not available: blocked driver: openel_sim" in result.stderr
    result = _blocked("demo", "--app", "arm2", "--virtual", "--no-live")
    assert result.returncode == 1
    assert "MuJoCo cannot run --app arm2: ModuleNotFoundError" in result.stderr


def _driver_imports(path: Path) -> list[str]:
    """Every import of a driver package in ``path``: ``import``, ``from ... import`` (at
    any depth, also inside functions) and ``import_module("...")``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        elif isinstance(node, ast.Call) and node.args:  # import_module("openel_x...")
            first = node.args[0]
            if isinstance(first, ast.Constant) and isinstance(first.value, str):
                func = node.func
                called = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
                if called in ("import_module", "__import__"):
                    names = [first.value]
        found += [
            f"{path.name}:{node.lineno}: {name}" for name in names if name.split(".")[0] in DRIVERS
        ]
    return found


def test_no_module_of_the_framework_imports_a_driver() -> None:
    files = sorted(SRC.rglob("*.py"))
    assert len(files) > 50
    offenders = [hit for path in files for hit in _driver_imports(path)]
    assert offenders == []


@pytest.mark.parametrize(
    "source",
    [
        "import openel_sim",
        "from openel_mujoco import MujocoSim",
        "def f():\n    from openel_can.demo import can_rig",
        "import importlib\nimportlib.import_module('openel_zenoh.config')",
    ],
)
def test_the_static_check_sees_every_form_of_import(source: str, tmp_path: Path) -> None:
    probe = tmp_path / "probe.py"
    probe.write_text(source)
    assert len(_driver_imports(probe)) == 1
    probe.write_text(source.replace("openel_", "openel_async_"))
    assert _driver_imports(probe) == []


def _imported_modules(path: Path) -> set[str]:
    """Absolute module names imported by ``path`` (relative imports resolved)."""
    parts = path.relative_to(ROOT).with_suffix("").parts
    package = list(parts[1:-1] if parts[0] in ("src", "drivers", "apps") else parts[:-1])
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = ".".join([*base, *([node.module] if node.module else [])])
            found.add(module)
            found.update(f"{module}.{alias.name}" for alias in node.names)
    return found


def test_apps_and_the_library_use_the_public_app_sdk_not_the_cli() -> None:
    """Issue 21 point 11: apps import ``openel_async.app``; the CLI package is private to the
    command line, and nothing outside it (framework, drivers but the command plug-in seam,
    apps) imports it."""
    offenders = []
    roots = [SRC, ROOT / "apps" / "openel_apps", *(ROOT / "drivers").glob("openel_*")]
    for root in roots:
        for path in root.rglob("*.py"):
            if SRC / "cli" in path.parents:
                continue
            for module in _imported_modules(path):
                if module == "openel_async.cli" or module.startswith("openel_async.cli."):
                    if module.startswith("openel_async.cli.commands") and "drivers" in path.parts:
                        continue  # the seam a driver contributes a subcommand through
                    offenders.append(f"{path.relative_to(ROOT)}: {module}")
    assert offenders == []
