"""The runnable examples of docs/surface.md and docs/remote.md."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from openel_async.rig import build_components, parse_rig

DOCS = Path(__file__).resolve().parents[2] / "docs"


def _blocks(doc: str, language: str) -> list[str]:
    text = (DOCS / doc).read_text()
    return re.findall(rf"^```{language}\n(.*?)^```$", text, flags=re.M | re.S)


@pytest.mark.parametrize(
    ("doc", "index"),
    [(doc, i) for doc in ("surface.md", "remote.md") for i in range(len(_blocks(doc, "python")))],
)
def test_python_examples_run(doc: str, index: int, capsys: pytest.CaptureFixture[str]) -> None:
    code = compile(_blocks(doc, "python")[index], f"{doc}[{index}]", "exec")
    exec(code, {"__name__": f"docs_{doc}_{index}"})
    assert capsys.readouterr().out  # each example prints what it shows


def test_remote_rig_example_builds() -> None:
    (block,) = _blocks("remote.md", "yaml")
    spec = parse_rig(yaml.safe_load(block))
    components = build_components(spec)
    assert [c.device_name for c in components] == ["MOTOR_1", "ENCODER_1"]
    assert components[1].device.motor is components[0].device  # type: ignore[attr-defined]


def test_key_table_matches_the_code() -> None:
    from openel_zenoh.keys import Keys

    keys = Keys("ns")
    text = (DOCS / "remote.md").read_text()
    for key in (keys.execute, keys.subscribe, keys.unsubscribe, keys.event_detail, keys.error_detail,
                keys.components, keys.server_alive, keys.notices("c"), keys.client_alive("c")):  # fmt: skip
        documented = key.replace("openel/ns/", "openel/<ns>/").replace("/c/", "/<client>/")
        documented = re.sub(r"/c$", "/<client>", documented)
        assert f"`{documented}`" in text


def test_rig_builds_the_hal4rt_class_of_each_device_kind() -> None:
    """A served motor is a Motor and a sensor its kind's class, so the surface offers their
    HAL4RT operations (SetSpeed with tmAcc, SetOrigin, units) over Zenoh too."""
    from openel_async import Encoder, Motor

    (block,) = _blocks("remote.md", "yaml")
    motor, encoder = build_components(parse_rig(yaml.safe_load(block)))
    assert isinstance(motor, Motor)
    assert isinstance(encoder, Encoder)
