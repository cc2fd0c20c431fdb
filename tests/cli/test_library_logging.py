"""Used as a library, openel_async prints nothing of its own (issue 21 point 3): structlog is
routed to the standard ``logging`` module, silent below WARNING until the application
configures logging; an application's own structlog configuration is left alone."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _readme_example() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    found = re.search(r"## Example\n\n```python\n(.*?)```", text, re.S)
    assert found is not None, "README.md has no '## Example' python block"
    return found.group(1)


def _python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT
    )


def test_the_readme_example_prints_only_its_own_output() -> None:
    result = _python(_readme_example())
    assert result.returncode == 0, result.stderr
    assert result.stdout == "1.0\n"
    assert result.stderr == ""


def test_logging_basic_config_turns_the_framework_info_events_on() -> None:
    code = "import logging\nlogging.basicConfig(level=logging.INFO)\n" + _readme_example()
    result = _python(code)
    assert result.returncode == 0, result.stderr
    assert result.stdout == "1.0\n"
    assert (
        "INFO:openel_async.component:state_changed component=MOTOR_100 old=Initialized "
        "new=Active" in result.stderr.splitlines()
    )


def test_warnings_reach_logging_without_any_configuration() -> None:
    code = (
        "import structlog, openel_async\n"
        "structlog.get_logger('openel_async.x').info('quiet')\n"
        "structlog.get_logger('openel_async.x').warning('loud', port='/dev/x')\n"
    )
    result = _python(code)
    assert result.returncode == 0, result.stderr
    assert result.stdout == ""
    assert result.stderr == "loud port=/dev/x\n"  # logging's last-resort handler


def test_an_application_structlog_configuration_is_kept() -> None:
    code = (
        "import structlog\n"
        "structlog.configure(processors=[structlog.processors.JSONRenderer()])\n"
        "before = structlog.get_config()\n"
        "import openel_async\n"
        "assert structlog.get_config() == before, structlog.get_config()\n"
        "structlog.get_logger('openel_async.x').info('mine')\n"
    )
    result = _python(code)
    assert result.returncode == 0, result.stderr
    assert result.stdout == '{"event": "mine"}\n'
