"""The documentation's examples: the third-party driver, and every runnable code block.

``docs/examples/linear_stage.py`` is imported by path, as a third party's module would
be, and driven through Actuator and Sensor on the virtual clock.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path
from types import ModuleType

import pytest

from openel_async import (
    Actuator,
    BadParameterError,
    ComponentState,
    DeviceFaultError,
    EventId,
    NotImplementedHALError,
    Outcome,
    Request,
    ReturnCode,
    Sensor,
    ValueSource,
    VirtualClock,
)
from openel_async.testing import ComponentStack, EventRecorder

DOCS = Path(__file__).resolve().parents[2] / "docs"
EXAMPLE = DOCS / "examples" / "linear_stage.py"


def _load(path: Path, name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


linear_stage = _load(EXAMPLE, "docs_example_linear_stage")


def _python_blocks(markdown: Path) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```$", markdown.read_text(), flags=re.M | re.S)


# -- the example driver ------------------------------------------------------------------
def test_example_is_under_100_lines() -> None:
    assert len(EXAMPLE.read_text().splitlines()) < 100


def test_drivers_doc_includes_the_example_verbatim() -> None:
    assert EXAMPLE.read_text() in _python_blocks(DOCS / "drivers.md")


async def test_stage_completes_by_tolerance_and_posts_completed(
    virtual_clock: VirtualClock, hal_events: EventRecorder
) -> None:
    stage = linear_stage.LinearStage(time_constant=0.05)
    assert not stage.reports_completion
    async with Actuator(stage, clock=virtual_clock) as actuator:
        actuator.add_observer(hal_events)
        assert actuator.device_name == "HalMotorAcmeLinearStage"
        motion = await actuator.set_value(0.1, Request.POSITION)
        assert motion.outcome is Outcome.PENDING
        await motion
        assert motion.outcome is Outcome.REACHED
        # |0.1 e^(-t/tau)| <= 1e-3 from t = tau ln(100) = 230 ms, then 20 ms of settle,
        # sampled every 5 ms.
        assert motion.reached_ns is not None
        assert 250_000_000 <= motion.reached_ns - motion.issued_ns <= 260_000_000
        assert await actuator.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.1, abs=1e-3)
        assert await actuator.get_value(Request.POSITION) == 0.1
        assert hal_events.count("event", EventId.COMPLETED) == 1
        assert hal_events.events[-1].time_ns == motion.reached_ns
    assert actuator.state is ComponentState.FINALIZED


async def test_stage_velocity_mode_and_unsupported_requests(
    hal_components: ComponentStack, hal_events: EventRecorder
) -> None:
    actuator = await hal_components.actuator(linear_stage.LinearStage())
    actuator.add_observer(hal_events)
    await (await actuator.set_value(0.05, Request.VELOCITY))
    assert await actuator.get_value(Request.VELOCITY_ACTUAL) == pytest.approx(0.05, abs=1e-2)
    with pytest.raises(NotImplementedHALError):
        await actuator.set_value(1.0, Request.TORQUE)  # not in supported_requests
    # Not measured (measured_requests): the commanded torque, as OpenEL §7.4.1.7 says.
    assert await actuator.get_value(Request.TORQUE_ACTUAL) == 0.0
    assert actuator.value_source(Request.TORQUE_ACTUAL) is ValueSource.COMMANDED
    with pytest.raises(BadParameterError):
        await actuator.set_value(0.5, Request.POSITION)  # outside ActuatorLimits
    no_excite = await actuator.set_value(0.0, Request.NO_EXCITE)
    assert no_excite.outcome is Outcome.REACHED  # NO_EXCITE completes at once
    assert hal_events.count("event", EventId.COMPLETED) == 2
    assert actuator.state is ComponentState.ACTIVE


async def test_scale_reads_the_stage_position(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    stage = linear_stage.LinearStage()
    actuator = await hal_components.actuator(stage)
    scale = await hal_components.sensor(linear_stage.LinearScale(stage))
    assert isinstance(scale, Sensor)
    assert scale.device_name == "HalDistanceAcmeLinearScale"
    assert scale.units == ("m",)
    await (await actuator.set_value(0.2))
    timed = await scale.get_timed_value()
    assert timed.num == 1
    assert timed.values[0] == pytest.approx(0.2, abs=1e-3)
    assert timed.time_ns == virtual_clock.now_ns()


async def test_lost_link_puts_the_stage_in_error(
    hal_components: ComponentStack, hal_events: EventRecorder
) -> None:
    stage = linear_stage.LinearStage()
    actuator = await hal_components.actuator(stage)
    actuator.add_observer(hal_events)
    motion = await actuator.set_value(0.1)
    stage.connected = False
    with pytest.raises(DeviceFaultError) as caught:
        await motion  # the completion watcher's read failed: NotConnectedError
    assert caught.value.code is ReturnCode.HAL_NO_CONNECTED
    assert actuator.state is ComponentState.ERROR
    assert hal_events.errors[-1].id == caught.value.error_id
    stage.connected = True
    await actuator.re_init()
    assert actuator.state is ComponentState.ACTIVE


def test_example_registers_a_driver_info() -> None:
    driver = linear_stage.DRIVER
    assert driver.name == "linear_stage"
    assert driver.devices == {"stage": linear_stage.LinearStage, "scale": linear_stage.LinearScale}


# -- every runnable block of the docs ----------------------------------------------------
RUNNABLE = [
    pytest.param(doc, index, block, id=f"{doc}-{index}")
    for doc in ("psm.md", "drivers.md", "architecture.md")
    for index, block in enumerate(_python_blocks(DOCS / doc))
]


@pytest.mark.parametrize(("doc", "index", "block"), RUNNABLE)
def test_doc_block_runs(
    doc: str,
    index: int,
    block: str,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Each ```python block is a complete program (examples/ is on the path)."""
    monkeypatch.syspath_prepend(str(EXAMPLE.parent))
    code = compile(block, f"docs/{doc}[{index}]", "exec")
    exec(code, {"__name__": f"docs_{doc.removesuffix('.md')}_{index}"})


def test_testing_doc_examples_are_tested_verbatim() -> None:
    """Every ```python block of testing.md is in tests/docs/test_testing_doc.py."""
    tests = (Path(__file__).parent / "test_testing_doc.py").read_text()
    blocks = _python_blocks(DOCS / "testing.md")
    assert blocks
    for block in blocks:
        assert block in tests, block
